"""Hand-built canonical records from closed-form geometry (no renderer): the exporters' test input.

One 800x600 pinhole camera ``front`` (90 deg horizontal field of view: fx = fy = 400, cx = 400,
cy = 300) mounted at (1.5, 0, 1.6) in the ego frame looking along ego +x, and one LiDAR ``top`` at
(0, 0, 1.8). The ego box centre is 0.75 m above flat ground (ego z = -0.75 is the ground).

Objects are boxes given in the ego frame (:data:`OBJECTS`): two cars ahead (A occludes part of B), a
car C hidden completely behind A, a car D cut by the left image border, and a far pedestrian P whose
mask is a handful of pixels. Since a box is convex and every corner lies in front of the camera, its
silhouette is exactly the convex hull of its 8 projected corners: a pixel belongs to an object when its
centre (col + 0.5, row + 0.5) lies inside that hull. Objects are painted far to near (their depth
ranges do not overlap where their hulls do), so the instance image is exact. Labels follow from the
masks (tight box, visible and unoccluded pixels), the corners (amodal box), a virtual image plane over
the amodal box (truncation) and the sampled LiDAR points (counts). LiDAR points lie 2 cm inside the
faces a roof-mounted sensor sees (rear and top) and on the ground outside the boxes.

Depth is approximate for objects (the box's nearest corner depth); exporters do not read depth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
from scipy.spatial import ConvexHull

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.geometry import R_CAMERA_FROM_BODY, Boxes3D, Transform, wrap_angle
from pipeline.core.record import (
    DEPTH_SCALE,
    FRAME_COLUMNS,
    LABEL_COLUMNS,
    POINT_COLUMNS,
    CameraInfo,
    LidarInfo,
    RecordInfo,
    camera_path,
    lidar_path,
)
from pipeline.core.tables import write_parquet

WIDTH, HEIGHT = 800, 600
K = np.array([[400.0, 0.0, 400.0], [0.0, 400.0, 300.0], [0.0, 0.0, 1.0]])
CAMERA_MOUNT = (1.5, 0.0, 1.6)
LIDAR_MOUNT = (0.0, 0.0, 1.8)
GROUND_Z_EGO = -0.75
FIRST_FRAME = 10  # frames are numbered as in the simulation; not starting at 0 catches indexing slips


@dataclass(frozen=True)
class ObjectSpec:
    """A box in the ego frame at the first frame; it moves ``speed_rel_mps`` along ego +x per second."""

    track_id: int
    cls: ObjectClass
    x_m: float
    y_m: float
    size_m: tuple[float, float, float]  # length, width, height
    yaw_rel_rad: float
    speed_rel_mps: float


OBJECTS = (
    ObjectSpec(3, ObjectClass.CAR, 12.0, -0.5, (4.5, 1.8, 1.5), 0.0, 2.0),  # A
    ObjectSpec(4, ObjectClass.VAN, 20.0, -2.2, (5.0, 2.0, 1.6), 0.15, 2.0),  # B, partly behind A
    ObjectSpec(7, ObjectClass.CAR, 17.5, -0.3, (3.0, 1.4, 1.0), 0.0, 2.0),  # C, hidden behind A
    ObjectSpec(9, ObjectClass.TRUCK, 8.0, 5.0, (4.5, 1.8, 1.5), -0.1, -1.0),  # D, truncated at the left
    ObjectSpec(12, ObjectClass.PEDESTRIAN, 95.0, 4.0, (0.5, 0.5, 1.8), 1.57, 0.0),  # P, tiny
)


def camera_info() -> CameraInfo:
    t_ego_cam = Transform(R_CAMERA_FROM_BODY.T, np.array(CAMERA_MOUNT))
    return CameraInfo("front", WIDTH, HEIGHT, K.tolist(), [0.0] * 5, t_ego_cam.matrix.tolist())


def lidar_info() -> LidarInfo:
    return LidarInfo("top", 32, 120.0, 10.0, Transform.from_xyz_rpy(LIDAR_MOUNT).matrix.tolist())


def ego_pose(frame: int, seed: int) -> tuple[np.ndarray, float]:
    """World position (3,) of the ego box centre and its yaw at ``frame``: driving straight at 10 m/s."""
    yaw = 0.3 + 0.1 * (seed % 5)
    t = (frame - FIRST_FRAME) * 0.1
    start = np.array([100.0 + seed, 50.0, 0.75 + 5.0])  # the ground lies at world z = 5
    return start + 10.0 * t * np.array([np.cos(yaw), np.sin(yaw), 0.0]), yaw


def ego_boxes(frame: int) -> Boxes3D:
    t = ((frame - FIRST_FRAME) % 20) * 0.1  # objects cycle every 2 s so that long records keep them in view
    centre = [[o.x_m + o.speed_rel_mps * t, o.y_m, GROUND_Z_EGO + o.size_m[2] / 2] for o in OBJECTS]
    return Boxes3D(np.array(centre), np.array([o.size_m for o in OBJECTS]), np.array([o.yaw_rel_rad for o in OBJECTS]))


def _hull_count(hull: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """(y1-y0, x1-x0) bool: pixel centres of the grid [x0, x1) x [y0, y1) inside the convex ``hull`` (M, 2)."""
    xs = np.arange(x0, x1) + 0.5
    ys = np.arange(y0, y1) + 0.5
    gx, gy = np.meshgrid(xs, ys)
    inside = np.ones(gx.shape, bool)
    for a, b in zip(hull, np.roll(hull, -1, axis=0), strict=True):
        inside &= (b[0] - a[0]) * (gy - a[1]) - (b[1] - a[1]) * (gx - a[0]) >= 0  # hull is counter-clockwise
    return inside


def _project(points_cam: np.ndarray) -> np.ndarray:
    return points_cam[:, :2] / points_cam[:, 2:3] * [K[0, 0], K[1, 1]] + K[:2, 2]


def _camera_masks(boxes: Boxes3D, cam_from_ego: Transform):
    """Per object: hull (M, 2), amodal box (4,), own full-image mask, full (virtual plane) pixel count."""
    out = []
    for corners in boxes.corners():
        uv = _project(cam_from_ego.apply(corners))
        hull = uv[ConvexHull(uv).vertices]
        (ax, ay), (bx, by) = hull[1] - hull[0], hull[2] - hull[1]
        if ax * by - ay * bx < 0:
            hull = hull[::-1]
        amodal = np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])
        gx0, gy0 = int(np.floor(amodal[0])), int(np.floor(amodal[1]))
        full = int(_hull_count(hull, gx0, gy0, int(np.ceil(amodal[2])), int(np.ceil(amodal[3]))).sum())
        own = _hull_count(hull, 0, 0, WIDTH, HEIGHT)
        out.append((amodal, own, full))
    return out


def _lidar_points(boxes_lidar: Boxes3D, ground_z: float, rng: np.random.Generator, n_ground: int) -> pd.DataFrame:
    """Points 2 cm inside the rear (-x) and top faces of each box, plus ground points outside the boxes."""
    pts, ids, sem = [], [], []
    for i, obj in enumerate(OBJECTS):
        length, width, height = boxes_lidar.size[i]
        n = 60
        rear = np.stack([np.full(n, -length / 2 + 0.02), rng.uniform(-width / 2 + 0.02, width / 2 - 0.02, n),
                         rng.uniform(-height / 2 + 0.02, height / 2 - 0.02, n)], axis=1)
        top = np.stack([rng.uniform(-length / 2 + 0.02, length / 2 - 0.02, n),
                        rng.uniform(-width / 2 + 0.02, width / 2 - 0.02, n), np.full(n, height / 2 - 0.02)], axis=1)
        local = np.concatenate([rear, top])
        c, s = np.cos(boxes_lidar.yaw_rad[i]), np.sin(boxes_lidar.yaw_rad[i])
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        pts.append(local @ rot.T + boxes_lidar.center[i])
        ids.append(np.full(len(local), obj.track_id))
        sem.append(np.full(len(local), obj.cls.semantic.value))
    ground = np.stack([rng.uniform(-20, 60, n_ground), rng.uniform(-15, 15, n_ground), np.full(n_ground, ground_z)],
                      axis=1)
    ground = ground[~boxes_lidar.contains(ground, margin_m=0.1).any(axis=0)]
    pts.append(ground)
    ids.append(np.zeros(len(ground), int))
    sem.append(np.full(len(ground), SemanticClass.ROAD.value))
    xyz = np.concatenate(pts)
    rng_m = np.linalg.norm(xyz, axis=1)
    elevation = np.degrees(np.arcsin(xyz[:, 2] / rng_m))
    return pd.DataFrame({
        "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2], "intensity": np.exp(-0.01 * rng_m),
        "ring": np.clip(np.round((elevation + 25.0) / 40.0 * 31), 0, 31), "instance_id": np.concatenate(ids),
        "semantic": np.concatenate(sem),
    }).astype(POINT_COLUMNS)


def _images(masks, boxes_cam: Boxes3D, night: bool, rng: np.random.Generator):
    """Instance (uint16), semantic (uint8), RGB (uint8) and depth (uint16) images for one frame."""
    instance = np.zeros((HEIGHT, WIDTH), np.uint16)
    semantic = np.zeros((HEIGHT, WIDTH), np.uint8)
    rows = np.arange(HEIGHT) + 0.5
    cam_height = CAMERA_MOUNT[2] - GROUND_Z_EGO
    with np.errstate(divide="ignore"):
        ground_depth = np.where(rows > K[1, 2], cam_height * K[1, 1] / (rows - K[1, 2]), 0.0)
    depth = np.repeat(ground_depth[:, None], WIDTH, axis=1)
    semantic[rows > K[1, 2]] = SemanticClass.ROAD.value
    order = np.argsort(-np.linalg.norm(boxes_cam.center, axis=1))  # far to near
    for i in order:
        own = masks[i][1]
        instance[own] = OBJECTS[i].track_id
        semantic[own] = OBJECTS[i].cls.semantic.value
        depth[own] = boxes_cam.center[i, 2] - boxes_cam.size[i, 0] / 2
    base = np.linspace(60, 200, HEIGHT, dtype=np.float64)[:, None, None] * np.ones((1, WIDTH, 3))
    base[instance > 0] = (37 * instance[instance > 0, None] % 255) * np.ones(3)
    rgb = np.clip(base * (0.3 if night else 1.0) + rng.integers(0, 8, base.shape), 0, 255).astype(np.uint8)
    depth_png = np.clip(np.round(depth * DEPTH_SCALE), 0, 65535).astype(np.uint16)
    return instance, semantic, rgb, depth_png


def _camera_rows(frame, boxes_ego, boxes_world, cam_from_ego, instance, masks, lidar_counts, ego_yaw):
    rows = []
    cam_centres = cam_from_ego.apply(boxes_ego.center)
    for i, obj in enumerate(OBJECTS):
        amodal, own, full = masks[i]
        unoccluded = int(own.sum())
        if unoccluded == 0:
            continue
        vis = instance == obj.track_id
        visible_px = int(vis.sum())
        tight = [pd.NA] * 4
        if visible_px:
            cols, rws = np.flatnonzero(vis.any(axis=0)), np.flatnonzero(vis.any(axis=1))
            tight = [float(cols[0]), float(rws[0]), float(cols[-1] + 1), float(rws[-1] + 1)]
        clip = np.clip(amodal, 0, [WIDTH, HEIGHT, WIDTH, HEIGHT])
        rows.append({
            "sensor": "front", "sensor_type": "camera", **_common(frame, obj, boxes_world, i),
            "sensor_x_m": cam_centres[i, 0], "sensor_y_m": cam_centres[i, 1], "sensor_z_m": cam_centres[i, 2],
            "sensor_yaw_rad": wrap_angle(-(boxes_world.yaw_rad[i] - ego_yaw) - np.pi / 2),
            "distance_m": float(np.linalg.norm(cam_centres[i])), "visible": visible_px > 0,
            "x1": tight[0], "y1": tight[1], "x2": tight[2], "y2": tight[3],
            **{f"amodal_{k}": float(v) for k, v in zip(("x1", "y1", "x2", "y2"), amodal, strict=True)},
            **{f"amodal_clip_{k}": float(v) for k, v in zip(("x1", "y1", "x2", "y2"), clip, strict=True)},
            "visible_px": visible_px, "unoccluded_px": unoccluded, "occlusion": 1.0 - visible_px / unoccluded,
            "truncation": 1.0 - unoccluded / max(full, unoccluded), "lidar_points": lidar_counts.get(obj.track_id, 0),
        })
    return rows


def _common(frame: int, obj: ObjectSpec, boxes_world: Boxes3D, i: int) -> dict:
    return {
        "frame": frame, "track_id": obj.track_id, "cls": obj.cls.value, "category_id": obj.cls.coco_id,
        "model": "box", "person": "adult" if obj.cls is ObjectClass.PEDESTRIAN else "",
        "x_m": boxes_world.center[i, 0], "y_m": boxes_world.center[i, 1], "z_m": boxes_world.center[i, 2],
        "length_m": boxes_world.size[i, 0], "width_m": boxes_world.size[i, 1], "height_m": boxes_world.size[i, 2],
        "yaw_rad": boxes_world.yaw_rad[i],
    }


def build_record(root: Path, *, scenario: str = "highway", seed: int = 1, condition: str = "morning",
                 frames: int = 2, ground_points: int = 2000) -> Path:
    """Write a canonical record with ``frames`` frames at 10 Hz into ``root`` (created); returns ``root``.

    ``ground_points`` per sweep (before removing those under objects); a real 64-channel sweep has ~100k.
    """
    root = Path(root)
    cam, lidar = camera_info(), lidar_info()
    info = RecordInfo(scenario, seed, condition, "test_rig", 10.0, [cam], [lidar])
    rng = np.random.default_rng(seed)
    cam_from_ego = Transform.from_matrix(cam.T_array).inverse()
    lidar_from_ego = Transform.from_matrix(lidar.T_array).inverse()
    frame_rows, label_rows = [], []
    for frame in range(FIRST_FRAME, FIRST_FRAME + frames):
        position, yaw = ego_pose(frame, seed)
        world_from_ego = Transform.from_xyz_rpy(tuple(position), (0.0, 0.0, yaw))
        boxes_ego = ego_boxes(frame)
        boxes_world = boxes_ego.transformed(world_from_ego)
        boxes_lidar = boxes_ego.transformed(lidar_from_ego)
        masks = _camera_masks(boxes_ego, cam_from_ego)
        points = _lidar_points(boxes_lidar, GROUND_Z_EGO - LIDAR_MOUNT[2], rng, ground_points)
        ids, counts = np.unique(points["instance_id"].to_numpy(), return_counts=True)
        lidar_counts = {int(i): int(c) for i, c in zip(ids, counts, strict=True) if i > 0}
        boxes_cam_centres = Boxes3D(cam_from_ego.apply(boxes_ego.center), boxes_ego.size, boxes_ego.yaw_rad)
        instance, semantic, rgb, depth = _images(masks, boxes_cam_centres, condition == "night", rng)
        for channel, image in (("rgb", rgb[:, :, ::-1]), ("instance", instance), ("semantic", semantic),
                               ("depth", depth)):
            path = camera_path(root, cam.name, channel, frame)
            path.parent.mkdir(parents=True, exist_ok=True)
            cv2.imwrite(str(path), image)
        path = lidar_path(root, lidar.name, frame)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_parquet(points, path)
        frame_rows.append({"frame": frame, "time_s": frame * 0.1, "ego_track_id": 1, "ego_x_m": position[0],
                           "ego_y_m": position[1], "ego_z_m": position[2], "ego_yaw_rad": yaw, "ego_speed_mps": 10.0})
        label_rows += _camera_rows(frame, boxes_ego, boxes_world, cam_from_ego, instance, masks, lidar_counts, yaw)
        for i, obj in enumerate(OBJECTS):
            n = lidar_counts.get(obj.track_id, 0)
            label_rows.append({
                "sensor": "top", "sensor_type": "lidar", **_common(frame, obj, boxes_world, i),
                "sensor_x_m": boxes_lidar.center[i, 0], "sensor_y_m": boxes_lidar.center[i, 1],
                "sensor_z_m": boxes_lidar.center[i, 2], "sensor_yaw_rad": boxes_lidar.yaw_rad[i],
                "distance_m": float(np.linalg.norm(boxes_lidar.center[i])), "visible": n > 0, "lidar_points": n,
            })
    write_parquet(pd.DataFrame(frame_rows).astype(FRAME_COLUMNS), root / "frames.parquet")
    labels = pd.DataFrame(label_rows).reindex(columns=list(LABEL_COLUMNS))
    write_parquet(labels.astype(LABEL_COLUMNS), root / "labels.parquet")
    (root / "record.json").write_text(info.to_json())
    meta = {"stage": "render", "seed": seed, "config": {"condition": condition, "scenario": scenario},
            "versions": {"roadsynth": "test"}, "command": ["roadsynth", "render"]}
    (root / "meta.json").write_text(json.dumps(meta, sort_keys=True, indent=2) + "\n")
    return root
