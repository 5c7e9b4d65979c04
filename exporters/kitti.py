"""KITTI object export (devkit layout): ``DIR/training/{image_2,label_2,calib,velodyne}/NNNNNN.*``,
``DIR/ImageSets/<split>.txt`` and ``DIR/mapping.txt``.

Frames of all records are numbered 000000, 000001, ... in export order; ``mapping.txt`` gives, per
index, ``scenario seed condition frame timestamp_s split``. One camera (``--camera``, default the
record's first) is image_2 and one LiDAR (``--lidar``, default the first) is velodyne.

Conventions (the devkit's readme.txt; mapping and thresholds in exporters/README.md):

- label_2: ``type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y``, one object per line;
  location is the bottom centre of the box in the rectified camera frame; objects the filter marks
  tiny or occluded become ``DontCare`` regions (dropping their 3D fields as the devkit does).
- Our 2D boxes are continuous with x2 = last covered column + 1 (docs/design.md); written as is.
- calib: the rectified reference camera *is* our camera, so R0_rect = I and P0 = P1 = P2 = P3 = [K | 0]
  (one camera, no stereo baseline); Tr_velo_to_cam maps LiDAR to camera; Tr_imu_to_velo maps the ego
  body frame (x forward, y left, z up, like KITTI's OXTS/IMU frame) to the LiDAR.
- velodyne: float32 x, y, z, intensity per point, LiDAR frame.

KITTI's model is a level pinhole camera: a camera with lens distortion or pitch/roll is refused.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from exporters.base import CameraRows, Exporter, ExportError, ExportOptions, sensors_text
from exporters.filters import KEPT, FilterSummary
from exporters.source import ExportSource, RecordSource, safe_name
from exporters.writing import link_or_copy
from pipeline.core.classes import RIDER, Person
from pipeline.core.geometry import wrap_angle
from pipeline.core.record import CameraInfo, LidarInfo

log = logging.getLogger(__name__)

KITTI_TYPE = {"car": "Car", "van": "Van", "truck": "Truck", "bus": "Misc", "motorcycle": "Misc",
              "bicycle": "Cyclist", "pedestrian": "Pedestrian", "stroller": "Misc"}
"""Our class -> KITTI type. KITTI has no bus, motorcycle or stroller class; 'Misc' holds other objects there."""


def kitti_type(cls: str, person: str) -> str:
    """A label row's KITTI type: :data:`KITTI_TYPE` of its class, but a wheelchair user (``person``) is
    ``Person_sitting``, as KITTI's annotators label a seated person (its evaluation neither counts nor punishes it
    for Pedestrian: a neighbouring class)."""
    return "Person_sitting" if cls == "pedestrian" and person == Person.WHEELCHAIR_USER.value else KITTI_TYPE[cls]


OCCLUSION_LEVEL_EDGES = (0.1, 0.5)
"""Occlusion fraction < 0.1: level 0 (fully visible); < 0.5: 1 (partly); otherwise 2 (largely)."""

DONT_CARE = "DontCare -1 -1 -10 {:.2f} {:.2f} {:.2f} {:.2f} -1 -1 -1 -1000 -1000 -1000 -10"


def occlusion_level(occlusion: np.ndarray) -> np.ndarray:
    """(N,) int KITTI occluded level 0-2 of (N,) occlusion fractions (level 3, unknown, never applies)."""
    return np.searchsorted(np.asarray(OCCLUSION_LEVEL_EDGES), np.asarray(occlusion, dtype=np.float64), side="right")


def camera_and_lidar(src: RecordSource, options: ExportOptions) -> tuple[CameraInfo, LidarInfo]:
    """The camera (``options.camera``, default the first) and the LiDAR (``options.lidar``, default the first) of a
    record that has both; :class:`ExportError` naming the record when the one asked for is not there."""
    info, root = src.info, src.record.root
    try:
        cam = info.camera(options.camera) if options.camera else info.cameras[0]
    except KeyError as exc:
        raise ExportError(f"{root}: {exc.args[0]}") from None
    lidars = {x.name: x for x in info.lidars}
    name = options.lidar or info.lidars[0].name
    if name not in lidars:
        raise ExportError(f"{root}: no LiDAR {name!r}; LiDARs: {', '.join(lidars)}")
    return cam, lidars[name]


def sensors_of(src: RecordSource, options: ExportOptions) -> tuple[CameraInfo, LidarInfo]:
    """The camera and LiDAR a record contributes; :class:`ExportError` if missing or not KITTI-compatible."""
    info, root = src.info, src.record.root
    if not info.cameras or not info.lidars:
        missing = "camera or LiDAR" if not (info.cameras or info.lidars) else "camera" if not info.cameras else "LiDAR"
        raise ExportError(f"{root}: the record has no {missing} ({sensors_text(info)}); KITTI needs a camera "
                          "(image_2) and a LiDAR (velodyne) in every record")
    cam, lidar = camera_and_lidar(src, options)
    if np.any(np.abs(cam.distortion) > 0):
        raise ExportError(f"{root}: camera {cam.name} has lens distortion {cam.distortion}; KITTI's calib models "
                          "a rectified pinhole camera (export COCO/MCAP instead, or render without distortion)")
    if not np.allclose(cam.T_array[:3, 1], [0.0, 0.0, -1.0], atol=1e-6):
        raise ExportError(f"{root}: camera {cam.name} is not level (its image y axis is {cam.T_array[:3, 1]} in the "
                          "ego frame, not straight down); KITTI's 3D labels assume a level camera")
    return cam, lidar


def calib_text(cam: CameraInfo, lidar: LidarInfo) -> str:
    """The calib file: P0..P3, R0_rect, Tr_velo_to_cam, Tr_imu_to_velo (row-major, %.12e)."""
    p = np.hstack([cam.K_array, np.zeros((3, 1))])
    tr_velo_to_cam = np.linalg.inv(cam.T_array) @ lidar.T_array
    tr_imu_to_velo = np.linalg.inv(lidar.T_array)
    rows = [(f"P{i}", p) for i in range(4)] + [
        ("R0_rect", np.eye(3)), ("Tr_velo_to_cam", tr_velo_to_cam[:3]), ("Tr_imu_to_velo", tr_imu_to_velo[:3])]
    return "".join(f"{name}: {' '.join(f'{v:.12e}' for v in m.reshape(-1))}\n" for name, m in rows)


def label_lines(table: CameraRows, rows: np.ndarray) -> list[str]:
    """label_2 lines of one frame's shown rows (``CameraRows.rows``): objects by track id, then DontCare regions."""
    objects, dont_care = [], []
    col = table.columns
    levels = occlusion_level(np.nan_to_num(col["occlusion"][rows], nan=0.0))
    for j, i in enumerate(rows):
        x1, y1, x2, y2 = table.boxes[i]
        if table.reasons[i] != KEPT:
            dont_care.append(DONT_CARE.format(x1, y1, x2, y2))
            continue
        h, w, length = col["height_m"][i], col["width_m"][i], col["length_m"][i]
        x, y, z = col["sensor_x_m"][i], col["sensor_y_m"][i] + h / 2.0, col["sensor_z_m"][i]  # bottom centre (y down)
        ry = wrap_angle(col["sensor_yaw_rad"][i])
        alpha = wrap_angle(ry - np.arctan2(x, z))
        kind = kitti_type(col["cls"][i], col["person"][i])
        objects.append(f"{kind} {min(max(float(col['truncation'][i]), 0.0), 1.0):.2f} "
                       f"{int(levels[j])} {alpha:.2f} {x1:.2f} {y1:.2f} {x2:.2f} {y2:.2f} {h:.2f} {w:.2f} "
                       f"{length:.2f} {x:.2f} {y:.2f} {z:.2f} {ry:.2f}")
    return objects + dont_care


