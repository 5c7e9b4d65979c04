"""KITTI tracking export (the tracking devkit's layout): one sequence per record, all under ``DIR/training/``.

``training/image_02/<seq>/<frame>.png``, ``training/label_02/<seq>.txt``, ``training/calib/<seq>.txt``,
``training/velodyne/<seq>/<frame>.bin``, ``training/oxts/<seq>.txt``; sequences are numbered 0000, 0001, ... in
export order (records ordered by scenario, seed, condition), frames 000000, 000001, ... in each.
``training/evaluate_tracking.seqmap.<split>`` lists each split's sequences as the devkit's seqmaps do
(``<seq> empty 000000 <frames>``; TrackEval's ``Kitti2DBox`` reads it as ``SPLIT_TO_EVAL``), and ``DIR/mapping.txt``
gives per exported frame ``sequence frame scenario seed condition record_frame timestamp_s split``.

Conventions are exporters/kitti.py's (the same camera checks, classes, boxes, calib and velodyne), except where the
tracking devkit's readme differs:

- label_02: ``frame track_id type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y``; ``track_id`` is
  the record's; ``truncated`` is an integer level, 0 below 0.1 of the silhouette outside the image, 1 below 0.5,
  2 from 0.5 (the same bins as ``occluded``); objects the filter marks tiny or occluded are
  ``frame -1 DontCare -1 -1 -10 x1 y1 x2 y2 -1 -1 -1 -1000 -1000 -1000 -10``.
- calib: one file per sequence, the tracking devkit's names ``P0:`` .. ``P3:``, ``R_rect``, ``Tr_velo_cam``,
  ``Tr_imu_velo`` (the last three without a colon, as in the devkit's files).
- oxts: one line per frame, the 30 OXTS values. lat/lon are the ego position converted by the devkit's Mercator
  projection about latitude 0 (scale 1), so the devkit's ``convertOxtsToPose`` gives back our world x, y; alt = world
  z; roll = pitch = 0; yaw = our heading (0 = east, counter-clockwise, as OXTS's); vn, ve, vf from the ego speed,
  vl = vu = 0; accelerations and angular rates are not in the record: ``nan``; pos/vel accuracy 0 (exact); the five
  GPS status integers -1 (no GPS).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from exporters.base import CameraRows, Exporter, ExportError, ExportOptions
from exporters.filters import KEPT, FilterSummary
from exporters.kitti import KITTI_TYPE, kitti_type, occlusion_level, sensors_of
from exporters.source import ExportSource, safe_name
from exporters.writing import link_or_copy
from pipeline.core.classes import RIDER
from pipeline.core.geometry import wrap_angle
from pipeline.core.record import CameraInfo, LidarInfo

log = logging.getLogger(__name__)

TRUNCATION_LEVEL_EDGES = (0.1, 0.5)
"""Truncation fraction < 0.1: level 0 (not truncated); < 0.5: 1 (partly); otherwise 2 (largely)."""
DONT_CARE = "{} -1 DontCare -1 -1 -10 {:.2f} {:.2f} {:.2f} {:.2f} -1 -1 -1 -1000 -1000 -1000 -10"
EARTH_RADIUS_M = 6378137.0
"""The tracking devkit's earth radius (convertOxtsToPose / pykitti)."""


def truncation_level(truncation: np.ndarray) -> np.ndarray:
    """(N,) int KITTI tracking truncated level 0-2 of (N,) truncation fractions."""
    return np.searchsorted(np.asarray(TRUNCATION_LEVEL_EDGES), np.asarray(truncation, dtype=np.float64), side="right")


def calib_text(cam: CameraInfo, lidar: LidarInfo) -> str:
    """The tracking calib file: P0..P3, R_rect, Tr_velo_cam, Tr_imu_velo (row-major, %.12e)."""
    p = np.hstack([cam.K_array, np.zeros((3, 1))])
    rows = [(f"P{i}:", p) for i in range(4)] + [
        ("R_rect", np.eye(3)), ("Tr_velo_cam", (np.linalg.inv(cam.T_array) @ lidar.T_array)[:3]),
        ("Tr_imu_velo", np.linalg.inv(lidar.T_array)[:3])]
    return "".join(f"{name} {' '.join(f'{v:.12e}' for v in m.reshape(-1))}\n" for name, m in rows)


