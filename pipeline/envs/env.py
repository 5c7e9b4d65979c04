"""RoadsynthEnv: drive the ego through naturalistic SUMO traffic (Gymnasium 1.x API).

Background traffic is the ``simulate`` stage's: the same network builder, the same demand and per-vehicle
driver-parameter sampling, the same SUMO settings (write_sumocfg) and the same ego choice, all drawn from the
run seed. ``reset(seed=N)`` uses N as that run seed (so ``roadsynth simulate --seed N`` shows the same
traffic); ``reset()`` without a seed draws the next run seed from the env's generator.

The ego is taken from SUMO (speed mode 0, lane-change mode 0) and moved each step with ``moveToXY(keepRoute=2)``
by a kinematic point model in the lane frame: longitudinal speed >= 0 (no reversing), lateral speed limited and
never above the longitudinal one; SUMO maps the moved ego to the nearest lane, so lane changes emerge from
lateral motion, and SUMO's own collision detection reports collisions.

On request the env also renders the rig's camera and LiDAR each step (``sensors=``, pipeline.envs.sensors) and
writes each episode as a simulated run (``record=DIR``, pipeline.envs.recording); both read every actor through
the simulate stage's recorder (pipeline.traffic.simulation.RunRecorder), which the feature-only env does without.
"""

from __future__ import annotations

import itertools
import logging
import math
import os
import shutil
import tempfile
import weakref
from dataclasses import fields, replace
from pathlib import Path
from typing import ClassVar

import gymnasium as gym
import numpy as np
import pandas as pd
from gymnasium import spaces

from pipeline.core.config import ScenarioConfig, SimulationConfig
from pipeline.core.config.base import MAX_RUN_SEED, run_seed_problem
from pipeline.core.config.resolve import resolve_scenario
from pipeline.envs import features
from pipeline.envs.options import EnvOptions, RewardWeights
from pipeline.envs.reward import reward_terms
from pipeline.envs.walkways import Walkways
from pipeline.traffic import networks
from pipeline.traffic.demand import Demand, build_demand, network_bus_stops
from pipeline.traffic.parking import place_parked, with_parked
from pipeline.traffic.roadgeometry import load_road_geometry, read_network_geometry, write_road_geometry
from pipeline.traffic.simulation import (
    RunRecorder,
    choose_ego,
    close_sumo,
    require_sumo,
    start_sumo,
    to_trajectories,
    write_sumocfg,
)

log = logging.getLogger(__name__)

_INVALID_DISTANCE = -1.0e8  # SUMO answers about -2^30 when a distance along the route is undefined
_owners = itertools.count()


def collision_record(collision, ego: str, sumo) -> dict:
    """What the ego hit, from SUMO's collision record (``simulation.getCollisions()``): the other party's id, whether
    it is a ``person`` or a ``vehicle``, its type id and speed, the ego's speed, which of the two SUMO calls the
    collider, SUMO's collision type (its collision output's ``type``; e.g. ``collision`` for two vehicles on one
    lane, ``junction`` for overlapping shapes on a junction, ``crossing`` for a person on a pedestrian crossing) and
    the lane and position along it where SUMO saw it. ``other_kind`` is ``unknown`` when SUMO's
    ``collision.action`` removed the other party in this step."""
    ego_first = collision.collider == ego
    other = collision.victim if ego_first else collision.collider
    kind = ("person" if other in sumo.person.getIDList() else
            "vehicle" if other in sumo.vehicle.getIDList() else "unknown")
    return {"other": other, "other_kind": kind,
            "other_type": collision.victimType if ego_first else collision.colliderType,
            "other_speed_mps": float(collision.victimSpeed if ego_first else collision.colliderSpeed),
            "ego_speed_mps": float(collision.colliderSpeed if ego_first else collision.victimSpeed),
            "ego_is_collider": ego_first, "type": collision.type, "lane": collision.lane, "pos_m": float(collision.pos)}