class KittiExporter(Exporter):
    name = "kitti"

    def check(self, source: ExportSource, options: ExportOptions) -> None:
        for src in source.records:
            sensors_of(src, options)
            unknown = sorted(set(src.labels["cls"]) - set(KITTI_TYPE) - {RIDER})  # a rider: in its Cyclist
            if unknown:
                raise ExportError(f"{src.record.root}: classes {unknown} have no KITTI type "
                                  f"(known: {sorted(KITTI_TYPE)})")

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        training = tmp / "training"
        for sub in ("image_2", "label_2", "calib", "velodyne"):
            (training / sub).mkdir(parents=True)
        summary = FilterSummary()
        sets: dict[str, list[str]] = {s: [] for s in source.split_names}
        mapping, linked, points = [], 0, 0
        per_record = {}
        for src in source.records:
            cam, lidar = sensors_of(src, options)
            per_record[id(src)] = (cam, lidar, CameraRows(src, cam.name, options, riders=False), calib_text(cam, lidar))
        for index, item in enumerate(tqdm(source.frames(), total=source.n_frames(), desc="kitti", unit="frame",
                                          disable=not options.progress)):
            cam, lidar, labels, calib = per_record[id(item.source)]
            stem = f"{index:06d}"
            linked += link_or_copy(item.source.record.image_path(cam.name, "rgb", item.frame),
                                   training / "image_2" / f"{stem}.png", link=options.link_images)
            lines = label_lines(labels, labels.rows(item.frame, summary))
            (training / "label_2" / f"{stem}.txt").write_text("".join(f"{line}\n" for line in lines))
            (training / "calib" / f"{stem}.txt").write_text(calib)
            cloud = item.source.record.points(lidar.name, item.frame)
            xyzi = cloud[["x_m", "y_m", "z_m", "intensity"]].to_numpy(dtype=np.float32)
            (training / "velodyne" / f"{stem}.bin").write_bytes(np.ascontiguousarray(xyzi).tobytes())
            points += len(xyzi)
            sets[item.source.split].append(stem)
            attrs = item.source.attributes(item.frame, item.time_s)
            mapping.append(f"{stem} {safe_name(attrs['scenario'])} {attrs['seed']} {safe_name(attrs['condition'])} "
                           f"{attrs['frame']} {attrs['timestamp_s']:.6f} {item.source.split}\n")
        (tmp / "ImageSets").mkdir()
        for split, stems in sets.items():
            (tmp / "ImageSets" / f"{safe_name(split)}.txt").write_text("".join(f"{s}\n" for s in stems))
        (tmp / "mapping.txt").write_text("".join(mapping))
        return {"frames": len(mapping), "images_linked": int(linked), "images_copied": len(mapping) - int(linked),
                "lidar_points": int(points), "objects": summary.to_dict()}


EXPORTER = KittiExporter()
