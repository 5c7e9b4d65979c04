"""KITTI depth export (the depth completion / prediction benchmark's layout): one drive per record.

``DIR/<split>/<drive>/`` holds, per exported frame ``<i:010d>`` (0, 1, ... in record order):

- ``image_02/data/<i>.png``: the camera's RGB image (hard-linked from the record, as the raw drives have it);
- ``proj_depth/groundtruth/image_02/<i>.png``: dense ground truth, the record's depth image;
- ``proj_depth/velodyne_raw/image_02/<i>.png``: the LiDAR sweep projected into the camera (sparse);
- ``calib_cam_to_cam.txt``, ``calib_velo_to_cam.txt``, ``calib_imu_to_velo.txt`` in the raw drives' format.

Drives are named ``2026_01_01_drive_<n:04d>_sync``, n = 1, 2, ... in export order (records ordered by scenario,
seed, condition) across all splits; ``DIR/mapping.txt`` gives per frame ``split drive frame scenario seed condition
record_frame timestamp_s`` and ``export.json``'s ``counts.drives`` the record of each drive.

Depth PNGs follow the benchmark's readme: uint16 grey, depth = value / 256 metres, value 0 = no measurement
(``valid = png > 0``). Depth is the **z-depth** along the optical axis in the camera frame, which is what the record
stores (docs/design.md), so the ground truth is the record's image with one change: the record's value 65535
("255.996 m or farther", not a measurement) becomes 0, as does no hit (sky). The sparse map takes every LiDAR point
in front of the camera, projects it with the pinhole model (u = fx x/z + cx, v = fy y/z + cy) onto the pixel that
covers it (col = floor(u), row = floor(v): pixel (col, row) covers [col, col+1) x [row, row+1)), and keeps the
nearest point per pixel; its value is round(z * 256) to nearest (ties to even), written where it is 1..65534
(points 255.998 m or farther away are left out, like the ground truth's saturated pixels). Like KITTI's own
velodyne_raw, it is the raw projection: a point the LiDAR sees but the camera does not (past an object's edge, from
the LiDAR's higher viewpoint) still lands in the map.

Calibration: the rectified reference camera is our camera, so every camera 00-03 of calib_cam_to_cam.txt is our
camera (K, no distortion, R = R_rect = I, T = 0, P_rect = [K | 0]; no stereo baseline); calib_velo_to_cam.txt's R, T
map the LiDAR frame to the camera frame (``inv(T_ego_cam) T_ego_lidar``); calib_imu_to_velo.txt maps the ego body
frame (x forward, y left, z up, like KITTI's OXTS/IMU frame) to the LiDAR (``inv(T_ego_lidar)``). A camera with lens
distortion is refused (KITTI's images are rectified); a camera's pitch or roll is fine for depth.
"""

from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from exporters.base import Exporter, ExportError, ExportOptions, sensors_text
from exporters.kitti import camera_and_lidar
from exporters.source import ExportSource, RecordSource, safe_name
from exporters.writing import link_or_copy
from pipeline.core.png import encode_png
from pipeline.core.record import DEPTH_SCALE, CameraInfo, LidarInfo, RecordError, camera_path, lidar_path

log = logging.getLogger(__name__)

DRIVE_DATE = "2026_01_01"
"""The date part of every drive name (KITTI's drives are named after their recording day; ours have none)."""
CALIB_TIME = "01-Jan-2026 00:00:00"
SATURATED = 65535
"""The record's depth value for '255.996 m or farther': not a measurement, written 0."""
MAX_VALUE = SATURATED - 1
"""The largest depth value written (255.9922 m)."""
DEPTH_FILTER = "sub"
"""PNG row filter of the ground truth where it is encoded here (the record's own choice for depth)."""
SPARSE_FILTER = "none"
"""PNG row filter of the sparse maps: mostly zeros, which deflate smaller and faster unfiltered than as Sub's
differences."""
FRAME_THREADS = 2
"""Frames written at once. Each frame's files are a function of that frame alone, so the bytes do not depend on
the count; two overlap one frame's deflating with the next one's reading (bench/bench_export.py)."""


def drive_name(number: int) -> str:
    """The KITTI-style name of drive ``number`` (1-based): ``2026_01_01_drive_0001_sync``."""
    return f"{DRIVE_DATE}_drive_{number:04d}_sync"


