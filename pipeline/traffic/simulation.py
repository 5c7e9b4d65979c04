"""Running a scenario in libsumo and recording every actor at a fixed rate.

libsumo runs one simulation per process (start/close in sequence is fine; parallel runs need
processes). Actors are read through subscriptions, not per-vehicle getters: after the warm-up every
running vehicle and person is subscribed once, and each newly departed one when it appears.

Recorded positions follow docs/design.md: SUMO's front-bumper position and clockwise-from-north angle are
converted to box centre and yaw (CCW from east); centre z = road z + height / 2.
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from pipeline.core.config import EgoConfig, SimulationConfig
from pipeline.core.geometry import sumo_front_to_center
from pipeline.traffic.demand import FORMATION_PARAM, STANDING_LATERAL_M
from pipeline.traffic.sumo_tools import binary

log = logging.getLogger(__name__)

SUMOCFG_FILE = "run.sumocfg"
# traci.constants, spelled out so this module needs only libsumo at run time.
VAR_POSITION3D, VAR_ANGLE, VAR_SPEED, VAR_ACCELERATION, VAR_LANE_ID, VAR_SIGNALS = 0x39, 0x43, 0x40, 0x72, 0x51, 0x5B
VAR_ROAD_ID, TL_STATE = 0x50, 0x20
VEHICLE_VARS = (VAR_POSITION3D, VAR_ANGLE, VAR_SPEED, VAR_ACCELERATION, VAR_LANE_ID, VAR_SIGNALS)
PERSON_VARS = (VAR_POSITION3D, VAR_ANGLE, VAR_SPEED, VAR_ROAD_ID)
SIGNAL_BRAKELIGHT = 8
STAGE_WAITING = 1  # libsumo's stage type of a person who stands (a <stop> in its plan)
# SUMO draws a person who waits on a lane MSStage::ROADSIDE_OFFSET (3 m) to the right of its edge's first lane, the
# sidewalk, whose centre it walks on once it moves on: recorded there, a standing person would stand 1.75 m beyond a
# 2.5 m sidewalk (in a wall) and jump 3 m when it starts to walk. We put it on the sidewalk, STANDING_LATERAL_M right
# of the sidewalk's centre: negative, towards the kerb, where SUMO's striping model starts most of them walking
# (measured on an urban run: 124 of 139 at -0.93 m, the others at +0.35 m), so that they step off without a jump. A
# member of a standing group stands at its place in the group's formation instead (pipeline.traffic.demand), facing
# the others, and walks from there onto SUMO's line over STEP_OFF_S once the group moves on.
SUMO_ROADSIDE_OFFSET_M = 3.0
STEP_OFF_S = 1.0


class SimulationError(RuntimeError):
    """The simulation could not produce a valid recording (e.g. no vehicle can serve as ego)."""


class SumoBusyError(RuntimeError):
    """A second libsumo simulation was asked for while one is open in this process, or a simulation that was taken
    over (see :func:`start_sumo`) was used by its former owner."""


# libsumo holds one simulation per process, and a second start() silently replaces the first (its clock
# jumps back, no error): every start goes through start_sumo, which knows who holds the open one.
_active_owner: str | None = None
_yielding = False  # whether the open simulation may be taken over by another owner


def start_sumo(args: list[str], owner: str, *, yielding: bool = False):
    """Start libsumo with ``args`` (after the binary) for ``owner``; returns the libsumo module.

    ``owner`` names who holds the simulation (shown in errors). The same owner may restart (its open simulation
    is closed first). A different owner gets :class:`SumoBusyError` until :func:`close_sumo`, unless the open
    simulation was started ``yielding``: then it is closed and the new owner takes over, and the former owner,
    which checks :func:`require_sumo` before each use, gets :class:`SumoBusyError` there instead of reading the
    other simulation (the driving environment's simulations yield: Gymnasium's env checker opens a second env
    while the first is open, and only uses the second).
    """
    global _active_owner, _yielding
    import libsumo

    if _active_owner is not None and _active_owner != owner and not _yielding:
        raise SumoBusyError(f"libsumo already runs a simulation in this process (held by {_active_owner}); "
                            f"{owner} cannot start another: close the first, or use one process per simulation")
    if _active_owner is not None:
        if _active_owner != owner:
            log.info("libsumo: %s takes over this process's simulation from %s", owner, _active_owner)
        libsumo.close()
        _active_owner = None
    libsumo.start([binary("sumo"), *args])
    _active_owner, _yielding = owner, yielding
    return libsumo


def require_sumo(owner: str) -> None:
    """Raise :class:`SumoBusyError` unless ``owner`` holds this process's simulation."""
    if _active_owner != owner:
        now = f"taken over by {_active_owner}" if _active_owner is not None else "closed"
        raise SumoBusyError(f"{owner}'s SUMO simulation was {now} (libsumo runs one simulation per process); "
                            "reset() to start it again, or use one process per env (gymnasium.vector.AsyncVectorEnv)")


