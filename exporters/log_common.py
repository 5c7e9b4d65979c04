"""What the log formats (MCAP, rosbag2) share: time stamps, frame names, topics, quaternions, point layout.

Frames (tf tree, one per record): ``world`` (SUMO coordinates) -> ``ego`` (ego box centre, x forward,
y left, z up) -> each sensor by name (cameras: OpenCV optical frame; LiDARs and radars: x forward, y left, z up).
Topics are ``/camera/<name>/...``, ``/lidar/<name>/...``, ``/radar/<name>/...``, ``/tf``, ``/scene/objects``,
``/ego/pose``.
When one log holds several records (e.g. morning and night of one run, whose times coincide), every
topic is prefixed with ``/<scenario>_s<seed>_<condition>`` and every frame id with ``<that>/`` so the
records stay apart; a single record uses the plain names.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from exporters.source import ExportSource, FrameItem, RecordSource

# RGBA in [0, 1] per object class (the ``cls`` column), shared by image boxes and 3D cubes.
CLASS_COLORS: dict[str, tuple[float, float, float, float]] = {
    "car": (0.12, 0.56, 1.0, 0.6), "van": (0.0, 0.8, 0.8, 0.6), "truck": (1.0, 0.55, 0.0, 0.6),
    "bus": (0.9, 0.9, 0.0, 0.6), "motorcycle": (0.8, 0.2, 0.8, 0.6), "bicycle": (0.2, 0.8, 0.2, 0.6),
    "pedestrian": (1.0, 0.2, 0.2, 0.6), "stroller": (1.0, 0.6, 0.7, 0.6),
    "rider": (1.0, 0.45, 0.1, 0.6),
}
DEFAULT_COLOR = (0.7, 0.7, 0.7, 0.6)

# Packed point layout (little endian, 24 bytes): name, byte offset, numpy dtype.
POINT_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("x", 0, "<f4"), ("y", 4, "<f4"), ("z", 8, "<f4"), ("intensity", 12, "<f4"), ("ring", 16, "<u2"),
    ("class", 18, "u1"), ("instance", 20, "<i4"),
)
POINT_STRIDE = 24
# Packed radar detection layout (little endian, 48 bytes; every field at its natural alignment, the 3 bytes after
# ``class`` zero): name, byte offset, numpy dtype. Units as the record's columns: m, rad, m/s, dBsm, dB.
RADAR_FIELDS: tuple[tuple[str, int, str], ...] = (
    ("x", 0, "<f4"), ("y", 4, "<f4"), ("z", 8, "<f4"), ("range", 12, "<f4"), ("azimuth", 16, "<f4"),
    ("elevation", 20, "<f4"), ("radial_velocity", 24, "<f4"), ("radial_velocity_comp", 28, "<f4"),
    ("rcs", 32, "<f4"), ("snr", 36, "<f4"), ("instance", 40, "<i4"), ("class", 44, "u1"),
)
RADAR_STRIDE = 48
_RADAR_FLOATS = ("x_m", "y_m", "z_m", "range_m", "azimuth_rad", "elevation_rad", "radial_velocity_mps",
                 "radial_velocity_comp_mps", "rcs_dbsm", "snr_db")
PREFETCH = 2  # frames loaded ahead of the one being written
# The label columns that the log exporters read, in the row dicts of :class:`FrameRows`.
ROW_COLUMNS = ("frame", "sensor", "track_id", "cls", "x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad",
               "sensor_x_m", "sensor_y_m", "sensor_z_m", "sensor_yaw_rad")


def pack_points(points: Mapping[str, np.ndarray] | pd.DataFrame) -> memoryview:
    """The (N * 24) bytes of one sweep (record columns: a DataFrame or one array per column, as
    ``DatasetRecord.point_columns``) in :data:`POINT_FIELDS` layout, padding zeroed so output is deterministic.

    Built as six little-endian 32-bit words per point (x, y, z, intensity; ring | class << 16 with the pad
    byte zero; instance) and returned as a view of that buffer: several times faster than filling a structured
    array and copying it out.
    """
    n = len(points["x_m"])
    words = np.empty((n, POINT_STRIDE // 4), dtype="<u4")
    for j, column in enumerate(("x_m", "y_m", "z_m", "intensity")):
        words[:, j] = np.asarray(points[column], dtype="<f4").view("<u4")
    np.left_shift(np.asarray(points["semantic"], dtype="u1"), 16, out=words[:, 4], dtype="<u4")
    words[:, 4] |= np.asarray(points["ring"], dtype="<u2")
    words[:, 5] = np.asarray(points["instance_id"], dtype="<i4").view("<u4")
    return memoryview(words.reshape(-1).view(np.uint8))


def pack_radar(detections: Mapping[str, np.ndarray] | pd.DataFrame) -> memoryview:
    """The (N * 48) bytes of one radar scan (record columns, ``DatasetRecord.radar_detections``) in
    :data:`RADAR_FIELDS` layout, padding zeroed so output is deterministic."""
    n = len(detections["x_m"])
    words = np.zeros((n, RADAR_STRIDE // 4), dtype="<u4")
    for j, column in enumerate(_RADAR_FLOATS):
        words[:, j] = np.asarray(detections[column], dtype="<f4").view("<u4")
    words[:, 10] = np.asarray(detections["instance_id"], dtype="<i4").view("<u4")
    words[:, 11] = np.asarray(detections["semantic"], dtype="u1")
    return memoryview(words.reshape(-1).view(np.uint8))


def unpack_radar(packed: memoryview) -> np.ndarray:
    """(N,) structured array of :data:`RADAR_FIELDS` from :func:`pack_radar`'s bytes."""
    dtype = np.dtype({"names": [n for n, _, _ in RADAR_FIELDS], "formats": [d for _, _, d in RADAR_FIELDS],
                      "offsets": [o for _, o, _ in RADAR_FIELDS], "itemsize": RADAR_STRIDE})
    return np.frombuffer(packed, dtype=dtype)