def label_lines(table: CameraRows, rows: np.ndarray, frame: int) -> list[str]:
    """label_02 lines of one frame's shown rows: objects by track id, then DontCare regions."""
    objects, dont_care = [], []
    col = table.columns
    occluded = occlusion_level(np.nan_to_num(col["occlusion"][rows], nan=0.0))
    truncated = truncation_level(np.nan_to_num(col["truncation"][rows], nan=0.0))
    for j, i in enumerate(rows):
        x1, y1, x2, y2 = table.boxes[i]
        if table.reasons[i] != KEPT:
            dont_care.append(DONT_CARE.format(frame, x1, y1, x2, y2))
            continue
        h, w, length = col["height_m"][i], col["width_m"][i], col["length_m"][i]
        x, y, z = col["sensor_x_m"][i], col["sensor_y_m"][i] + h / 2.0, col["sensor_z_m"][i]  # bottom centre (y down)
        ry = wrap_angle(col["sensor_yaw_rad"][i])
        alpha = wrap_angle(ry - np.arctan2(x, z))
        kind = kitti_type(col["cls"][i], col["person"][i])
        objects.append(f"{frame} {int(col['track_id'][i])} {kind} {int(truncated[j])} "
                       f"{int(occluded[j])} {alpha:.2f} {x1:.2f} {y1:.2f} {x2:.2f} {y2:.2f} {h:.2f} {w:.2f} "
                       f"{length:.2f} {x:.2f} {y:.2f} {z:.2f} {ry:.2f}")
    return objects + dont_care


def oxts_lines(frames) -> str:
    """The oxts file of a record's frames (frames.parquet rows, in order): one line of 30 values per frame."""
    x, y = frames["ego_x_m"].to_numpy(np.float64), frames["ego_y_m"].to_numpy(np.float64)
    z, yaw = frames["ego_z_m"].to_numpy(np.float64), frames["ego_yaw_rad"].to_numpy(np.float64)
    speed = frames["ego_speed_mps"].to_numpy(np.float64)
    lon = np.degrees(x / EARTH_RADIUS_M)
    lat = np.degrees(2.0 * np.arctan(np.exp(y / EARTH_RADIUS_M))) - 90.0
    zeros, nan = np.zeros_like(x), np.full_like(x, np.nan)
    values = np.stack([lat, lon, z, zeros, zeros, yaw, speed * np.sin(yaw), speed * np.cos(yaw), speed, zeros, zeros,
                       *[nan] * 12, zeros, zeros], axis=1)
    return "".join(" ".join(f"{v:.12g}" for v in line) + " -1 -1 -1 -1 -1\n" for line in values)


class KittiTrackingExporter(Exporter):
    name = "kitti-tracking"

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
        for sub in ("image_02", "label_02", "calib", "velodyne", "oxts"):
            (training / sub).mkdir(parents=True)
        summary = FilterSummary()
        seqmaps: dict[str, list[str]] = {s: [] for s in source.split_names}
        mapping, linked, points, frames = [], 0, 0, 0
        progress = tqdm(total=source.n_frames(), desc="kitti-tracking", unit="frame", disable=not options.progress)
        for number, src in enumerate(source.records):
            cam, lidar = sensors_of(src, options)
            table = CameraRows(src, cam.name, options, riders=False)
            seq = f"{number:04d}"
            (training / "image_02" / seq).mkdir()
            (training / "velodyne" / seq).mkdir()
            lines = []
            for index, row in enumerate(src.frames.itertuples(index=False)):
                frame, stem = int(row.frame), f"{index:06d}"
                image = src.record.image_path(cam.name, "rgb", frame)
                linked += link_or_copy(image, training / "image_02" / seq / f"{stem}.png", link=options.link_images)
                lines += label_lines(table, table.rows(frame, summary), index)
                cloud = src.record.points(lidar.name, frame)
                xyzi = cloud[["x_m", "y_m", "z_m", "intensity"]].to_numpy(dtype=np.float32)
                (training / "velodyne" / seq / f"{stem}.bin").write_bytes(np.ascontiguousarray(xyzi).tobytes())
                points += len(xyzi)
                mapping.append(f"{seq} {stem} {safe_name(src.info.scenario)} {int(src.info.seed)} "
                               f"{safe_name(src.info.condition)} {frame} {float(row.time_s):.6f} {src.split}\n")
                progress.update()
            (training / "label_02" / f"{seq}.txt").write_text("".join(f"{line}\n" for line in lines))
            (training / "calib" / f"{seq}.txt").write_text(calib_text(cam, lidar))
            (training / "oxts" / f"{seq}.txt").write_text(oxts_lines(src.frames))
            seqmaps[src.split].append(f"{seq} empty 000000 {len(src.frames):06d}\n")
            frames += len(src.frames)
        progress.close()
        for split, lines in seqmaps.items():
            (training / f"evaluate_tracking.seqmap.{safe_name(split)}").write_text("".join(lines))
        (tmp / "mapping.txt").write_text("".join(mapping))
        return {"frames": frames, "sequences": {s: len(v) for s, v in seqmaps.items()}, "images_linked": int(linked),
                "images_copied": frames - int(linked), "lidar_points": int(points), "objects": summary.to_dict()}


EXPORTER = KittiTrackingExporter()