def close_sumo(owner: str) -> None:
    """Close the simulation ``owner`` holds; nothing if it holds none."""
    global _active_owner
    if _active_owner != owner:
        return
    import libsumo

    _active_owner = None
    libsumo.close()


def active_sumo_owner() -> str | None:
    """Who holds this process's libsumo simulation, or None."""
    return _active_owner


def write_sumocfg(out_dir: Path, net_file: str, routes_file: str, sim: SimulationConfig, seed: int) -> Path:
    """Write the .sumocfg that replays the run in plain ``sumo`` / ``sumo-gui``."""
    root = ET.Element("configuration")
    inp = ET.SubElement(root, "input")
    ET.SubElement(inp, "net-file", value=net_file)
    ET.SubElement(inp, "route-files", value=routes_file)
    time = ET.SubElement(root, "time")
    ET.SubElement(time, "begin", value="0")
    ET.SubElement(time, "end", value=f"{sim.warmup_s + sim.duration_s:g}")
    ET.SubElement(time, "step-length", value=f"{sim.step_length_s:g}")
    proc = ET.SubElement(root, "processing")
    ET.SubElement(proc, "time-to-teleport", value=f"{sim.time_to_teleport_s:g}")
    ET.SubElement(proc, "collision.action", value=sim.collision_action)
    ET.SubElement(proc, "collision.check-junctions", value="true")
    ET.SubElement(root, "random_number").append(ET.Element("seed", value=str(seed)))
    report = ET.SubElement(root, "report")
    ET.SubElement(report, "no-step-log", value="true")
    ET.SubElement(report, "duration-log.disable", value="true")
    ET.indent(root)
    path = out_dir / SUMOCFG_FILE
    path.write_text(ET.tostring(root, encoding="unicode") + "\n")
    return path


@dataclass
class ActorColumns:
    """Growing per-record columns (one entry per actor per recorded frame)."""

    frame: list[np.ndarray] = field(default_factory=list)
    time_s: list[np.ndarray] = field(default_factory=list)
    actor_id: list[str] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)  # (n, 7): x, y, z, angle, speed, accel, signals
    lane_id: list[str] = field(default_factory=list)

    def add(self, frame: int, time_s: float, results: dict[str, dict[int, object]], person: bool) -> None:
        if not results:
            return
        # One tuple per actor, built in a comprehension: this runs for every actor of every frame.
        if person:
            rows = [(*r[VAR_POSITION3D], r[VAR_ANGLE], r[VAR_SPEED], 0.0, 0) for r in results.values()]
            self.lane_id.extend(r[VAR_ROAD_ID] for r in results.values())
        else:
            rows = [(*r[VAR_POSITION3D], r[VAR_ANGLE], r[VAR_SPEED], r[VAR_ACCELERATION], r[VAR_SIGNALS])
                    for r in results.values()]
            self.lane_id.extend(r[VAR_LANE_ID] for r in results.values())
        self.actor_id.extend(results)
        self.values.append(np.array(rows, dtype=np.float64))
        self.frame.append(np.full(len(rows), frame, dtype=np.int32))
        self.time_s.append(np.full(len(rows), time_s))

    def extend(self, other: ActorColumns) -> None:
        """Append ``other``'s rows."""
        for name in ("frame", "time_s", "actor_id", "values", "lane_id"):
            getattr(self, name).extend(getattr(other, name))