def nanoseconds(time_s: float) -> int:
    """Simulation time in integer nanoseconds (log time of every message of the frame)."""
    return round(float(time_s) * 1e9)


def split_ns(time_ns: int) -> tuple[int, int]:
    """(seconds, nanoseconds) of a time in nanoseconds."""
    return time_ns // 1_000_000_000, time_ns % 1_000_000_000


def quat_from_matrix(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """(x, y, z, w) unit quaternion of a (3, 3) rotation, w >= 0."""
    q = Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_quat()
    q = -q if q[3] < 0 else q
    return tuple(float(v) for v in q)


def quat_from_yaw(yaw_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw_rad`` about +z."""
    return 0.0, 0.0, float(np.sin(yaw_rad / 2.0)), float(np.cos(yaw_rad / 2.0))


@dataclass(frozen=True)
class FrameData:
    """The record files of one frame that a log carries: RGB PNG bytes by camera; by LiDAR, the sweep packed
    in :data:`POINT_FIELDS` layout (:func:`pack_points`, bytes-like; ``len // POINT_STRIDE`` points); by radar,
    the scan packed in :data:`RADAR_FIELDS` layout (:func:`pack_radar`)."""

    images: dict[str, bytes]
    points: dict[str, memoryview]
    radars: dict[str, memoryview] = field(default_factory=dict)


def load_frame(item: FrameItem) -> FrameData:
    """Read the :class:`FrameData` of one frame from its record (sweeps packed straight from their columns)."""
    record, info = item.source.record, item.source.info
    return FrameData(images={c.name: record.image_path(c.name, "rgb", item.frame).read_bytes() for c in info.cameras},
                     points={lidar.name: pack_points(record.point_columns(lidar.name, item.frame))
                             for lidar in info.lidars},
                     radars={radar.name: pack_radar(record.radar_detections(radar.name, item.frame))
                             for radar in info.radars})


def frames_with_data(source: ExportSource, ahead: int = PREFETCH) -> Iterator[tuple[FrameItem, FrameData]]:
    """Every frame of ``source`` in export order with its :class:`FrameData`, loaded up to ``ahead`` frames
    early on a worker thread (Parquet decoding, packing and file reads mostly release the GIL, so they overlap
    the caller's message building). A load error is raised when its frame is reached."""
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="frame-loader") as pool:
        loading: deque[tuple[FrameItem, Future[FrameData]]] = deque()
        try:
            for item in source.frames():
                loading.append((item, pool.submit(load_frame, item)))
                if len(loading) > ahead:
                    yield _loaded(loading)
            while loading:
                yield _loaded(loading)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _loaded(loading: deque[tuple[FrameItem, Future[FrameData]]]) -> tuple[FrameItem, FrameData]:
    item, future = loading.popleft()
    return item, future.result()


def prefixed_topic(prefix: str, name: str) -> str:
    """Topic ``name`` of the record with ``prefix`` ("" in a single-record log)."""
    return f"/{prefix}{name}" if prefix else name


def prefixed_frame(prefix: str, name: str) -> str:
    """Frame id ``name`` of the record with ``prefix`` ("" in a single-record log)."""
    return f"{prefix}/{name}" if prefix else name


class Naming:
    """Topic and frame names of one record within a log."""

    def __init__(self, source: RecordSource, export: ExportSource) -> None:
        self.prefix = "" if len(export.records) == 1 else source.stem

    def topic(self, name: str) -> str:
        return prefixed_topic(self.prefix, name)

    def frame(self, name: str) -> str:
        return prefixed_frame(self.prefix, name)


class FrameRows:
    """A record's label rows as plain dicts by frame, classified and boxed once (vectorised), for log exports.

    Each row dict has the label columns :data:`ROW_COLUMNS` plus ``reason`` (:data:`exporters.filters.REASONS`
    for camera rows, ``""`` for others), ``box`` ((4,) float64 x1, y1, x2, y2 of the chosen 2D box, NaN if none)
    and ``box_finite`` (no NaN in ``box``).
    """

    def __init__(self, source: RecordSource, options, summary) -> None:
        from exporters.base import boxes_2d

        labels = source.labels
        camera = (labels["sensor_type"] == "camera").to_numpy()
        reasons = np.full(len(labels), "", dtype=object)
        reasons[camera] = options.filter.classify(labels[camera])
        summary.add(reasons[camera], labels["cls"].to_numpy()[camera])
        boxes = boxes_2d(labels, options.box)
        finite = np.isfinite(boxes).all(axis=1).tolist()
        self._by_frame: dict[int, list[dict]] = {}
        for row, reason, box, box_finite in zip(labels[list(ROW_COLUMNS)].to_dict("records"), reasons, boxes, finite,
                                                strict=True):
            row["reason"], row["box"], row["box_finite"] = reason, box, box_finite
            self._by_frame.setdefault(int(row["frame"]), []).append(row)

    def sensor(self, frame: int, sensor: str) -> list[dict]:
        return [r for r in self._by_frame.get(frame, ()) if r["sensor"] == sensor]

    def objects(self, frame: int) -> list[dict]:
        """One row per track id (the first of its sensors), sorted by track id: the world boxes of the frame."""
        seen: dict[int, dict] = {}
        for row in self._by_frame.get(frame, ()):
            seen.setdefault(int(row["track_id"]), row)
        return [seen[k] for k in sorted(seen)]