def groundtruth_values(raw: np.ndarray) -> np.ndarray:
    """(H, W) uint16 benchmark ground truth of the record's (H, W) uint16 depth image: the saturated value 0."""
    return np.where(raw == SATURATED, np.uint16(0), raw)


def sparse_depth(points_cam: np.ndarray, K: np.ndarray, width: int, height: int) -> tuple[np.ndarray, int]:
    """The projected LiDAR depth map and the number of in-view points left out as too far.

    Args:
        points_cam: (N, 3) float64 points in the camera's optical frame (x right, y down, z forward), metres.
        K: (3, 3) float64 intrinsics (pinhole, no distortion).
        width, height: the image size in pixels.

    Returns:
        (height, width) uint16 z-depth x 256 rounded to nearest, the nearest point per pixel, 0 where none; and the
        count of points that land in the image but lie 255.998 m or farther (value above :data:`MAX_VALUE`).
    """
    x, y, z = points_cam[:, 0], points_cam[:, 1], points_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):  # points at z <= 0 are dropped below
        u = (K[0, 0] * x + K[0, 1] * y) / z + K[0, 2]
        v = K[1, 1] * y / z + K[1, 2]
    # floor(u) in [0, width) <=> u in [0, width); NaN fails every comparison
    inside = (z > 0.0) & (u >= 0.0) & (u < width) & (v >= 0.0) & (v < height)
    value = np.rint(z[inside] * DEPTH_SCALE)
    too_far = int(np.count_nonzero(value > MAX_VALUE))
    near = (value >= 1) & (value <= MAX_VALUE)
    pixel = v[inside][near].astype(np.int64) * width + u[inside][near].astype(np.int64)  # truncation = floor here
    # the nearest point per pixel: a minimum over repeated indices (a plain scatter leaves the winner undefined)
    out = np.full(height * width, SATURATED, np.uint16)
    np.minimum.at(out, pixel, value[near].astype(np.uint16))
    out[out == SATURATED] = 0
    return out.reshape(height, width), too_far


def points_in_front(cloud: dict[str, np.ndarray], transform: np.ndarray) -> np.ndarray:
    """(M, 3) float64 camera-frame points, of a sweep's ``x_m``, ``y_m``, ``z_m`` columns under the (4, 4)
    ``transform``, that lie in front of the camera (z > 0): z first, so that x and y are computed only for those (a
    sweep is 360 degrees, about half of it behind the camera); column by column, where a (N, 3) @ (3, 3) product
    goes through BLAS at many times the cost."""
    x, y, z = (cloud[c].astype(np.float64) for c in ("x_m", "y_m", "z_m"))
    r = transform
    depth = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z + r[2, 3]
    front = depth > 0.0
    x, y, z = x[front], y[front], z[front]
    out = np.empty((len(x), 3), np.float64)
    for i in range(2):
        out[:, i] = r[i, 0] * x + r[i, 1] * y + r[i, 2] * z + r[i, 3]
    out[:, 2] = depth[front]
    return out


def _line(name: str, values: np.ndarray) -> str:
    return f"{name}: {' '.join(f'{v:.12e}' for v in np.asarray(values, dtype=np.float64).reshape(-1))}\n"


def calib_cam_to_cam(cam: CameraInfo) -> str:
    """calib_cam_to_cam.txt: cameras 00-03 all our camera (rectified, no baseline)."""
    size = np.array([cam.width_px, cam.height_px], dtype=np.float64)
    p = np.hstack([cam.K_array, np.zeros((3, 1))])
    text = f"calib_time: {CALIB_TIME}\n" + _line("corner_dist", np.zeros(1))
    for i in range(4):
        text += "".join([_line(f"S_{i:02d}", size), _line(f"K_{i:02d}", cam.K_array), _line(f"D_{i:02d}", np.zeros(5)),
                         _line(f"R_{i:02d}", np.eye(3)), _line(f"T_{i:02d}", np.zeros(3)),
                         _line(f"S_rect_{i:02d}", size), _line(f"R_rect_{i:02d}", np.eye(3)),
                         _line(f"P_rect_{i:02d}", p)])
    return text


def _rigid_text(transform: np.ndarray, extra: str = "") -> str:
    return f"calib_time: {CALIB_TIME}\n" + _line("R", transform[:3, :3]) + _line("T", transform[:3, 3]) + extra


def cam_from_lidar(cam: CameraInfo, lidar: LidarInfo) -> np.ndarray:
    """(4, 4) float64 transform of LiDAR-frame points into the camera's optical frame."""
    return np.linalg.inv(cam.T_array) @ lidar.T_array


