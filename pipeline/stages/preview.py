"""``roadsynth preview``: a contact sheet of a record's frames for people to look at.

Each row shows one frame: the first camera's image with tight 2D boxes (solid, class colour) and amodal
boxes clipped to the image (thin grey), labelled with class, track id and occlusion; and a bird's-eye
view of the first LiDAR's sweep (static points grey by intensity, object points in their class colour, the
same as the 2D boxes') with the 3D boxes of the LiDAR's labels and the first camera's horizontal field of
view (two cyan lines from the camera along the left and right image edges); where the record has radars, the
first radar's detections as discs coloured by radial velocity (RADAR_VELOCITY_RANGE_MPS: red approaching fast,
through green, to blue moving away; objects' detections ringed white).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import cv2
import numpy as np

from pipeline.core.classes import RIDER, ObjectClass, SemanticClass
from pipeline.core.files import atomic_file
from pipeline.core.geometry import Boxes3D
from pipeline.core.outputs import MARK, OutputSpec, png_file
from pipeline.core.png import with_text
from pipeline.core.record import CameraInfo, DatasetRecord, LidarInfo, RadarInfo
from pipeline.stages.common import int_at_least

log = logging.getLogger(__name__)

INPUT_ARGS = ("dataset",)
HELP = "draw a contact sheet of a dataset record: boxes on images and a bird's-eye LiDAR (and radar) view"
CLASS_BGR = {"car": (60, 200, 60), "van": (200, 200, 60), "truck": (40, 140, 255), "bus": (255, 120, 40),
             "motorcycle": (200, 60, 200), "bicycle": (255, 60, 160), "pedestrian": (60, 60, 255),
             "stroller": (180, 150, 255), "rider": (20, 110, 255)}
OTHER_BGR = (255, 255, 255)  # a class without a colour
FOV_BGR = (255, 255, 0)
BEV_RANGE_M, BEV_PX = 60.0, 600
RADAR_VELOCITY_RANGE_MPS = (-30.0, 10.0)  # the colour map's ends (red .. blue)
# Object points by their semantic class (the point clouds' ``semantic`` column), in the colours of CLASS_BGR.
_SEMANTIC_BGR = np.tile(np.array(OTHER_BGR, np.uint8), (256, 1))
for _cls in ObjectClass:
    _SEMANTIC_BGR[_cls.semantic] = CLASS_BGR.get(_cls.value, OTHER_BGR)
_SEMANTIC_BGR[SemanticClass.RIDER] = CLASS_BGR[RIDER]  # a cycle's rider's points


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--dataset", type=Path, required=True, help="a record folder from `roadsynth render`")
    parser.add_argument("--out", type=Path, required=True, help="PNG file to write (replaced atomically)")
    parser.add_argument("--frames", type=int_at_least(1), default=4, help="frames shown, evenly spaced (default 4)")
    parser.add_argument("--min-visible-px", type=int_at_least(0), default=20,
                        help="hide boxes with fewer visible pixels")


def outputs(args: argparse.Namespace) -> list[OutputSpec]:
    return [OutputSpec(args.out, folder=False, recognise=png_file, expected="a PNG image")]


def _camera_panel(record: DatasetRecord, camera: str, frame: int, labels, min_px: int) -> np.ndarray:
    img = np.ascontiguousarray(record.rgb(camera, frame)[:, :, ::-1])
    rows = labels[(labels["frame"] == frame) & (labels["sensor"] == camera) & labels["visible"]
                  & (labels["visible_px"] >= min_px)]
    for r in rows.itertuples(index=False):
        colour = CLASS_BGR.get(r.cls, OTHER_BGR)
        a = [round(v) for v in (r.amodal_clip_x1, r.amodal_clip_y1, r.amodal_clip_x2, r.amodal_clip_y2)]
        cv2.rectangle(img, (a[0], a[1]), (a[2] - 1, a[3] - 1), (170, 170, 170), 1, cv2.LINE_AA)
        t = [round(v) for v in (r.x1, r.y1, r.x2, r.y2)]
        cv2.rectangle(img, (t[0], t[1]), (t[2] - 1, t[3] - 1), colour, 2, cv2.LINE_AA)
        text = f"{r.cls} #{r.track_id} occ {r.occlusion:.2f}"
        cv2.putText(img, text, (t[0], max(t[1] - 4, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(img, text, (t[0], max(t[1] - 4, 10)), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1, cv2.LINE_AA)
    return img


def _to_bev(xy: np.ndarray) -> np.ndarray:
    """LiDAR x (forward) up, y (left) to the left; ego at the centre."""
    scale = BEV_PX / (2 * BEV_RANGE_M)
    return np.column_stack([BEV_PX / 2 - xy[:, 1] * scale, BEV_PX / 2 - xy[:, 0] * scale])


def point_colours(points) -> np.ndarray:
    """(N, 3) uint8 BGR colours of a sweep's points (a point-cloud table): static points grey by intensity,
    object points (``instance_id`` > 0) in the colour of their class."""
    level = np.clip(60 + 400 * points["intensity"].to_numpy(), 60, 255).astype(np.uint8)
    colours = np.repeat(level[:, None], 3, axis=1)
    on_object = points["instance_id"].to_numpy() > 0
    colours[on_object] = _SEMANTIC_BGR[points["semantic"].to_numpy()[on_object]]
    return colours


def camera_fov_bev(camera: CameraInfo, lidar: LidarInfo, samples: int = 33) -> tuple[np.ndarray, np.ndarray] | None:
    """The camera's horizontal field of view in the LiDAR frame, seen from above: its origin (2,) and the
    (2, 2) unit directions of its right and left edges (x forward, y left), taken over rays through the
    image's left and right borders (distortion undone, so a distorted lens shows its real field of view).
    None when the camera looks straight up or down."""
    w, h = camera.width_px, camera.height_px
    rows = np.linspace(0.0, h, samples)
    border = np.concatenate([np.column_stack([np.zeros(samples), rows]), np.column_stack([np.full(samples, w), rows])])
    # Iterate to convergence (the default 5 steps miss by ~1e-5 rad); OpenCV 4 names this variant ...Iter.
    undistort = getattr(cv2, "undistortPointsIter", cv2.undistortPoints)
    normalised = undistort(border.reshape(-1, 1, 2), camera.K_array, np.asarray(camera.distortion, np.float64),
                           R=None, P=None, criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))
    normalised = normalised.reshape(-1, 2)
    lidar_from_cam = np.linalg.inv(lidar.T_array) @ camera.T_array
    rotation = lidar_from_cam[:3, :3]
    rays = np.column_stack([normalised, np.ones(len(normalised))]) @ rotation.T
    axis = rotation[:2, 2]
    if np.linalg.norm(axis) < 1e-6:
        return None
    axis = axis / np.linalg.norm(axis)
    angle = np.arctan2(axis[0] * rays[:, 1] - axis[1] * rays[:, 0], rays[:, :2] @ axis)  # CCW from the axis
    edges = np.array([angle.min(), angle.max()])
    cos, sin = np.cos(edges), np.sin(edges)
    directions = np.column_stack([cos * axis[0] - sin * axis[1], sin * axis[0] + cos * axis[1]])
    return lidar_from_cam[:2, 3], directions


def _draw_fov(img: np.ndarray, camera: CameraInfo, lidar: LidarInfo) -> None:
    fov = camera_fov_bev(camera, lidar)
    if fov is None:
        return
    origin, directions = fov
    start = tuple(int(v) for v in np.round(_to_bev(origin[None, :])[0]))
    for direction in directions:
        end = _to_bev((origin + 3 * BEV_RANGE_M * direction)[None, :])[0]  # beyond the panel: cv2 clips
        cv2.line(img, start, tuple(int(v) for v in np.round(end)), FOV_BGR, 1, cv2.LINE_AA)


def radial_velocity_colours(velocity_mps: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 BGR: OpenCV's turbo colour map over RADAR_VELOCITY_RANGE_MPS, reversed so that an approaching
    target (negative) is red and one moving away blue."""
    low, high = RADAR_VELOCITY_RANGE_MPS
    level = np.clip((high - np.asarray(velocity_mps, np.float64)) / (high - low), 0.0, 1.0)
    return cv2.applyColorMap(np.round(255 * level).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_TURBO)[:, 0]