@dataclass(frozen=True)
class Recording:
    """What a run produced: trajectories (one row per actor per frame), traffic-light states and stats."""

    trajectories: pd.DataFrame
    tls_states: pd.DataFrame
    stats: dict[str, object]
    ego_id: str


def choose_ego(sumo, candidates: list[str], ego: EgoConfig, sim: SimulationConfig, rng: np.random.Generator) -> str:
    """The named vehicle, or a random running vehicle whose remaining route covers the recording."""
    running = sorted(sumo.vehicle.getIDList())
    if ego.vehicle_id is not None:
        if ego.vehicle_id not in running:
            raise SimulationError(f"ego.vehicle_id {ego.vehicle_id!r} is not driving at the end of the warm-up "
                                  f"({len(running)} vehicles are, e.g. {', '.join(running[:5])})")
        return ego.vehicle_id
    eligible = []
    for vid in sorted(set(running) & set(candidates)):
        route = sumo.vehicle.getRoute(vid)
        last = route[-1]
        remaining = sumo.vehicle.getDrivingDistance(vid, last, sumo.lane.getLength(f"{last}_0"))
        speed = max(sumo.vehicle.getSpeed(vid), sumo.vehicle.getAllowedSpeed(vid))
        if remaining >= ego.route_margin * sim.duration_s * speed and sumo.vehicle.getSpeed(vid) >= ego.min_speed_mps:
            eligible.append(vid)
    if not eligible:
        raise SimulationError(f"no {ego.cls.value} driving at the end of the warm-up ({sim.warmup_s} s) has a route "
                              f"long enough for {sim.duration_s} s of recording and a speed >= ego.min_speed_mps "
                              f"({ego.min_speed_mps:g} m/s); shorten simulation.duration_s, lengthen the warm-up, "
                              "lower ego.min_speed_mps, or name ego.vehicle_id")
    if ego.min_neighbours > 0:
        xy = {vid: np.array(sumo.vehicle.getPosition(vid)) for vid in running}
        heading = {vid: np.radians(90.0 - sumo.vehicle.getAngle(vid)) for vid in running}
        counts = neighbours_ahead(np.array([xy[v] for v in eligible]), np.array([heading[v] for v in eligible]),
                                  np.array([xy[v] for v in running]), np.array([heading[v] for v in running]),
                                  ego.neighbour_radius_m)
        enough = [v for v, c in zip(eligible, counts, strict=True) if c >= ego.min_neighbours]
        if not enough:
            most = int(counts.max())
            log.warning("no ego candidate has %d vehicles within %g m ahead; choosing among the %d with the most (%d)",
                        ego.min_neighbours, ego.neighbour_radius_m, int((counts == most).sum()), most)
            enough = [v for v, c in zip(eligible, counts, strict=True) if c == most]
        log.info("ego: %d of %d candidates have >= %d vehicles driving their way within %g m ahead", len(enough),
                 len(eligible),
                 ego.min_neighbours, ego.neighbour_radius_m)
        eligible = enough
    return eligible[int(rng.integers(len(eligible)))]


def neighbours_ahead(xy: np.ndarray, yaw_rad: np.ndarray, others_xy: np.ndarray, others_yaw_rad: np.ndarray,
                     radius_m: float) -> np.ndarray:
    """(N,) int: for each of N vehicles at ``xy`` (N, 2) heading ``yaw_rad`` (N,), the number of the M others
    (positions ``others_xy`` (M, 2), headings ``others_yaw_rad`` (M,)) within ``radius_m`` of it, strictly in
    front of it (positive projection on its heading) and driving its way (headings less than 90 deg apart):
    oncoming traffic passes in a second or two. A vehicle's own position (distance 0) is not in front of it, so
    it never counts itself."""
    d = others_xy[None, :, :] - xy[:, None, :]
    ahead = d[..., 0] * np.cos(yaw_rad)[:, None] + d[..., 1] * np.sin(yaw_rad)[:, None]
    same_way = np.cos(others_yaw_rad[None, :] - yaw_rad[:, None]) > 0
    return ((np.hypot(d[..., 0], d[..., 1]) <= radius_m) & (ahead > 0) & same_way).sum(axis=1)


