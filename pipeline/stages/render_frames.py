"""Rendering the frames of one shard into a record folder (the render stage's worker side).

A :class:`ShardJob` is a pure function of its inputs: the simulated run, the static world (built once
by the parent and pickled), the rig, the condition, the seed and the frame numbers. Every random draw
comes from a generator seeded by (seed, condition, frame, sensor), so a frame renders the same whether
it is rendered alone, in another shard, or by another worker.
"""

from __future__ import annotations

import pickle
import zlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from pipeline.core.classes import ObjectClass
from pipeline.core.config import ConditionConfig, RigConfig
from pipeline.core.geometry import Boxes3D, Transform, wrap_angle
from pipeline.core.record import DEPTH_SCALE, FRAME_COLUMNS, LABEL_COLUMNS, POINT_COLUMNS, camera_path, lidar_path
from pipeline.core.tables import read_parquet, write_parquet
from pipeline.sensors.lidar import render_lidar
from pipeline.sensors.render import render_camera
from pipeline.stages.rig import build_sensors
from pipeline.world.actors import Actors, srgb8_to_linear
from pipeline.world.materials import material_index
from pipeline.world.scene import FrameScene, StaticScene
from pipeline.world.static import StaticWorld

# zlib level 1: ~40% faster than 3 for about the same size on rendered images (bench/bench_render.py).
PNG = [cv2.IMWRITE_PNG_COMPRESSION, 1]


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


class _SignalState:
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
        if not len(self.lamps):
            return
        rows = self.tls[self.tls["frame"] == frame]
        lit = self.lamps.lit(dict(zip(rows["tls_id"], rows["state"], strict=True)))
        material = np.where(lit, self.lit_material, self.off)[self.lamp_of_triangle]
        self.scene.set_triangle_materials(self.mesh_index, self.triangles, material)


def _actors(rows: pd.DataFrame) -> Actors:
    boxes = Boxes3D(rows[["x_m", "y_m", "z_m"]].to_numpy(), rows[["length_m", "width_m", "height_m"]].to_numpy(),
                    rows["yaw_rad"].to_numpy())
    color = srgb8_to_linear(rows[["color_r", "color_g", "color_b"]].to_numpy())
    return Actors(rows["track_id"].to_numpy(), rows["cls"].tolist(), boxes, color, rows["braking"].to_numpy())


def _write_png(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image, PNG):
        raise OSError(f"{path}: could not write image")


def _camera_rows(frame: int, name: str, cam, rows: pd.DataFrame, points_by_track: dict[int, int]) -> pd.DataFrame:
    lab = cam.labels
    actor = rows.iloc[lab.actor_index]
    heading = lab.rotation_cam[:, :, 0]  # the box's forward axis in the optical frame
    tight = np.where(lab.visible[:, None], lab.box_tight, np.nan)  # NaN becomes null when typed Float64
    out = pd.DataFrame({
        "frame": frame, "sensor": name, "sensor_type": "camera", "track_id": lab.track_id,
        "cls": actor["cls"].to_numpy(), "category_id": [ObjectClass(c).coco_id for c in actor["cls"]],
        "x_m": actor["x_m"].to_numpy(), "y_m": actor["y_m"].to_numpy(), "z_m": actor["z_m"].to_numpy(),
        "length_m": lab.size[:, 0], "width_m": lab.size[:, 1], "height_m": lab.size[:, 2],
        "yaw_rad": actor["yaw_rad"].to_numpy(),
        "sensor_x_m": lab.center_cam[:, 0], "sensor_y_m": lab.center_cam[:, 1], "sensor_z_m": lab.center_cam[:, 2],
        # KITTI rotation_y: the heading in the optical frame is (cos ry, 0, -sin ry).
        "sensor_yaw_rad": wrap_angle(np.arctan2(-heading[:, 2], heading[:, 0])),
        "distance_m": lab.distance_m.astype(np.float64), "visible": lab.visible,
    })
    for j, key in enumerate(("x1", "y1", "x2", "y2")):
        out[key] = tight[:, j]
        out[f"amodal_{key}"] = lab.box_amodal[:, j]
        out[f"amodal_clip_{key}"] = lab.box_amodal_clipped[:, j]
    out["visible_px"], out["unoccluded_px"] = lab.visible_px, lab.unoccluded_px
    out["occlusion"], out["truncation"] = lab.occlusion.astype(np.float64), lab.truncation.astype(np.float64)
    out["lidar_points"] = [points_by_track.get(int(t), 0) for t in lab.track_id]
    return out