def calib_velo_to_cam(cam: CameraInfo, lidar: LidarInfo) -> str:
    """calib_velo_to_cam.txt: R, T (LiDAR -> camera); delta_f, delta_c 0 (no sweep-time compensation needed)."""
    return _rigid_text(cam_from_lidar(cam, lidar), _line("delta_f", np.zeros(2)) + _line("delta_c", np.zeros(2)))


def calib_imu_to_velo(lidar: LidarInfo) -> str:
    """calib_imu_to_velo.txt: R, T (ego body frame -> LiDAR)."""
    return _rigid_text(np.linalg.inv(lidar.T_array))


def depth_sensors(src: RecordSource, options: ExportOptions) -> tuple[CameraInfo, LidarInfo]:
    """The camera and LiDAR a record contributes; :class:`ExportError` naming the record and what is missing."""
    info, root = src.info, src.record.root
    if not info.lidars:
        raise ExportError(f"{root}: the record has no LiDAR ({sensors_text(info)}); a kitti-depth export writes each "
                          "frame's LiDAR sweep projected into the camera (proj_depth/velodyne_raw), so it needs one")
    cam, lidar = camera_and_lidar(src, options)
    if np.any(np.abs(cam.distortion) > 0):
        raise ExportError(f"{root}: camera {cam.name} has lens distortion {cam.distortion}; KITTI's depth maps belong "
                          "to rectified pinhole images (render without distortion)")
    return cam, lidar


def check_files(src: RecordSource, cam: CameraInfo, lidar: LidarInfo) -> None:
    """Refuse, before anything is written, a record whose camera has no depth image or whose LiDAR has no sweep for
    one of its frames, naming the record, the sensor, the frame and the file."""
    root = src.record.root
    for frame in src.frames["frame"].to_numpy():
        depth = camera_path(root, cam.name, "depth", int(frame))
        if not depth.is_file():
            raise ExportError(f"{root}: the record has no depth image of camera {cam.name} for frame {int(frame)} "
                              f"({depth} is missing); a kitti-depth export's ground truth is the camera's depth")
        sweep = lidar_path(root, lidar.name, int(frame))
        if not sweep.is_file():
            raise ExportError(f"{root}: the record has no sweep of LiDAR {lidar.name} for frame {int(frame)} "
                              f"({sweep} is missing); a kitti-depth export projects it into velodyne_raw")


@dataclass
class DepthCounts:
    """What the export wrote and left out (of one frame, or summed), for ``export.json``."""

    images_linked: int = 0
    groundtruth_linked: int = 0
    groundtruth_rewritten: int = 0
    saturated_px: int = 0
    points_too_far: int = 0
    sparse_px: int = 0

    def add(self, other: DepthCounts) -> None:
        for name in self.__dataclass_fields__:
            setattr(self, name, getattr(self, name) + getattr(other, name))


@dataclass(frozen=True)
class FrameJob:
    """One frame to export: where from (record, sensors, frame number) and where to (drive folder, file stem)."""

    source: RecordSource
    cam: CameraInfo
    lidar: LidarInfo
    frame: int
    drive: Path
    stem: str


def read_depth(src: RecordSource, cam: CameraInfo, frame: int) -> tuple[Path, np.ndarray]:
    """The path and (H, W) uint16 values of a frame's record depth image."""
    import cv2

    path = src.record.image_path(cam.name, "depth", frame)
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 2:
        raise RecordError(f"{path}: not a one-channel 16-bit depth image (frame {frame}, camera {cam.name})")
    return path, raw