class RoadsynthEnv(gym.Env):
    """One ego in one SUMO scenario. Observation: Dict("ego", "neighbours", "signal", "path") (pipeline.envs.features);
    action: Box(2,) float32 (longitudinal, lateral) acceleration, normalised or in m/s^2 (EnvOptions).

    Args:
        scenario: a scenario NAME (configs/scenarios/) or YAML PATH, as for ``simulate``.
        vehicles, warmup_s: override demand.vehicles and simulation.warmup_s.
        dt: seconds per step (SUMO's step length); None keeps the scenario's.
        options: EnvOptions; any of its fields may also be given as a keyword (``reward`` as RewardWeights or
            a dict of its fields).
        sensors: any of "camera", "lidar", "radar": rendered each step into the observation, ground truth in
            ``info["sensors"]`` (pipeline.envs.sensors); ``rig`` and ``condition`` as for ``roadsynth render``.
        record: a folder; each episode is written to ``record/episode-NNNN`` as a simulated run
            (pipeline.envs.recording) when it ends (or at ``reset``/``close``, if it did not).
        render_mode: None or "rgb_array": ``render()`` gives the camera image with the "camera" sensor, else a top
            view around the ego (pipeline.envs.topview).
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, scenario: str | Path = "highway", *, vehicles: int | None = None, warmup_s: float | None = None,
                 dt: float | None = None, options: EnvOptions | None = None, render_mode: str | None = None,
                 sensors: list[str] | tuple[str, ...] | None = None, rig: str | Path = "default",
                 condition: str | Path = "noon", record: str | Path | None = None, **option_kwargs) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if dt is not None and (isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt)
                               or not 0 < dt <= 1.0):
            raise ValueError(f"dt: expected the seconds of one step, a number in (0, 1], got {dt!r}")
        self._closed = False
        self._work: Path | None = None
        self._walkways: Walkways | None = None  # built on first use (on_road) from the network's road geometry
        self._work_cleanup: weakref.finalize | None = None
        self.render_mode = render_mode
        self.options = _options(options, option_kwargs)
        # The renderer (open3d, numba kernels) and OpenCV are imported only when asked for: a feature-only env
        # starts without them.
        self.sensors = None
        if sensors:
            from pipeline.envs.sensors import LiveSensors, check_sensors

            self.sensors = LiveSensors(check_sensors(sensors), rig, condition)
        self.record_dir = Path(record) if record is not None else None
        if self.record_dir is not None:
            _check_writable(self.record_dir)
        self._episodes_recorded = 0
        self._recorder: RunRecorder | None = None
        self._tables_seed: int | None = None
        self._topview = None
        if render_mode == "rgb_array" and "camera" not in (sensors or ()):
            from pipeline.envs.topview import TopView

            self._topview = TopView()
        config, _ = resolve_scenario(scenario, vehicles=vehicles, warmup_s=warmup_s,
                                     duration_s=self.options.time_limit_s)
        self.config: ScenarioConfig = config
        step = dt if dt is not None else config.simulation.step_length_s
        self.sim = SimulationConfig.model_validate({**config.simulation.model_dump(), "step_length_s": step,
                                                    "record_hz": 1.0 / step})
        o = self.options
        self.observation_space = features.observation_space(o.max_speed_mps, o.accel_min_mps2, o.accel_max_mps2,
                                                            o.neighbour_range_m, o.nearby_k)
        if self.sensors is not None:
            self.observation_space = spaces.Dict({**self.observation_space.spaces, **self.sensors.spaces()})
        self.metadata = {**self.metadata, "render_fps": 1.0 / step}
        if o.normalize_actions:
            self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        else:
            self.action_space = spaces.Box(np.array([o.accel_min_mps2, -o.lat_accel_max_mps2], dtype=np.float32),
                                           np.array([o.accel_max_mps2, o.lat_accel_max_mps2], dtype=np.float32))
        self._owner = f"RoadsynthEnv({config.name}, #{next(_owners)})"
        self._net_file: Path | None = None
        self._demands: dict[int, tuple[Path, list[str], Demand]] = {}
        self._classes: dict[int, dict[str, int]] = {}  # run seed -> vehicle id -> features.CLASS_ORDER index + 1
        self._sumo = None
        self.ego_id = ""
        self._pose: tuple[float, float, float] | None = None
        self._path = np.zeros((0, 2))
        # SUMO searches lanes within this radius of the moved ego (default 100 m): the ego moves at most
        # max_speed x dt a step, so a few metres beyond that is enough, and the search is the step's main cost.
        self._match_m = o.max_speed_mps * step + 10.0

    # ---- episode ----

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self._require_open("reset")
        if seed is not None and run_seed_problem(seed):
            raise ValueError(f"reset(seed={seed!r}): {run_seed_problem(seed)}")
        super().reset(seed=seed)
        self._write_record(None)  # an episode left unfinished is written as far as it went
        run_seed = int(seed) if seed is not None else int(self.np_random.integers(0, MAX_RUN_SEED + 1))
        sumocfg, candidates, _ = self.sumo_inputs(run_seed)
        sumo = start_sumo(["-c", str(sumocfg), "--no-warnings", "true", "--no-step-log", "true",
                           "--end", f"{self.sim.warmup_s + self.options.time_limit_s + 60:g}"], self._owner,
                          yielding=True)
        self._sumo = sumo
        self._run_seed = run_seed
        dt = self.sim.step_length_s
        self._warm_steps = round(self.sim.warmup_s / dt)
        recorder = RunRecorder(sumo) if self.record_dir is not None or self.sensors is not None else None
        for step in range(self._warm_steps + 1):
            sumo.simulationStep()
            if recorder is not None:
                recorder.count(round(step * dt, 6))
        # The same draw as simulate's ego choice (pipeline.traffic.simulation.run).
        self.ego_id = ego = choose_ego(sumo, candidates, self.config.ego, self.sim,
                                       np.random.default_rng([run_seed, 0xE90]))
        sumo.vehicle.setSpeedMode(ego, 0)
        sumo.vehicle.setLaneChangeMode(ego, 0)
        self._vclass = sumo.vehicle.getVehicleClass(ego)
        self._lane_ok: dict[str, bool] = {}
        self._lane_shapes: dict[str, tuple[np.ndarray, float]] = {}
        self._ego_width_m = float(sumo.vehicle.getWidth(ego))
        # The persons around the ego, for the "path" row (features.path_row).
        sumo.vehicle.subscribeContext(ego, features.CMD_GET_PERSON_VARIABLE, self.options.neighbour_range_m,
                                      features.PERSON_CONTEXT_VARS)
        if self.options.nearby_k > 0:
            # Collecting every vehicle in range each step costs about as much as the rest of the features: only
            # when "nearby" asks for it (the slots then read their vehicles from it too).
            sumo.vehicle.subscribeContext(ego, features.CMD_GET_VEHICLE_VARIABLE, self.options.neighbour_range_m,
                                          features.CONTEXT_VARS)
        self._start_time_s = sumo.simulation.getTime()
        self._frame = 0
        self._truth: dict[str, object] | None = None
        self._recorder = recorder
        if recorder is not None:
            recorder.subscribe_all()
        if self.sensors is not None:
            self.sensors.start(self._work / "roads", run_seed)
        if self._topview is not None:
            self._topview.start(sumo)
        self._speed = sumo.vehicle.getSpeed(ego)
        self._lat_speed = 0.0
        self._accel = 0.0
        self._last_edge = sumo.vehicle.getRoute(ego)[-1]
        self._last_edge_length = sumo.lane.getLength(f"{self._last_edge}_0")
        self._route_left = self._route_left_m()
        self._obs = self._observe()
        self._sense()
        return self._obs, self._info()

    def step(self, action):
        self._require_open("step")
        if self._sumo is None:
            raise RuntimeError("step() before reset()")
        require_sumo(self._owner)
        sumo, ego, o, dt = self._sumo, self.ego_id, self.options, self.sim.step_length_s
        a_lon, a_lat = self._accelerations(np.asarray(action, dtype=np.float64))
        speed = min(max(self._speed + a_lon * dt, 0.0), o.max_speed_mps)
        accel = (speed - self._speed) / dt
        jerk = (accel - self._accel) / dt
        limit = min(o.lat_speed_max_mps, speed)
        lat_speed = min(max(self._lat_speed + a_lat * dt, -limit), limit)
        # The lane's direction half a step ahead: moving along the tangent at the start would drift outward on curves.
        lane_yaw = self._lane_yaw(0.5 * speed * dt)
        heading = lane_yaw + (math.atan2(lat_speed, speed) if speed > 0 else 0.0)
        fx, fy = sumo.vehicle.getPosition(ego)
        c, s = math.cos(lane_yaw), math.sin(lane_yaw)
        x = fx + (speed * c - lat_speed * s) * dt
        y = fy + (speed * s + lat_speed * c) * dt
        # No edge or lane hint: SUMO prefers a hinted lane, which would keep the ego on it across the lane border.
        sumo.vehicle.moveToXY(ego, "", -1, x, y, angle=90.0 - math.degrees(heading), keepRoute=2,
                              matchThreshold=self._match_m)
        sumo.simulationStep()
        self._frame += 1
        if self._recorder is not None:
            self._recorder.count(self._frame_time_s())
            self._recorder.subscribe_departed()
        self._speed, self._accel, self._lat_speed = speed, accel, lat_speed

        collision = next((col for col in sumo.simulation.getCollisions() if ego in (col.collider, col.victim)), None)
        collided = collision is not None
        gone = ego in sumo.simulation.getArrivedIDList() or ego in sumo.simulation.getStartingTeleportIDList()
        reason = None
        if collided:
            reason = "collision"
        elif gone:
            reason = "left_network"
        off_road = False
        progress = 0.0
        half_width = 1.75
        if not gone:
            route_left = self._route_left_m()
            off_road, half_width = self._off_road()
            if route_left is None:
                off_road = True
                reason = reason or "left_route"
            else:
                progress = self._route_left - route_left
                self._route_left = route_left
            if off_road and reason is None:
                reason = "off_road"
            self._obs = self._observe()
            self._sense()
        target = o.reward.target_speed_mps or (sumo.vehicle.getAllowedSpeed(ego) if not gone else 1.0)
        terms = reward_terms(o.reward, progress_m=progress, target_speed_mps=max(target, 1.0), dt_s=dt, jerk_mps3=jerk,
                             lateral_offset_m=float(self._obs["ego"][3]), half_lane_width_m=half_width,
                             collided=collided, off_road=off_road)
        terminated = collided or off_road
        elapsed = sumo.simulation.getTime() - self._start_time_s
        truncated = False
        if not terminated:
            if gone or self._route_left <= max(1.0, 2 * speed * dt):
                truncated, reason = True, reason or "route_end"
            elif elapsed >= o.time_limit_s - 1e-9:
                truncated, reason = True, "time_limit"
        info = self._info()
        info["reward_terms"] = terms
        if reason is not None:
            info["reason"] = reason
        if collision is not None:
            info["collision"] = collision_record(collision, ego, sumo)
        if (terminated or truncated) and self._recorder is not None:
            written = self._write_record(reason)
            if written is not None:
                info["record_dir"] = str(written)
        return self._obs, float(sum(terms.values())), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The camera image (with the "camera" sensor) or a top view around the ego, for render_mode "rgb_array"."""
        if self.render_mode is None:
            return None
        self._require_open("render")
        if self._sumo is None:
            raise RuntimeError("render() before reset()")
        require_sumo(self._owner)
        if self._topview is None:
            return self._obs["camera"]
        return self._topview.draw(self._sumo, self.ego_id)

    def close(self) -> None:
        if self._sumo is not None:
            self._write_record(None)
        close_sumo(self._owner)
        self._sumo = None
        if self._work_cleanup is not None:
            self._work_cleanup()
        self._work, self._work_cleanup, self._net_file, self._demands, self._classes = None, None, None, {}, {}
        self._walkways = None
        self._closed = True

    def _require_open(self, call: str) -> None:
        if self._closed:
            raise RuntimeError(f"{self._owner}: {call}() after close(); make a new env")

    def ego_length_m(self) -> float:
        """The ego's length (its leader's gap is ds minus half of both lengths)."""
        require_sumo(self._owner)
        return self._sumo.vehicle.getLength(self.ego_id)

    def ego_width_m(self) -> float:
        """The ego's width (the "path" row's corridor is as wide, plus a person's reach on each side)."""
        require_sumo(self._owner)
        return self._ego_width_m

    def ego_height_m(self) -> float:
        """The ego's height as its sensors' frame has it: the ego frame's origin (its box centre) lies half of it above
        the road."""
        if self._sumo is None:
            raise RuntimeError(f"{self._owner}: ego_height_m() before reset()")
        actors, _ = self._actor_tables()  # cached per run seed; the sensors read it every step
        return float(actors.at[self.ego_id, "height_m"])

    def ego_pose(self) -> tuple[float, float, float]:
        """The ego's box centre (x, y) and yaw (rad, CCW from +x) in the world frame, at the current observation
        (the last one's after the ego has left): what a driving stack's localisation gives it."""
        if self._pose is None:
            raise RuntimeError(f"{self._owner}: ego_pose() before reset()")
        return self._pose

    def lane_width_m(self) -> float:
        """Width of the ego's lane."""
        require_sumo(self._owner)
        return self._sumo.lane.getWidth(self._sumo.vehicle.getLaneID(self.ego_id))

    def action_from_mps2(self, lon_mps2: float, lat_mps2: float) -> np.ndarray:
        """The action (in this env's action space, clipped to it) for accelerations in m/s^2."""
        o = self.options
        lon = min(max(lon_mps2, o.accel_min_mps2), o.accel_max_mps2)
        lat = min(max(lat_mps2, -o.lat_accel_max_mps2), o.lat_accel_max_mps2)
        if o.normalize_actions:
            lon = lon / o.accel_max_mps2 if lon > 0 else lon / -o.accel_min_mps2
            lat = lat / o.lat_accel_max_mps2
        return np.array([lon, lat], dtype=np.float32)

    # ---- helpers ----

    def sumo_inputs(self, run_seed: int) -> tuple[Path, list[str], Demand]:
        """The run's .sumocfg, ego candidates and demand: network built once per env, demand once per run seed."""
        if self._work is None:
            self._work = Path(tempfile.mkdtemp(prefix="roadsynth-env-"))
            # Removed by close(), or when the env is garbage-collected or the interpreter exits without close().
            self._work_cleanup = weakref.finalize(self, shutil.rmtree, str(self._work), True)
            self._net_file = networks.build_network(self.config.network, self._work / "net")
            if self.sensors is not None:
                write_road_geometry(self._net_file, self._work / "roads",
                                    network_bus_stops(self._net_file, self.config.demand))
        if run_seed not in self._demands:
            out = self._work / f"seed{run_seed}"
            out.mkdir()
            demand = build_demand(self.config.demand, self._net_file, out, out / "_work", run_seed)
            shutil.rmtree(out / "_work")
            sumocfg = write_sumocfg(out, str(self._net_file), demand.routes_file.name, self.sim, run_seed)
            vehicles = demand.vehicles
            candidates = vehicles.loc[vehicles["cls"] == self.config.ego.cls.value, "vehicle_id"].tolist()
            self._demands[run_seed] = (sumocfg, candidates, demand)
            index = {c.value: i + 1 for i, c in enumerate(features.CLASS_ORDER)}
            self._classes[run_seed] = dict(zip(vehicles["vehicle_id"], vehicles["cls"].map(index), strict=True))
        return self._demands[run_seed]

    def _accelerations(self, action: np.ndarray) -> tuple[float, float]:
        o = self.options
        if action.shape != (2,) or not np.all(np.isfinite(action)):
            raise ValueError(f"action must be 2 finite numbers (longitudinal, lateral), got {action!r}")
        if not o.normalize_actions:
            return (float(np.clip(action[0], o.accel_min_mps2, o.accel_max_mps2)),
                    float(np.clip(action[1], -o.lat_accel_max_mps2, o.lat_accel_max_mps2)))
        lon, lat = np.clip(action, -1.0, 1.0)
        return (float(lon * (o.accel_max_mps2 if lon > 0 else -o.accel_min_mps2)), float(lat * o.lat_accel_max_mps2))

    def _lane_yaw(self, ahead_m: float = 0.0) -> float:
        """yaw (rad) of the ego's lane at its position, or ``ahead_m`` further along the lane (within it)."""
        sumo, ego = self._sumo, self.ego_id
        lane = sumo.vehicle.getLaneID(ego)
        pos = min(sumo.vehicle.getLanePosition(ego) + ahead_m, sumo.lane.getLength(lane))
        angle = sumo.lane.getAngle(lane, pos)
        return features.yaw_from_sumo_angle(angle)

    def _route_left_m(self) -> float | None:
        d = self._sumo.vehicle.getDrivingDistance(self.ego_id, self._last_edge, self._last_edge_length)
        return None if d < _INVALID_DISTANCE else max(d, 0.0)

    def _off_road(self) -> tuple[bool, float]:
        """Whether the ego's centre is beyond the outer border of the lanes it may drive on (a sidewalk or
        parking lane beside it counts as off the road), or on a lane it may not use; half its lane's width."""
        sumo, ego = self._sumo, self.ego_id
        lane = sumo.vehicle.getLaneID(ego)
        half = 0.5 * sumo.lane.getWidth(lane)
        lat, index = sumo.vehicle.getLateralLanePosition(ego), sumo.vehicle.getLaneIndex(ego)
        beyond = ((lat > half and not self.lane_drivable(index + 1))
                  or (lat < -half and not self.lane_drivable(index - 1))
                  or abs(lat) > 2 * half or not self._drivable(lane))
        return bool(beyond), half

    def lane_reach_m(self, index: int) -> float:
        """How far the ego's route lets it drive on lane ``index`` of its current edge, from the ego's position along
        the edge, before it must change lanes (SUMO's best lanes for the ego: map and route knowledge); 0 for a lane
        the edge does not have, and inf inside a junction (no lanes to choose there)."""
        require_sumo(self._owner)
        sumo, ego = self._sumo, self.ego_id
        road = sumo.vehicle.getRoadID(ego)
        if road.startswith(":"):
            return math.inf
        lane = f"{road}_{index}"
        reach = next((float(row[1]) for row in sumo.vehicle.getBestLanes(ego) if row[0] == lane), 0.0)
        return max(reach - sumo.vehicle.getLanePosition(ego), 0.0)

    def speed_limit_mps(self) -> float | None:
        """The speed limit of the ego's lane (map knowledge); None inside a junction, whose internal lanes carry
        SUMO's turning speeds rather than a limit."""
        require_sumo(self._owner)
        lane = self._sumo.vehicle.getLaneID(self.ego_id)
        return None if lane.startswith(":") else float(self._sumo.lane.getMaxSpeed(lane))

    def lane_drivable(self, index: int) -> bool:
        """Whether lane ``index`` of the ego's current edge exists and admits the ego's vehicle class."""
        require_sumo(self._owner)
        sumo = self._sumo
        road = sumo.vehicle.getRoadID(self.ego_id)
        return 0 <= index < sumo.edge.getLaneNumber(road) and self._drivable(f"{road}_{index}")

    def _drivable(self, lane: str) -> bool:
        if lane not in self._lane_ok:
            self._lane_ok[lane] = self._vclass not in self._sumo.lane.getDisallowed(lane)
        return self._lane_ok[lane]

    def path_xy(self) -> np.ndarray:
        """(N, 2) world vertices of the ego's path as of the last observation: its front bumper, then the centre
        lines of the lanes its route takes, up to ``neighbour_range_m`` (features.path_polyline; map knowledge);
        empty before the first reset."""
        self._require_open("path_xy")
        return self._path

    def on_road(self, xy: np.ndarray) -> np.ndarray:
        """(M,) bool for (M, 2) world places: whether each lies on the carriageway or a crossing rather than a
        sidewalk or a junction's walking area, from the network's road geometry (:class:`walkways.Walkways`; map
        knowledge, for places estimated from the sensors: the ground truth asks SUMO which lane a person is on)."""
        self._require_open("on_road")
        if self._walkways is None:
            roads = self._work / "roads"
            geometry = (load_road_geometry(roads) if (roads / "lanes.parquet").is_file()
                        else read_network_geometry(self._net_file))
            self._walkways = Walkways.from_geometry(geometry)
        return self._walkways.on_road(xy)

    def _lane_shape(self, lane: str) -> tuple[np.ndarray, float]:
        if lane not in self._lane_shapes:
            self._lane_shapes[lane] = (np.array(self._sumo.lane.getShape(lane), np.float64).reshape(-1, 2),
                                       float(self._sumo.lane.getLength(lane)))
        return self._lane_shapes[lane]

    def _path_polyline(self) -> np.ndarray:
        sumo, ego, reach = self._sumo, self.ego_id, self.options.neighbour_range_m
        shape, length = self._lane_shape(sumo.vehicle.getLaneID(ego))
        shapes, ahead = [shape], length - sumo.vehicle.getLanePosition(ego)
        for link in sumo.vehicle.getNextLinks(ego):  # (lane, prio, open, foe, via lane, state, direction, length)
            if ahead >= reach:
                break
            for lane in (link[4], link[0]):
                if lane:
                    shape, length = self._lane_shape(lane)
                    shapes.append(shape)
                    ahead += length
        return features.path_polyline(sumo.vehicle.getPosition(ego), shapes, reach)

    def _people(self, context: dict[str, dict[int, object]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M, 2) positions and velocities of the persons on foot in the ego's context subscription, by id, and (M,)
        whether each is on the carriageway (a lane the ego may drive on) or a crossing."""
        ids = sorted(pid for pid, values in context.items()
                     if features.VAR_VEHICLE in values and not values[features.VAR_VEHICLE])
        if not ids:
            return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, bool)
        values = np.array([(*context[p][features.VAR_POSITION], context[p][features.VAR_ANGLE],
                            context[p][features.VAR_SPEED]) for p in ids], np.float64)
        yaw = np.radians(90.0 - values[:, 2])
        # A person who stands (a stop, not a walk) has no lane, only an edge: on a crossing, or taken as off the road.
        lanes = [str(context[p][features.VAR_LANE_ID]) for p in ids]
        edges = [str(context[p][features.VAR_ROAD_ID]) for p in ids]
        on_road = np.array([features.is_crossing(lane or edge) or (bool(lane) and self._drivable(lane))
                            for lane, edge in zip(lanes, edges, strict=True)], bool)
        return values[:, :2], values[:, 3:4] * np.column_stack([np.cos(yaw), np.sin(yaw)]), on_road

    def _observe(self) -> dict[str, np.ndarray]:
        sumo, ego = self._sumo, self.ego_id
        lane_yaw = self._lane_yaw()
        cx, cy, yaw = features.centre_xy(sumo, ego)
        self._pose = (cx, cy, yaw)
        heading_rel = (yaw - lane_yaw + math.pi) % (2 * math.pi) - math.pi
        ego_row = np.array([self._speed, self._accel, sumo.vehicle.getLaneIndex(ego),
                            sumo.vehicle.getLateralLanePosition(ego), heading_rel, self._route_left or 0.0])
        space = self.observation_space
        # Both context subscriptions' results in one dict: the persons' entries (features.VAR_VEHICLE) apart.
        results = sumo.vehicle.getContextSubscriptionResults(ego)
        context = {vid: values for vid, values in results.items() if features.VAR_VEHICLE not in values}
        self._path = self._path_polyline()
        people_xy, people_velocity, on_road = self._people(results)
        obs = {
            "ego": np.clip(ego_row, space["ego"].low, space["ego"].high).astype(np.float32),
            "neighbours": features.neighbour_rows(sumo, ego, self._speed, lane_yaw, self.options.neighbour_range_m,
                                                  context, space["neighbours"]),
            "signal": features.signal_row(sumo.vehicle.getNextTLS(ego), self.options.neighbour_range_m),
            "path": np.clip(features.path_row(self._path, people_xy, people_velocity, self._speed,
                                              0.5 * self._ego_width_m, on_road=on_road),
                            space["path"].low, space["path"].high),
        }
        if "nearby" in space.spaces:
            obs["nearby"] = features.nearby_rows(context, ego, (cx, cy), lane_yaw, self._speed,
                                                 self._classes[self._run_seed], space["nearby"])
        return obs

    def _info(self) -> dict[str, object]:
        info = {"ego_id": self.ego_id, "run_seed": self._run_seed,
                "time_s": round(self._sumo.simulation.getTime() - self._start_time_s, 6)}
        if self._truth is not None:
            info["sensors"] = self._truth
        return info

    def _frame_time_s(self) -> float:
        """The current frame's time as simulate labels it (frame 0 at the end of the warm-up)."""
        return round((self._warm_steps + self._frame) * self.sim.step_length_s, 6)

    def _sense(self) -> None:
        """Record the current frame (``record=``) and render its sensors into the observation (``sensors=``)."""
        if self._recorder is None:
            return
        frame, time_s = self._frame, self._frame_time_s()
        if self.record_dir is not None:
            self._recorder.record(frame, time_s, self.ego_id)
        if self.sensors is None:
            return
        snapshot = self._recorder.snapshot(frame, time_s, self.ego_id)
        if snapshot is None:
            return  # the ego left: the last frame's sensor observation stays
        vehicles, persons, tls_rows = snapshot
        actors, parked = self._actor_tables()
        table = with_parked(to_trajectories(vehicles, persons, actors, self.ego_id), parked,
                            int(actors["track_id"].max()) + 1)
        obs, self._truth = self.sensors.render(table, frame, {tls: state for _, _, tls, state in tls_rows})
        self._obs.update(obs)

    def _actor_tables(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """The run's actor table (Demand.actor_table) and parked vehicles, as simulate builds them (once per seed)."""
        if self._tables_seed != self._run_seed:
            _, _, demand = self._demands[self._run_seed]
            self._tables = demand.actor_table(), place_parked(self.config.demand, self._net_file, self._run_seed,
                                                              demand.bus_stops)
            self._tables_seed = self._run_seed
        return self._tables

    def _write_record(self, end: str | None) -> Path | None:
        """Write the episode recorded so far (``record=``), once; its folder, or None when there is none."""
        if self.record_dir is None or self._recorder is None or not self._recorder.vehicles.frame:
            return None
        from pipeline.envs.recording import episode_dir, write_episode

        recorder, self._recorder = self._recorder, None
        out = episode_dir(self.record_dir, self._episodes_recorded)
        _, _, demand = self._demands[self._run_seed]
        write_episode(out, config=self.config, sim=self.sim, options=self.options, seed=self._run_seed,
                      net_file=self._net_file, demand=demand, recorder=recorder, ego_id=self.ego_id, end=end)
        self._episodes_recorded += 1
        log.info("recorded the episode (%s) in %s", end or "stopped", out)
        return out


def _check_writable(folder: Path) -> None:
    """Raise ValueError, naming ``record=``, when episodes cannot be written into ``folder`` (checked at
    construction: an episode is written when it ends, and would otherwise be lost then)."""
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"record={folder}: is a file; expected a folder to write episodes into")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".roadsynth-env-probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"record={folder}: cannot write episodes there ({exc.strerror or exc})") from None


def scenario_env(scenario: str | Path | None = None, **kwargs) -> RoadsynthEnv:
    """``roadsynth/Scenario-v0``: like RoadsynthEnv, but the scenario (a NAME or YAML PATH) must be named."""
    if scenario is None:
        raise TypeError("roadsynth/Scenario-v0 needs scenario=NAME (configs/scenarios/) or a YAML PATH")
    return RoadsynthEnv(scenario, **kwargs)


def _options(options: EnvOptions | None, kwargs: dict) -> EnvOptions:
    base = options or EnvOptions()
    known = {f.name for f in fields(EnvOptions)}
    unknown = sorted(set(kwargs) - known)
    if unknown:
        raise TypeError(f"unknown option(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    if isinstance(kwargs.get("reward"), dict):
        kwargs = {**kwargs, "reward": RewardWeights(**kwargs["reward"])}
    return replace(base, **kwargs)