def _lidar_rows(frame: int, name: str, lidar, sweep, rows: pd.DataFrame, ego_pose: Transform) -> pd.DataFrame:
    cfg = lidar.config
    world_to_lidar = (ego_pose @ cfg.mount).inverse()
    boxes = Boxes3D(rows[["x_m", "y_m", "z_m"]].to_numpy(), rows[["length_m", "width_m", "height_m"]].to_numpy(),
                    rows["yaw_rad"].to_numpy())
    local = boxes.transformed(world_to_lidar) if abs(world_to_lidar.rotation[2, 2] - 1) < 1e-9 else None
    centre = world_to_lidar.apply(boxes.center)
    dist = np.linalg.norm(centre, axis=1)
    keep = dist <= cfg.range_max_m
    heading = world_to_lidar.apply_vectors(np.column_stack([np.cos(boxes.yaw_rad), np.sin(boxes.yaw_rad),
                                                            np.zeros(len(boxes))]))
    yaw = local.yaw_rad if local is not None else np.arctan2(heading[:, 1], heading[:, 0])
    sel = rows[keep]
    counts = np.asarray(sweep.points_per_actor)[np.flatnonzero(keep)] if len(sweep.points_per_actor) else 0
    out = pd.DataFrame({
        "frame": frame, "sensor": name, "sensor_type": "lidar", "track_id": sel["track_id"].to_numpy(),
        "cls": sel["cls"].to_numpy(), "category_id": [ObjectClass(c).coco_id for c in sel["cls"]],
        "x_m": sel["x_m"].to_numpy(), "y_m": sel["y_m"].to_numpy(), "z_m": sel["z_m"].to_numpy(),
        "length_m": sel["length_m"].to_numpy(), "width_m": sel["width_m"].to_numpy(),
        "height_m": sel["height_m"].to_numpy(), "yaw_rad": sel["yaw_rad"].to_numpy(),
        "sensor_x_m": centre[keep, 0], "sensor_y_m": centre[keep, 1], "sensor_z_m": centre[keep, 2],
        "sensor_yaw_rad": wrap_angle(yaw[keep]), "distance_m": dist[keep], "visible": False,
        "lidar_points": counts,
    })
    for key in ("x1", "y1", "x2", "y2"):
        out[key] = out[f"amodal_{key}"] = out[f"amodal_clip_{key}"] = np.nan
    out["visible_px"] = out["unoccluded_px"] = pd.NA
    out["occlusion"] = out["truncation"] = np.nan
    return out


@dataclass
class _WorkerState:
    """What every shard of one render shares; built once per process (see :func:`_state`)."""

    world: StaticWorld
    static: StaticScene
    cameras: list
    lidars: list
    condition: object
    trajectories: pd.DataFrame
    signals: _SignalState


_STATE: dict[tuple, _WorkerState] = {}


def _state(job: ShardJob) -> _WorkerState:
    key = (str(job.static_pickle), str(job.sim_dir), job.rig.model_dump_json(), job.condition.model_dump_json())
    if key not in _STATE:
        from pipeline.sensors import conditions

        _STATE.clear()  # one render at a time per process
        with job.static_pickle.open("rb") as fh:
            world: StaticWorld = pickle.load(fh)
        static = StaticScene(world.meshes)
        cameras, lidars = build_sensors(job.rig)
        _STATE[key] = _WorkerState(world, static, cameras, lidars, conditions.condition_from_config(job.condition),
                                   read_parquet(job.sim_dir / "trajectories.parquet"),
                                   _SignalState(world, static, read_parquet(job.sim_dir / "tls_states.parquet")))
    return _STATE[key]