def write_frame(job: FrameJob, link: bool) -> DepthCounts:
    """One frame's RGB image, ground truth and sparse map; what it wrote and left out. Reads and writes only this
    frame's files, so frames run on several threads (the decoding, deflating and Parquet reading release the
    interpreter lock) and the bytes do not depend on their order."""
    src, cam, frame, drive, stem = job.source, job.cam, job.frame, job.drive, job.stem
    counts = DepthCounts()
    counts.images_linked = int(link_or_copy(src.record.image_path(cam.name, "rgb", frame),
                                            drive / "image_02" / "data" / f"{stem}.png", link=link))
    path, raw = read_depth(src, cam, frame)
    gt = drive / "proj_depth" / "groundtruth" / "image_02" / f"{stem}.png"
    counts.saturated_px = int(np.count_nonzero(raw == SATURATED))
    if counts.saturated_px:
        gt.write_bytes(encode_png(groundtruth_values(raw), DEPTH_FILTER, name=str(gt)))
        counts.groundtruth_rewritten = 1
    else:  # the record's image is the ground truth as it is
        counts.groundtruth_linked = int(link_or_copy(path, gt, link=link))
    points = points_in_front(src.record.point_columns(job.lidar.name, frame), cam_from_lidar(cam, job.lidar))
    sparse, counts.points_too_far = sparse_depth(points, cam.K_array, cam.width_px, cam.height_px)
    sparse_path = drive / "proj_depth" / "velodyne_raw" / "image_02" / f"{stem}.png"
    sparse_path.write_bytes(encode_png(sparse, SPARSE_FILTER, name=str(sparse_path)))
    counts.sparse_px = int(np.count_nonzero(sparse))
    return counts


def start_drive(drive: Path, cam: CameraInfo, lidar: LidarInfo) -> None:
    """A drive's folders and calibration files."""
    for sub in ("image_02/data", "proj_depth/groundtruth/image_02", "proj_depth/velodyne_raw/image_02"):
        (drive / sub).mkdir(parents=True)
    (drive / "calib_cam_to_cam.txt").write_text(calib_cam_to_cam(cam))
    (drive / "calib_velo_to_cam.txt").write_text(calib_velo_to_cam(cam, lidar))
    (drive / "calib_imu_to_velo.txt").write_text(calib_imu_to_velo(lidar))


class KittiDepthExporter(Exporter):
    name = "kitti-depth"
    needs_camera = True

    def check(self, source: ExportSource, options: ExportOptions) -> None:
        for src in source.records:
            check_files(src, *depth_sensors(src, options))

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        jobs, mapping, drives = [], [], {}
        per_split = dict.fromkeys(source.split_names, 0)
        for number, src in enumerate(source.records, start=1):
            cam, lidar = depth_sensors(src, options)
            name = drive_name(number)
            drive = tmp / safe_name(src.split) / name
            start_drive(drive, cam, lidar)
            origin = f"{safe_name(src.info.scenario)} {int(src.info.seed)} {safe_name(src.info.condition)}"
            for index, row in enumerate(src.frames.itertuples(index=False)):
                jobs.append(FrameJob(src, cam, lidar, int(row.frame), drive, f"{index:010d}"))
                mapping.append(f"{safe_name(src.split)} {name} {index:010d} {origin} {int(row.frame)} "
                               f"{float(row.time_s):.6f}\n")
            drives[name] = {"scenario": src.info.scenario, "seed": int(src.info.seed), "condition": src.info.condition,
                            "split": src.split, "camera": cam.name, "lidar": lidar.name, "frames": len(src.frames)}
            per_split[src.split] += 1
        counts = DepthCounts()
        with tqdm(total=len(jobs), desc="kitti-depth", unit="frame", disable=not options.progress) as progress, \
                ThreadPoolExecutor(max_workers=FRAME_THREADS, thread_name_prefix="kitti-depth") as pool:
            try:
                for frame_counts in pool.map(write_frame, jobs, [options.link_images] * len(jobs)):
                    counts.add(frame_counts)
                    progress.update()
            except BaseException:
                pool.shutdown(wait=True, cancel_futures=True)  # no frame starts writing after a failure
                raise
        (tmp / "mapping.txt").write_text("".join(mapping))
        if counts.saturated_px:
            log.info("kitti-depth: %d ground-truth pixels at 255.996 m or farther written as 0 (no measurement)",
                     counts.saturated_px)
        if counts.points_too_far:
            log.info("kitti-depth: %d LiDAR points in view 255.998 m or farther left out of velodyne_raw",
                     counts.points_too_far)
        frames = len(jobs)
        return {"frames": frames, "drives": drives, "drives_per_split": per_split,
                "images_linked": counts.images_linked, "images_copied": frames - counts.images_linked,
                "groundtruth_linked": counts.groundtruth_linked,
                "groundtruth_copied": frames - counts.groundtruth_rewritten - counts.groundtruth_linked,
                "groundtruth_rewritten": counts.groundtruth_rewritten,
                "groundtruth_saturated_px": counts.saturated_px, "sparse_px": counts.sparse_px,
                "lidar_points_too_far": counts.points_too_far}


EXPORTER = KittiDepthExporter()