def run(sumocfg: Path, sim: SimulationConfig, ego: EgoConfig, ego_candidates: list[str], seed: int, *,
        progress: bool = True) -> tuple[ActorColumns, ActorColumns, list[tuple], dict[str, object], str]:
    """Step the simulation; return vehicle and person columns, TLS rows, counters and the ego id."""
    owner = f"simulate({sumocfg})"
    sumo = start_sumo(["-c", str(sumocfg), "--no-warnings", "true"], owner)
    try:
        return _loop(sumo, sim, ego, ego_candidates, np.random.default_rng([seed, 0xE90]), progress)
    finally:
        close_sumo(owner)


def _loop(sumo, sim, ego, ego_candidates, rng, progress):
    # Times follow SUMO's outputs (FCD, sumo-gui): the state after the step that starts at time t is
    # labelled t, while libsumo's clock already reads t + step_length. Frame 0 is the state at warmup_s.
    warm_steps = round(sim.warmup_s / sim.step_length_s)
    last_step = warm_steps + (sim.num_frames - 1) * sim.record_every_steps
    recorder = RunRecorder(sumo)
    ego_id = ""
    bar = tqdm(total=round(sim.warmup_s + sim.duration_s, 3), unit="s", desc="simulate", disable=not progress,
               bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} sim-s [{elapsed}<{remaining}]")
    for step in range(last_step + 1):
        sumo.simulationStep()
        time_s = round(step * sim.step_length_s, 6)
        recorder.count(time_s)
        since = step - warm_steps
        if since == 0:
            ego_id = choose_ego(sumo, ego_candidates, ego, sim, rng)
            recorder.subscribe_all()
        elif since > 0:
            recorder.subscribe_departed()
        recording = since >= 0 and since % sim.record_every_steps == 0
        if recording and not recorder.record(since // sim.record_every_steps, time_s, ego_id):
            log.warning("ego %s left the network at %.1f s; recording stops", ego_id, time_s)
            break
        if (step + 1) % round(1.0 / sim.step_length_s) == 0:
            bar.update(1.0)
    bar.close()
    return recorder.vehicles, recorder.persons, recorder.tls_rows, recorder.stats(), ego_id


class RunRecorder:
    """Records a running libsumo simulation the way ``simulate`` does: counters of every step (departures,
    arrivals, teleports, collisions) and, once :meth:`subscribe_all` was called, every actor and traffic light at
    the frames passed to :meth:`record` (through subscriptions). Used by the simulate loop and by the driving
    environment's ``record=``; :func:`to_trajectories` turns ``vehicles`` and ``persons`` into the table."""

    def __init__(self, sumo) -> None:
        self.sumo = sumo
        self.standing = StandingPlaces(sumo)
        self.vehicles, self.persons = ActorColumns(), ActorColumns()
        self.tls_rows: list[tuple] = []
        self.counters: dict[str, int] = defaultdict(int)
        self.collisions: list[dict[str, object]] = []

    def count(self, time_s: float) -> None:
        """Add the step just simulated (labelled ``time_s``) to the counters; call after every simulationStep."""
        sim, counters = self.sumo.simulation, self.counters
        counters["departed"] += sim.getDepartedNumber()
        counters["arrived"] += sim.getArrivedNumber()
        counters["teleports"] += sim.getStartingTeleportNumber()
        counters["persons_departed"] += sim.getDepartedPersonNumber()
        for col in sim.getCollisions():
            self.collisions.append({"time_s": time_s, "collider": col.collider, "victim": col.victim,
                                    "type": col.type, "lane": col.lane})

    def subscribe_all(self) -> None:
        """Subscribe every vehicle, person and traffic light now in the simulation (once, at frame 0)."""
        sumo = self.sumo
        for vid in sumo.vehicle.getIDList():
            sumo.vehicle.subscribe(vid, VEHICLE_VARS)
        for pid in sumo.person.getIDList():
            sumo.person.subscribe(pid, PERSON_VARS)
        for tls in sumo.trafficlight.getIDList():
            sumo.trafficlight.subscribe(tls, (TL_STATE,))

    def subscribe_departed(self) -> None:
        """Subscribe the vehicles and persons that departed in the last step (every step after frame 0)."""
        sumo = self.sumo
        for vid in sumo.simulation.getDepartedIDList():
            sumo.vehicle.subscribe(vid, VEHICLE_VARS)
        for pid in sumo.simulation.getDepartedPersonIDList():
            sumo.person.subscribe(pid, PERSON_VARS)

    def record(self, frame: int, time_s: float, ego_id: str) -> bool:
        """Record every actor and traffic light as ``frame`` at ``time_s``; False (nothing recorded) when the ego
        is no longer in the simulation."""
        snapshot = self.snapshot(frame, time_s, ego_id)
        if snapshot is None:
            self.counters["ego_left_early"] = 1
            return False
        vehicles, persons, tls_rows = snapshot
        self.vehicles.extend(vehicles)
        self.persons.extend(persons)
        self.tls_rows.extend(tls_rows)
        return True

    def snapshot(self, frame: int, time_s: float,
                 ego_id: str) -> tuple[ActorColumns, ActorColumns, list[tuple]] | None:
        """The subscribed vehicles, persons and traffic-light rows now, as ``frame`` at ``time_s`` (not recorded);
        None when the ego is no longer in the simulation."""
        sumo = self.sumo
        veh_results = sumo.vehicle.getAllSubscriptionResults()
        if ego_id not in veh_results:
            return None
        vehicles, persons = ActorColumns(), ActorColumns()
        vehicles.add(frame, time_s, veh_results, person=False)
        persons.add(frame, time_s, self.standing.place(sumo.person.getAllSubscriptionResults(), time_s), person=True)
        tls_rows = [(frame, time_s, tls, res[TL_STATE])
                    for tls, res in sorted(sumo.trafficlight.getAllSubscriptionResults().items())]
        return vehicles, persons, tls_rows

    def stats(self) -> dict[str, object]:
        """The counters, ``collisions`` (their number) and ``collision_events`` (each one)."""
        return {**self.counters, "collisions": len(self.collisions), "collision_events": self.collisions}


class StandingPlaces:
    """Where the standing persons of a running libsumo simulation stand: :meth:`place` moves each standing person
    from where SUMO draws it (see SUMO_ROADSIDE_OFFSET_M) onto its sidewalk, STANDING_LATERAL_M right of the centre
    line, or to the place the person's FORMATION_PARAM gives (dx along the sidewalk, dy right of its centre line, the
    way it faces from the lane's direction): a member of a standing group in the group's formation, facing the
    others; one standing alone, facing the way drawn for it (:func:`pipeline.traffic.demand._lone_facing`); and one
    with such a place who starts to walk moves from it onto SUMO's line over STEP_OFF_S (no jump in its track). Only
    persons at rest on a normal edge are asked for their stage (one libsumo call each), each person's
    parameter once."""

    def __init__(self, sumo) -> None:
        self.sumo = sumo
        self._formation: dict[str, tuple[float, float, float] | None] = {}
        self._left: dict[str, tuple[float, float, float, float]] = {}  # pid -> its last place: x, y, angle, time

    def _place_of(self, pid: str) -> tuple[float, float, float] | None:
        if pid not in self._formation:
            value = self.sumo.person.getParameter(pid, FORMATION_PARAM)
            self._formation[pid] = tuple(float(v) for v in value.split()) if value else None
        return self._formation[pid]

    def place(self, results: dict[str, dict[int, object]], time_s: float) -> dict[str, dict[int, object]]:
        """Person subscription results with the standing persons (and those stepping off) moved; ``time_s`` the
        snapshot's time (increasing from call to call)."""
        out = results
        sumo = self.sumo
        for pid, r in results.items():
            standing = r[VAR_SPEED] == 0.0 and not str(r[VAR_ROAD_ID]).startswith(":") and \
                sumo.person.getStage(pid).type == STAGE_WAITING
            if standing:
                x, y, z = r[VAR_POSITION3D]
                cx, cy = sumo.simulation.convert2D(r[VAR_ROAD_ID], sumo.person.getLanePosition(pid), 0)
                # SUMO's offset points right of the lane: r; the lane runs along f (r turned left).
                rx, ry = (x - cx) / SUMO_ROADSIDE_OFFSET_M, (y - cy) / SUMO_ROADSIDE_OFFSET_M
                fx, fy = -ry, rx
                formation = self._place_of(pid)
                dx, dy, face = formation if formation is not None else (0.0, STANDING_LATERAL_M, None)
                px, py = cx + fx * dx + rx * dy, cy + fy * dx + ry * dy
                angle = r[VAR_ANGLE]
                if face is not None:  # SUMO's angle: degrees clockwise from north
                    c, s = np.cos(face), np.sin(face)
                    angle = float(np.degrees(np.arctan2(fx * c + rx * s, fy * c + ry * s))) % 360.0
                    self._left[pid] = (px, py, angle, time_s)
            elif pid in self._left:
                lx, ly, la, lt = self._left[pid]
                w = 1.0 - (time_s - lt) / STEP_OFF_S
                if w <= 0.0:
                    del self._left[pid]
                    continue
                x, y, z = r[VAR_POSITION3D]
                px, py = x + w * (lx - x), y + w * (ly - y)
                angle = (r[VAR_ANGLE] + w * ((la - r[VAR_ANGLE] + 180.0) % 360.0 - 180.0)) % 360.0
            else:
                continue
            if out is results:
                out = dict(results)
            out[pid] = {**r, VAR_POSITION3D: (px, py, z), VAR_ANGLE: angle}
        return out


def to_trajectories(vehicles: ActorColumns, persons: ActorColumns, actors: pd.DataFrame,
                    ego_id: str) -> pd.DataFrame:
    """Assemble the trajectories table from recorded columns and the static actor table.

    ``actors`` has one row per actor id: track_id, cls, length_m, width_m, height_m, color_r/g/b.
    """
    parts = []
    for cols in (vehicles, persons):
        if not cols.actor_id:
            continue
        values = np.concatenate(cols.values)
        part = pd.DataFrame({"frame": np.concatenate(cols.frame), "time_s": np.concatenate(cols.time_s),
                             "actor_id": cols.actor_id, "lane_id": cols.lane_id})
        static = actors.loc[part["actor_id"]].reset_index(drop=True)
        centre, yaw = sumo_front_to_center(values[:, :2], values[:, 3], static["length_m"].to_numpy())
        part["x_m"], part["y_m"] = centre[:, 0], centre[:, 1]
        part["z_m"] = values[:, 2] + 0.5 * static["height_m"].to_numpy()
        part["yaw_rad"] = yaw
        part["speed_mps"], part["accel_mps2"] = values[:, 4], values[:, 5]
        part["signals"] = values[:, 6].astype(np.int32)
        for name in ("track_id", "cls", "length_m", "width_m", "height_m", "color_r", "color_g", "color_b"):
            part[name] = static[name].to_numpy()
        parts.append(part)
    if not parts:
        raise SimulationError("nothing was recorded: no actor was in the network during the recording")
    table = pd.concat(parts, ignore_index=True)
    table["is_ego"] = table["actor_id"] == ego_id
    table["braking"] = (table["signals"] & SIGNAL_BRAKELIGHT) != 0
    order = ["frame", "time_s", "track_id", "actor_id", "is_ego", "cls", "x_m", "y_m", "z_m", "yaw_rad",
             "length_m", "width_m", "height_m", "speed_mps", "accel_mps2", "lane_id", "signals", "braking",
             "color_r", "color_g", "color_b"]
    table = table[order].sort_values(["frame", "track_id"], kind="stable").reset_index(drop=True)
    return table.astype({"frame": np.int32, "track_id": np.int32, "signals": np.int32})