def render_shard(job: ShardJob) -> int:
    """Render ``job.frames``; write images, point clouds and the shard's tables. Returns frames rendered."""
    state = _state(job)
    world, static, cameras, lidars, condition = state.world, state.static, state.cameras, state.lidars, \
        state.condition
    traj = state.trajectories[state.trajectories["frame"].isin(job.frames)]
    signals = state.signals
    frame_rows, label_parts = [], []
    for frame in job.frames:
        rows = traj[traj["frame"] == frame]
        ego = rows[rows["is_ego"]].iloc[0]
        others = rows[~rows["is_ego"]].reset_index(drop=True)
        ego_pose = Transform.from_xyz_rpy((ego.x_m, ego.y_m, ego.z_m), (0.0, 0.0, ego.yaw_rad))
        signals.apply(frame)
        scene = FrameScene(static, _actors(others), threads=job.threads)
        points_by_track: dict[int, int] = {}
        for k, lidar in enumerate(lidars):
            sweep = render_lidar(scene, lidar, ego_pose, frame_rng(job.seed, condition.name, frame, 1000 + k),
                                 condition=condition)
            _write_points(lidar_path(job.record_dir, lidar.config.name, frame), sweep)
            label_parts.append(_lidar_rows(frame, lidar.config.name, lidar, sweep, others, ego_pose))
            for t, n in zip(others["track_id"], sweep.points_per_actor, strict=True):
                points_by_track[int(t)] = points_by_track.get(int(t), 0) + int(n)
        for k, camera in enumerate(cameras):
            cam = render_camera(scene, camera, ego_pose, condition, frame_rng(job.seed, condition.name, frame, k),
                                street_lights_m=world.street_lights, ego_speed_mps=float(ego.speed_mps),
                                ego_size_m=(ego.length_m, ego.width_m, ego.height_m))
            _write_camera(job.record_dir, camera.config.name, frame, cam)
            label_parts.append(_camera_rows(frame, camera.config.name, cam, others, points_by_track))
        frame_rows.append((frame, float(ego.time_s), int(ego.track_id), ego.x_m, ego.y_m, ego.z_m, ego.yaw_rad,
                           ego.speed_mps))
    frames = pd.DataFrame(frame_rows, columns=list(FRAME_COLUMNS)).astype(FRAME_COLUMNS)
    labels = pd.concat(label_parts, ignore_index=True) if label_parts else pd.DataFrame(columns=list(LABEL_COLUMNS))
    job.shard_dir.mkdir(parents=True, exist_ok=True)
    write_parquet(frames, job.shard_dir / f"frames-{job.index:05d}.parquet")
    write_parquet(labels[list(LABEL_COLUMNS)].astype(LABEL_COLUMNS), job.shard_dir / f"labels-{job.index:05d}.parquet")
    (job.shard_dir / f"done-{job.index:05d}").write_text(" ".join(map(str, job.frames)) + "\n")
    return len(job.frames)


def _write_camera(root: Path, name: str, frame: int, cam) -> None:
    if cam.instance_id.max(initial=0) > np.iinfo(np.uint16).max:
        raise ValueError(f"track id {cam.instance_id.max()} does not fit the uint16 instance image")
    _write_png(camera_path(root, name, "rgb", frame), np.ascontiguousarray(cam.rgb[:, :, ::-1]))
    _write_png(camera_path(root, name, "instance", frame), cam.instance_id.astype(np.uint16))
    _write_png(camera_path(root, name, "semantic", frame), cam.semantic.astype(np.uint8))
    depth = np.where(cam.depth_valid, np.clip(np.rint(cam.depth_m * DEPTH_SCALE), 1, 65535), 0).astype(np.uint16)
    _write_png(camera_path(root, name, "depth", frame), depth)


def _write_points(path: Path, sweep) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    table = pd.DataFrame({
        "x_m": sweep.points_m[:, 0], "y_m": sweep.points_m[:, 1], "z_m": sweep.points_m[:, 2],
        "intensity": sweep.intensity, "ring": sweep.ring, "instance_id": sweep.instance_id, "semantic": sweep.semantic,
    })
    write_parquet(table.astype(POINT_COLUMNS), path)
