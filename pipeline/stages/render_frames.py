"""Rendering the frames of one shard into a record folder (the render stage's worker side).

A :class:`ShardJob` is a pure function of its inputs: the simulated run, the static world (built once
by the parent and pickled), the rig, the condition, the seed and the frame numbers. Every random draw
comes from a generator seeded by (seed, condition, frame, sensor), so a frame renders the same whether
it is rendered alone, in another shard, or by another worker.
"""

from __future__ import annotations

import contextlib
import functools
import pickle
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pyarrow as pa

from pipeline.core.classes import ObjectClass
from pipeline.core.config import ConditionConfig, RadarConfig, RigConfig
from pipeline.core.geometry import Transform
from pipeline.core.processes import RENDER_THRESHOLDS, ProcessCache, keep_freed_memory
from pipeline.core.record import FRAME_COLUMNS, LABEL_COLUMNS, label_columns, lidar_path
from pipeline.core.record_writers.camera import camera_label_rows, write_camera_frame
from pipeline.core.record_writers.lidar import lidar_label_rows, write_lidar_sweep
from pipeline.core.record_writers.rows import actor_boxes, rider_counts
from pipeline.core.tables import read_parquet, write_ipc
from pipeline.sensors.lidar import render_lidar
from pipeline.sensors.radar import heading_velocity
from pipeline.sensors.reach import actors_in_reach
from pipeline.sensors.render import render_camera
from pipeline.stages import radar_frames
from pipeline.stages.rig import build_actor_meshes, build_sensors
from pipeline.world.actors import ActorMeshes, Actors, actor_variants, srgb8_to_linear
from pipeline.world.materials import material_index
from pipeline.world.people import person_statures
from pipeline.world.posed_people import posed_boxes
from pipeline.world.prams import STROLLER_SIZE_M, stroller_colors, stroller_offset_m
from pipeline.world.scene import FrameScene, StaticGeometry, StaticScene
from pipeline.world.static import StaticWorld, load_static_geometry


@dataclass(frozen=True)
class ShardJob:
    """Everything one shard needs (picklable)."""

    index: int
    frames: tuple[int, ...]
    sim_dir: Path
    static_pickle: Path
    record_dir: Path
    shard_dir: Path
    rig: RigConfig
    condition: ConditionConfig
    seed: int
    threads: int


def frame_rng(seed: int, condition: str, frame: int, sensor: int) -> np.random.Generator:
    return np.random.default_rng([seed, zlib.crc32(condition.encode()), frame, sensor])


class SignalState:
    """Per-frame signal-lamp materials from the recorded traffic-light states."""

    def __init__(self, world: StaticWorld, scene: StaticScene, tls: pd.DataFrame) -> None:
        self.lamps, self.tls = world.signal_lamps, tls
        self.mesh_index = sorted(world.parts).index("traffic_light") if len(self.lamps) else -1
        ranges = self.lamps.triangles.astype(np.int64) if len(self.lamps) else np.zeros((0, 2), np.int64)
        self.lamp_of_triangle = np.repeat(np.arange(len(ranges)), ranges[:, 1] - ranges[:, 0])
        self.triangles = np.concatenate([np.arange(a, b) for a, b in ranges]) if len(ranges) else np.zeros(0, int)
        self.lit_material = np.array([material_index(f"signal_{c}") for c in self.lamps.colour], np.int32) \
            if len(self.lamps) else np.zeros(0, np.int32)
        self.scene, self.off = scene, material_index("signal_off")

    def apply(self, frame: int) -> None:
        """Light the lamps as recorded at ``frame``."""
        if not len(self.lamps):
            return
        rows = self.tls[self.tls["frame"] == frame]
        self.apply_states(dict(zip(rows["tls_id"], rows["state"], strict=True)))

    def apply_states(self, states: dict[str, str]) -> None:
        """Light the lamps for the traffic lights' ``states`` (tls id -> SUMO state string)."""
        if not len(self.lamps):
            return
        lit = self.lamps.lit(states)
        material = np.where(lit, self.lit_material, self.off)[self.lamp_of_triangle]
        self.scene.set_triangle_materials(self.mesh_index, self.triangles, material)