def _draw_radar(img: np.ndarray, record: DatasetRecord, radar: RadarInfo, lidar: LidarInfo, frame: int) -> int:
    """Draw the radar's detections of ``frame`` into the LiDAR's bird's-eye view; returns how many."""
    scan = record.radar_detections(radar.name, frame)
    xyz = scan[["x_m", "y_m", "z_m"]].to_numpy(np.float64)
    lidar_from_radar = np.linalg.inv(lidar.T_array) @ radar.T_array
    uv = np.round(_to_bev(xyz @ lidar_from_radar[:3, :3].T + lidar_from_radar[:3, 3])).astype(np.int32)
    colours = radial_velocity_colours(scan["radial_velocity_mps"].to_numpy())
    on_object = scan["instance_id"].to_numpy() > 0
    for (u, v), colour, ringed in zip(uv, colours, on_object, strict=True):
        if ringed:
            cv2.circle(img, (int(u), int(v)), 5, (255, 255, 255), 1, cv2.LINE_AA)
        cv2.circle(img, (int(u), int(v)), 3, tuple(int(c) for c in colour), -1, cv2.LINE_AA)
    return len(scan)


def _bev_panel(record: DatasetRecord, lidar_info: LidarInfo, frame: int, labels, height: int,
               camera: CameraInfo | None = None, radar: RadarInfo | None = None) -> np.ndarray:
    """The bird's-eye view of the LiDAR's sweep at ``frame``, ``height`` pixels square; with ``camera``, its
    field of view; with ``radar``, its detections."""
    lidar = lidar_info.name
    img = np.full((BEV_PX, BEV_PX, 3), 18, np.uint8)
    if camera is not None:
        _draw_fov(img, camera, lidar_info)
    pts = record.points(lidar, frame)
    uv = _to_bev(pts[["x_m", "y_m"]].to_numpy()).astype(np.int32)
    inside = (uv >= 0).all(1) & (uv < BEV_PX).all(1)
    img[uv[inside, 1], uv[inside, 0]] = point_colours(pts)[inside]
    rows = labels[(labels["frame"] == frame) & (labels["sensor"] == lidar)]
    if len(rows):
        boxes = Boxes3D(rows[["sensor_x_m", "sensor_y_m", "sensor_z_m"]].to_numpy(),
                        rows[["length_m", "width_m", "height_m"]].to_numpy(), rows["sensor_yaw_rad"].to_numpy())
        for corners, cls in zip(boxes.corners()[:, :4, :2], rows["cls"], strict=True):
            poly = _to_bev(corners).astype(np.int32)
            cv2.polylines(img, [poly], True, CLASS_BGR.get(cls, OTHER_BGR), 1, cv2.LINE_AA)
    cv2.circle(img, (BEV_PX // 2, BEV_PX // 2), 3, (255, 255, 255), -1)
    cv2.putText(img, f"{lidar}: {len(pts)} points, {BEV_RANGE_M:.0f} m", (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                (220, 220, 220), 1, cv2.LINE_AA)
    if radar is not None:
        count = _draw_radar(img, record, radar, lidar_info, frame)
        low, high = RADAR_VELOCITY_RANGE_MPS
        cv2.putText(img, f"{radar.name}: {count} detections, radial velocity {low:g} (red) .. {high:g} m/s (blue)",
                    (8, 36), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (220, 220, 220), 1, cv2.LINE_AA)
    return cv2.resize(img, (height, height), interpolation=cv2.INTER_NEAREST)


def contact_sheet(record: DatasetRecord, frames: int = 4, min_visible_px: int = 20) -> np.ndarray:
    """(H, W, 3) uint8 BGR sheet of ``frames`` evenly spaced frames."""
    all_frames = record.frames["frame"].to_numpy()
    if not len(all_frames):
        raise ValueError(f"{record.root}: the record has no frames")
    chosen = all_frames[np.unique(np.round(np.linspace(0, len(all_frames) - 1, min(frames, len(all_frames)))))
                        .astype(int)]
    labels = record.labels
    info = record.info
    rows = []
    for frame in chosen:
        panels = []
        if info.cameras:
            panels.append(_camera_panel(record, info.cameras[0].name, int(frame), labels, min_visible_px))
        height = panels[0].shape[0] if panels else BEV_PX
        if info.lidars:
            camera = info.cameras[0] if info.cameras else None
            radar = info.radars[0] if info.radars else None
            panels.append(_bev_panel(record, info.lidars[0], int(frame), labels, height, camera, radar))
        row = np.concatenate(panels, axis=1)
        title = f"{info.scenario} seed {info.seed} | {info.condition} | frame {frame}"
        cv2.putText(row, title, (8, height - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 3, cv2.LINE_AA)
        cv2.putText(row, title, (8, height - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (255, 255, 255), 1, cv2.LINE_AA)
        rows.append(row)
    return np.concatenate(rows, axis=0)


def main(args: argparse.Namespace) -> int:
    if args.out.suffix.lower() != ".png":
        raise ValueError(f"--out {args.out}: expected a .png file name, got {args.out.suffix or 'no extension'!r}")
    if args.frames < 1:
        raise ValueError(f"--frames must be >= 1, got {args.frames}")
    sheet = contact_sheet(DatasetRecord(args.dataset), args.frames, args.min_visible_px)
    ok, png = cv2.imencode(".png", sheet)  # the bytes cv2.imwrite would write, written atomically
    if not ok:
        raise OSError(f"{args.out}: could not encode the contact sheet")
    with atomic_file(args.out) as tmp:  # marked as ours: a rerun may replace it, another program's PNG it may not
        tmp.write_bytes(with_text(png.tobytes(), "Software", f"{MARK} preview"))
    log.info("wrote %s (%dx%d)", args.out, sheet.shape[1], sheet.shape[0])
    return 0