ACTOR_COLUMNS = ("track_id", "cls", "x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad", "color_r",
                 "color_g", "color_b", "braking", "speed_mps", "parked", "pose", "model", "person")
SIMULATED_COLUMNS = ACTOR_COLUMNS[:-3]  # what simulate records; body_sized_trajectories adds pose, model, person


class Trajectories:
    """The simulated run's trajectories as numpy columns, and each frame's row positions (in table order)."""

    def __init__(self, table: pd.DataFrame) -> None:
        self.columns = {c: table[c].to_numpy() for c in table.columns}
        self.rows = {int(f): rows for f, rows in table.groupby("frame").indices.items()}

    def frame(self, frame: int) -> tuple[dict[str, object], dict[str, np.ndarray]]:
        """The ego's values and the other actors' columns (ACTOR_COLUMNS, table order) at ``frame``."""
        rows = self.rows[frame]
        is_ego = self.columns["is_ego"][rows]
        ego = rows[is_ego][0]
        others = rows[~is_ego]
        return {c: v[ego] for c, v in self.columns.items()}, {c: self.columns[c][others] for c in ACTOR_COLUMNS}


def body_sized_trajectories(table: pd.DataFrame, meshes: ActorMeshes, seed: int,
                            umbrellas: float = 0.0) -> pd.DataFrame:
    """The trajectories with a stroller in front of each person who pushes one (:func:`with_strollers`), every
    actor's box as its body fills it, and a ``pose`` column (:func:`pipeline.world.posed_people.posed_boxes`: a
    person's box is its posed body's at its stature, in each row, with an umbrella for a share ``umbrellas`` of them;
    the others keep theirs, but for a pedestrian model's depth); the camera, the LiDAR, the label rows and so the
    exports all see that box. Two columns name each actor's body for the labels: ``model``, its body family's name
    (:meth:`ActorMeshes.family_names`), and ``person``, who a pedestrian is (:meth:`ActorMeshes.family_persons`;
    "" for the other classes)."""
    table = with_strollers(table, meshes, seed)
    _, first, inverse = np.unique(table["track_id"].to_numpy(), return_index=True, return_inverse=True)
    cols = {c: table[c].to_numpy()[first] for c in SIMULATED_COLUMNS}  # an actor's class and size hold for its track
    rows = {c: table[c].to_numpy() for c in ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")}
    boxes, pose = posed_boxes(meshes, _actors(cols, seed), inverse.reshape(-1), table["time_s"].to_numpy(),
                              table["speed_mps"].to_numpy(), actor_boxes(rows), seed, umbrellas)
    posed = {"x_m": boxes.center[:, 0], "y_m": boxes.center[:, 1], "z_m": boxes.center[:, 2],
             "length_m": boxes.size[:, 0], "width_m": boxes.size[:, 1], "height_m": boxes.size[:, 2]}
    changed = {c: v for c, v in posed.items() if not np.array_equal(v, rows[c])}
    family = meshes.family_codes(_actors(cols, seed))
    return table.assign(**changed, pose=pose, model=meshes.family_names(family)[inverse.reshape(-1)],
                        person=meshes.family_persons(family)[inverse.reshape(-1)])


STROLLER_TRACK_OFFSET = 1 << 15
"""A stroller's track id: its pusher's plus this (instance images hold track ids as uint16)."""


def with_strollers(table: pd.DataFrame, meshes: ActorMeshes, seed: int) -> pd.DataFrame:
    """The trajectories with a stroller actor (class ``stroller``) in front of every person who pushes one: the
    pedestrians whose body family pushes a pram (:class:`pipeline.world.prams.PramPusherFamily`, picked by its
    share, :meth:`ActorMeshes.family_codes`). In each of the pusher's rows the stroller stands on the same ground,
    heading the same way, its handle in the pusher's hands (:func:`pipeline.world.prams.stroller_offset_m` at the
    pusher's stature), with the pusher's speed; its track id is the pusher's + :data:`STROLLER_TRACK_OFFSET` (the
    same in every frame, shard and step of the driving environment, which renders a frame's rows alone), its
    ``actor_id`` the pusher's + ``/stroller``, its colour drawn from the seed
    (:func:`pipeline.world.prams.stroller_colors`).
    A stroller is its own object in every label and export, as nuScenes' annotators box a stroller apart from the
    person pushing it (human.pedestrian.stroller). The input's rows come first, as they were (index and order); the
    strollers' rows follow, sorted by (frame, track_id), their track ids above every other's."""
    people = np.flatnonzero(table["cls"].to_numpy() == ObjectClass.PEDESTRIAN.value)
    if not len(people):
        return table
    tracks, first = np.unique(table["track_id"].to_numpy()[people], return_index=True)
    cols = {c: table[c].to_numpy()[people[first]] for c in SIMULATED_COLUMNS}
    family = meshes.family_codes(_actors(cols, seed))
    pushes = np.array([getattr(meshes.families[f], "pram", False) for f in family], bool)
    if not pushes.any():
        return table
    if int(table["track_id"].max()) >= STROLLER_TRACK_OFFSET:
        raise ValueError(f"track id {int(table['track_id'].max())}: strollers take their pusher's track id + "
                         f"{STROLLER_TRACK_OFFSET}, so every track id must be below it (instance images are uint16)")
    pushers = tracks[pushes]
    group = np.array([meshes.families[f].group for f in family[pushes]], object)
    rows = table.iloc[people[np.isin(table["track_id"].to_numpy()[people], pushers)]]
    which = np.searchsorted(pushers, rows["track_id"].to_numpy())  # each row's pusher
    ahead = stroller_offset_m(person_statures(group, pushers, seed))[which]
    yaw = rows["yaw_rad"].to_numpy()
    length, width, height = STROLLER_SIZE_M
    track = (pushers + STROLLER_TRACK_OFFSET).astype(np.int32)
    color = stroller_colors(track, seed)[which]
    track = track[which]
    values = {"track_id": track, "cls": "stroller", "x_m": rows["x_m"].to_numpy() + ahead * np.cos(yaw),
              "y_m": rows["y_m"].to_numpy() + ahead * np.sin(yaw),
              "z_m": rows["z_m"].to_numpy() - 0.5 * rows["height_m"].to_numpy() + 0.5 * height,
              "length_m": length, "width_m": width, "height_m": height, "color_r": color[:, 0],
              "color_g": color[:, 1], "color_b": color[:, 2], "braking": False, "signals": 0, "is_ego": False}
    if "actor_id" in rows:
        values["actor_id"] = rows["actor_id"].astype(str).to_numpy() + "/stroller"
    strollers = rows.assign(**{c: v for c, v in values.items() if c in rows})
    strollers = strollers.sort_values(["frame", "track_id"], kind="stable")
    after = int(table.index.max()) + 1
    strollers.index = pd.RangeIndex(after, after + len(strollers))
    return pd.concat([table, strollers]).astype(table.dtypes.to_dict())


def _actors(cols: dict[str, np.ndarray], seed: int) -> Actors:
    color = srgb8_to_linear(np.column_stack([cols["color_r"], cols["color_g"], cols["color_b"]]))
    return Actors(cols["track_id"], cols["cls"].tolist(), actor_boxes(cols), color, cols["braking"],
                  actor_variants(cols["track_id"], seed), lights_on=~cols["parked"].astype(bool),
                  pose=cols.get("pose"))


def _shard_type(dtype: str) -> pa.DataType:
    """A shard table's Arrow type for a record column's pandas ``dtype``: strings as strings, the nullable Float64
    and Int64 as float64 with NaN for null (pixel counts are far below 2^53), the others as they are. The render's
    finalize types the record's tables from these once (pandas' astype), not each shard."""
    if dtype == "str":
        return pa.string()
    if dtype in ("Float64", "Int64"):
        return pa.float64()
    return pa.from_numpy_dtype(np.dtype(dtype))


SHARD_FORMAT = 2  # of the shard tables: 2, Arrow IPC files of these schemas (1: typed Parquet)
SHARD_LABELS = pa.schema([(c, _shard_type(t)) for c, t in LABEL_COLUMNS.items()])
SHARD_LABELS_RADAR = pa.schema([(c, _shard_type(t)) for c, t in label_columns(radars=True).items()])
SHARD_FRAMES = pa.schema([(c, _shard_type(t)) for c, t in FRAME_COLUMNS.items()])


def _shard_table(columns: dict[str, np.ndarray | list], schema: pa.Schema) -> pa.Table:
    """The Arrow table of ``schema`` from its columns (arrays or lists, converted to each column's type)."""
    arrays = []
    for field in schema:
        values = columns[field.name]
        if pa.types.is_string(field.type):
            arrays.append(pa.array(np.asarray(values, object), field.type))
        else:
            arrays.append(pa.array(np.asarray(values, field.type.to_pandas_dtype())))
    return pa.Table.from_arrays(arrays, schema=schema)


def _label_table(parts: list[dict[str, np.ndarray]], radars: bool = False) -> pa.Table:
    """One shard table (SHARD_LABELS, or SHARD_LABELS_RADAR for a rig with radars) from the label columns of several
    sensors and frames."""
    schema = SHARD_LABELS_RADAR if radars else SHARD_LABELS
    return _shard_table({k: np.concatenate([p[k] for p in parts]) if parts else [] for k in schema.names}, schema)


@dataclass
class _WorkerState:
    """What every shard of one render shares; built once per process (see :func:`_state`)."""

    world: StaticWorld
    static: StaticScene
    cameras: list
    lidars: list
    condition: object
    trajectories: Trajectories
    signals: SignalState
    meshes: ActorMeshes


@dataclass
class _Shared:
    """The part of a :class:`_WorkerState` that needs no Embree scene (see :func:`prepared_state`)."""

    world: StaticWorld
    geometry: StaticGeometry
    cameras: list
    lidars: list
    condition: object
    trajectories: Trajectories
    meshes: ActorMeshes


_STATE = ProcessCache()  # the _WorkerState of the render this process serves
_SHARED = ProcessCache()  # its part without Embree, built before the workers fork (prepared_state)
_MESHES = ProcessCache()  # the actor models of the last rig (its JSON, with or without umbrellas) this process built
_WORLDS = ProcessCache()  # the static world this process built, by the path it was pickled to


def rig_actor_meshes(rig: RigConfig, umbrellas: bool = False) -> ActorMeshes:
    """The rig's actor models (:func:`pipeline.stages.rig.build_actor_meshes`; ``umbrellas``: with the people's
    umbrella poses), read once per process and rig: the render stage reads them before it starts its workers (bad
    files fail early), and workers forked from it find them here."""
    return _MESHES.get((rig.model_dump_json(), umbrellas), lambda: build_actor_meshes(rig, umbrellas))


def remembered_world(path: Path, world: StaticWorld | None) -> contextlib.AbstractContextManager[None]:
    """Within the block, :func:`_state` takes ``world``, just pickled to ``path`` by this process, as it is instead
    of unpickling it: in this process, and in workers forked from it (docs/performance.md). Forgotten at the end,
    so that a later render never mistakes it for another pickle at the same path. ``world`` None: nothing to keep
    (the pickle was there already)."""
    return _WORLDS.lent(str(path), world)


def _state_key(job: ShardJob) -> tuple[str, ...]:
    return str(job.static_pickle), str(job.sim_dir), job.rig.model_dump_json(), job.condition.model_dump_json()


def _state(job: ShardJob) -> _WorkerState:
    return _STATE.get(_state_key(job), lambda: _worker_state(job))


def prepared_state(job: ShardJob) -> contextlib.AbstractContextManager[None]:
    """Within the block, the part of the render's worker state that needs no Embree scene (the static world and its
    merged geometry with the sun maps' triangle index, the rig's sensors with their rays and anti-aliasing samples,
    the condition, the body-sized trajectories) is the one built now, in this process, before its pool forks the
    workers: built once, not once per worker (~1 s of an urban render's each). Forgotten at the end, like
    :func:`remembered_world`."""
    return _SHARED.lent(_state_key(job), _shared(job))


def _shared(job: ShardJob) -> _Shared:
    from pipeline.sensors import conditions

    world = _WORLDS.peek(str(job.static_pickle))
    if world is None:
        with job.static_pickle.open("rb") as fh:
            world = pickle.load(fh)
    if job.threads:  # as render_shard does in each worker; workers forked after this inherit it (~50 ms each)
        _limit_blas(job.threads)
    cameras, lidars = build_sensors(job.rig)
    for camera in cameras:
        camera.sample_directions  # noqa: B018 -- computed and kept now (a cached property)
    condition = conditions.Condition(job.condition)
    meshes = rig_actor_meshes(job.rig, condition.umbrellas > 0.0)
    trajectories = Trajectories(body_sized_trajectories(read_parquet(job.sim_dir / "trajectories.parquet"), meshes,
                                                        job.seed, condition.umbrellas))
    geometry = load_static_geometry(world, job.sim_dir / "roads", seed=job.seed)  # pickled: the same world
    if condition.sun_shadows and any(c.config.quality == "realistic" for c in cameras):
        geometry.sun_tiles(condition.sun_disc)  # the realistic cameras' soft shadows test the sun's whole disc
    return _Shared(world, geometry, cameras, lidars, condition, trajectories, meshes)


def _worker_state(job: ShardJob) -> _WorkerState:
    keep_freed_memory(RENDER_THRESHOLDS)
    shared = _SHARED.get(_state_key(job), lambda: _shared(job))
    static = StaticScene(shared.world.meshes, shared.geometry)
    return _WorkerState(shared.world, static, shared.cameras, shared.lidars, shared.condition, shared.trajectories,
                        SignalState(shared.world, static, read_parquet(job.sim_dir / "tls_states.parquet")),
                        shared.meshes)


@functools.cache
def _limit_blas(threads: int) -> None:
    """Cap numpy's BLAS (OpenBLAS: a thread per core by default) at ``threads`` in this process, once: beside a
    pool's other workers its second thread only spins, e.g. in the (N, 3) @ (3, 3) transforms of the amodal boxes
    (docs/performance.md); each product is computed by one thread either way, so no byte changes."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(threads, user_api="blas")


def render_shard(job: ShardJob) -> int:
    """Render ``job.frames``; write images, point clouds and the shard's tables. Returns frames rendered.

    ``job.threads`` caps Embree's threads per cast and, when not 0, OpenCV's and BLAS's for the process (its post
    effects, its small matrix products: a second thread beside a pool's other workers only costs CPU). None changes
    a pixel."""
    if job.threads:
        cv2.setNumThreads(job.threads)
        _limit_blas(job.threads)
    state = _state(job)
    world, static, cameras, lidars, condition = state.world, state.static, state.cameras, state.lidars, \
        state.condition
    signals = state.signals
    radars = job.rig.radars
    frame_rows, label_parts = [], []
    for frame in job.frames:
        ego, others = state.trajectories.frame(frame)
        signals.apply(frame)
        out = render_frame(world, static, cameras, lidars, condition, state.meshes, job.seed, frame, ego, others,
                           threads=job.threads, radars=radars)
        for lidar, sweep in zip(lidars, out.sweeps, strict=True):
            write_lidar_sweep(lidar_path(job.record_dir, lidar.name, frame), sweep)
        for camera, cam in zip(cameras, out.cameras, strict=True):
            write_camera_frame(job.record_dir, camera.name, frame, cam)
        radar_frames.write_scans(job.record_dir, frame, radars, out.scans)
        label_parts.extend(out.labels)
        frame_rows.append((frame, float(ego["time_s"]), int(ego["track_id"]), ego["x_m"], ego["y_m"], ego["z_m"],
                           ego["yaw_rad"], ego["speed_mps"]))
    frames = _shard_table({c: [row[i] for row in frame_rows] for i, c in enumerate(FRAME_COLUMNS)}, SHARD_FRAMES)
    job.shard_dir.mkdir(parents=True, exist_ok=True)
    write_ipc(frames, job.shard_dir / f"frames-{job.index:05d}.arrow")
    write_ipc(_label_table(label_parts, bool(radars)), job.shard_dir / f"labels-{job.index:05d}.arrow")
    (job.shard_dir / f"done-{job.index:05d}").write_text(" ".join(map(str, job.frames)) + "\n")
    return len(job.frames)


@dataclass(frozen=True)
class FrameSensors:
    """One frame of a rig's sensors, as :func:`render_frame` rendered it.

    Attributes:
        cameras: one :class:`pipeline.sensors.render.CameraFrame` per camera, in rig order.
        sweeps: one :class:`pipeline.sensors.lidar.LidarSweep` per LiDAR, in rig order.
        labels: the frame's label columns (those of LABEL_COLUMNS, one array each), one dict per sensor: the
            LiDARs', the cameras', then the radars' (with radars, every row carries its object's radar detections).
        scans: one :class:`pipeline.sensors.radar.RadarScan` per radar, in rig order.
    """

    cameras: list
    sweeps: list
    labels: list[dict[str, np.ndarray]]
    scans: list = ()


def render_frame(world: StaticWorld, static: StaticScene, cameras: list, lidars: list, condition, meshes: ActorMeshes,
                 seed: int, frame: int, ego: dict[str, object], others: dict[str, np.ndarray], *,
                 threads: int = 0, radars: Sequence[RadarConfig] = ()) -> FrameSensors:
    """Render every sensor of the rig at one frame: the render stage's per-frame work, without writing anything.

    ``ego`` is the ego's trajectory row and ``others`` the other actors' columns (:meth:`Trajectories.frame`);
    the traffic lights must already be set (:class:`SignalState`). ``cameras`` and ``lidars`` are the rig's
    (:func:`pipeline.stages.rig.build_sensors`), ``radars`` its radar configs (:mod:`pipeline.stages.radar_frames`),
    ``condition`` a :class:`pipeline.sensors.conditions.Condition`.
    Random draws come from :func:`frame_rng` (seed, condition, frame, sensor), so the frame is the same however
    it is reached (a render shard, or the driving environment)."""
    ego_pose = Transform.from_xyz_rpy((ego["x_m"], ego["y_m"], ego["z_m"]), (0.0, 0.0, ego["yaw_rad"]))
    actors = _actors(others, seed)
    ego_size_m = (ego["length_m"], ego["width_m"], ego["height_m"])
    active = actors_in_reach(actors, ego_pose, cameras, lidars, condition, floor_z_m=static.floor_z_m,
                             street_lights_m=world.street_lights, ego_size_m=ego_size_m)
    if radars:
        active |= radar_frames.radar_reach(list(radars), actors, ego_pose)
    scene = FrameScene(static, actors, meshes, threads=threads, active=active)
    lidar_points = np.zeros(len(scene.actors), np.int64)
    rider_points = np.zeros(len(scene.actors), np.int64)
    actor_velocity = heading_velocity(others["speed_mps"], others["yaw_rad"])
    # Every moving vehicle's spray, in reach or not: a vehicle beyond the rays' reach (an oncoming one just passed)
    # may trail its cloud into view.
    spray = condition.spray(scene.actors, actor_velocity)
    sweeps, frames, labels = [], [], []
    scans = []
    if radars:  # scanned before the others; each sensor draws from its own generator, so the order changes nothing
        scans = radar_frames.render_scans(list(radars), scene, ego_pose, ego, others, condition.config,
                                          functools.partial(frame_rng, seed, condition.name, frame))
    for k, lidar in enumerate(lidars):
        sweep = render_lidar(scene, lidar, ego_pose, frame_rng(seed, condition.name, frame, 1000 + k),
                             condition=condition, spray=spray)
        sweeps.append(sweep)
        labels.append(lidar_label_rows(frame, lidar.name, lidar.mount, sweep, others, ego_pose))
        lidar_points += sweep.points_per_actor
        rider_points += rider_counts(sweep.instance_id, sweep.semantic, others["track_id"])
    for k, camera in enumerate(cameras):
        cam = render_camera(scene, camera, ego_pose, condition, frame_rng(seed, condition.name, frame, k),
                            street_lights_m=world.street_lights, ego_speed_mps=float(ego["speed_mps"]),
                            ego_size_m=ego_size_m, actor_velocity_mps=actor_velocity, spray=spray)
        frames.append(cam)
        labels.append(camera_label_rows(frame, camera.name, cam, others, lidar_points, rider_points))
    if radars:
        radar_frames.scan_rows(frame, list(radars), scans, others, ego_pose, lidar_points, labels)
    return FrameSensors(frames, sweeps, labels, scans)
