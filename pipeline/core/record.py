"""The canonical dataset record: one folder per (simulated run, condition), written by ``render``.

Exporters and the renderer meet only here. Layout (schema version :data:`SCHEMA_VERSION`;
field-by-field description in docs/dataset.md)::

    record.json                      RecordInfo: schema version, scenario, seed, condition, sensors
    frames.parquet                   one row per frame: time and ego pose in the world
    labels.parquet                   one row per (frame, sensor, object)
    cameras/<cam>/rgb/NNNNNN.png     8-bit sRGB
    cameras/<cam>/instance/NNNNNN.png  uint16 track id per pixel, 0 = no object
    cameras/<cam>/semantic/NNNNNN.png  uint8 SemanticClass per pixel
    cameras/<cam>/depth/NNNNNN.png   uint16, z-depth in metres x 256 (KITTI depth convention), 0 = no hit
    lidars/<lidar>/NNNNNN.parquet    one row per point, LiDAR frame
    radars/<radar>/NNNNNN.parquet    one row per detection, radar frame (only where the rig has radars)
    meta.json                        versions, resolved config, its hash, seed, command line

Frames are numbered as in the simulation's ``trajectories.parquet``. Extrinsics are stored as
``T_ego_sensor``: the 4x4 transform taking points from the sensor frame (cameras: OpenCV optical frame;
LiDARs and radars: x fwd, y left, z up) to the ego frame (x fwd, y left, z up, origin at the ego box centre).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from pipeline.core.png import check_png
from pipeline.core.tables import damage_message, open_parquet, read_parquet, require_finite

SCHEMA_VERSION = 3  # 2: labels name each actor's body (model, person); 3: a ridden cycle's boxes without its rider
RECORD_FILE = "record.json"
DEPTH_SCALE = 256.0  # depth PNG value = metres * 256

FRAME_COLUMNS = {
    "frame": "int32", "time_s": "float64", "ego_track_id": "int32",
    "ego_x_m": "float64", "ego_y_m": "float64", "ego_z_m": "float64", "ego_yaw_rad": "float64",
    "ego_speed_mps": "float64",
}
LABEL_COLUMNS = {
    # identity
    "frame": "int32", "sensor": "str", "sensor_type": "str", "track_id": "int32", "cls": "str",
    "category_id": "int32", "model": "str", "person": "str",
    # 3D box in the world (centre, size, yaw about +z)
    "x_m": "float64", "y_m": "float64", "z_m": "float64", "length_m": "float64", "width_m": "float64",
    "height_m": "float64", "yaw_rad": "float64",
    # 3D box centre in the sensor frame; cameras: rotation_y about the optical +y (KITTI ry),
    # LiDARs: yaw about +z
    "sensor_x_m": "float64", "sensor_y_m": "float64", "sensor_z_m": "float64", "sensor_yaw_rad": "float64",
    "distance_m": "float64",
    # 2D (cameras; null for LiDAR rows). Tight box valid only where visible.
    "visible": "bool", "x1": "Float64", "y1": "Float64", "x2": "Float64", "y2": "Float64",
    "amodal_x1": "Float64", "amodal_y1": "Float64", "amodal_x2": "Float64", "amodal_y2": "Float64",
    "amodal_clip_x1": "Float64", "amodal_clip_y1": "Float64", "amodal_clip_x2": "Float64",
    "amodal_clip_y2": "Float64",
    # a ridden bicycle's or motorcycle's tight and amodal (unclipped) boxes without its rider (null on other rows)
    "cycle_x1": "Float64", "cycle_y1": "Float64", "cycle_x2": "Float64", "cycle_y2": "Float64",
    "cycle_amodal_x1": "Float64", "cycle_amodal_y1": "Float64", "cycle_amodal_x2": "Float64",
    "cycle_amodal_y2": "Float64",
    "visible_px": "Int64", "unoccluded_px": "Int64", "occlusion": "Float64", "truncation": "Float64",
    # LiDAR points carrying this object's id (cameras: summed over the rig's LiDARs)
    "lidar_points": "int32",
}
# Added to LABEL_COLUMNS where the rig has radars (a record without radars keeps the columns above, byte for byte).
RADAR_LABEL_COLUMNS = {
    # radar detections carrying this object's id (cameras and LiDARs: summed over the rig's radars)
    "radar_detections": "int32",
}
RADAR_COLUMNS = {
    "x_m": "float32", "y_m": "float32", "z_m": "float32", "range_m": "float32", "azimuth_rad": "float32",
    "elevation_rad": "float32", "radial_velocity_mps": "float32", "radial_velocity_comp_mps": "float32",
    "rcs_dbsm": "float32", "snr_db": "float32", "instance_id": "int32", "semantic": "uint8",
}
POINT_COLUMNS = {
    "x_m": "float32", "y_m": "float32", "z_m": "float32", "intensity": "float32", "ring": "uint16",
    "instance_id": "int32", "semantic": "uint8",
}


class RecordError(ValueError):
    """A record is missing, incomplete or of another schema version; names the path and the problem."""


class _SensorInfo:
    """What every sensor's record.json entry has: ``T_ego_sensor``, the 4x4 sensor frame -> ego frame."""

    T_ego_sensor: list[list[float]]

    @property
    def T_array(self) -> np.ndarray:
        return np.asarray(self.T_ego_sensor, dtype=np.float64)


@dataclass(frozen=True)
class CameraInfo(_SensorInfo):
    name: str
    width_px: int
    height_px: int
    K: list[list[float]]  # 3x3 intrinsics, pixels
    distortion: list[float]  # k1, k2, p1, p2, k3 (OpenCV order)
    T_ego_sensor: list[list[float]]  # 4x4, optical frame -> ego frame

    @property
    def K_array(self) -> np.ndarray:
        return np.asarray(self.K, dtype=np.float64)


@dataclass(frozen=True)
class LidarInfo(_SensorInfo):
    name: str
    channels: int
    range_m: float
    rotation_hz: float
    T_ego_sensor: list[list[float]]  # 4x4, LiDAR frame -> ego frame


@dataclass(frozen=True)
class RadarInfo(_SensorInfo):
    name: str
    range_min_m: float
    range_max_m: float
    azimuth_fov_deg: float  # full field of view, symmetric about the radar's x axis
    elevation_fov_deg: float
    range_resolution_m: float
    azimuth_resolution_deg: float
    velocity_resolution_mps: float
    max_detections: int
    cycle_hz: float
    T_ego_sensor: list[list[float]]  # 4x4, radar frame -> ego frame


def label_columns(radars: bool) -> dict[str, str]:
    """The columns of labels.parquet: :data:`LABEL_COLUMNS`, and :data:`RADAR_LABEL_COLUMNS` when the rig has
    radars."""
    return {**LABEL_COLUMNS, **RADAR_LABEL_COLUMNS} if radars else dict(LABEL_COLUMNS)


@dataclass(frozen=True)
class RecordInfo:
    scenario: str
    seed: int
    condition: str
    rig: str
    frame_rate_hz: float
    cameras: list[CameraInfo] = field(default_factory=list)
    lidars: list[LidarInfo] = field(default_factory=list)
    radars: list[RadarInfo] = field(default_factory=list)
    schema_version: int = SCHEMA_VERSION

    def to_json(self) -> str:
        data = asdict(self)
        if not self.radars:  # a record without radars reads as it did before radars existed
            del data["radars"]
        return json.dumps(data, sort_keys=True, indent=2, allow_nan=False) + "\n"

    @classmethod
    def from_dict(cls, data: dict, source: str) -> RecordInfo:
        try:
            cams = [CameraInfo(**c) for c in data.get("cameras", [])]
            lidars = [LidarInfo(**lidar) for lidar in data.get("lidars", [])]
            radars = [RadarInfo(**radar) for radar in data.get("radars", [])]
            rest = {k: v for k, v in data.items() if k not in ("cameras", "lidars", "radars")}
            return cls(cameras=cams, lidars=lidars, radars=radars, **rest)
        except TypeError as exc:
            raise RecordError(f"{source}: malformed record description ({exc})") from None

    def camera(self, name: str) -> CameraInfo:
        for cam in self.cameras:
            if cam.name == name:
                return cam
        raise KeyError(f"no camera {name!r}; cameras: {', '.join(c.name for c in self.cameras) or '(none)'}")


def frame_stem(frame: int) -> str:
    return f"{frame:06d}"


def camera_path(root: Path, camera: str, channel: str, frame: int) -> Path:
    """Path of a camera image; ``channel`` is rgb, instance, semantic or depth."""
    if channel not in ("rgb", "instance", "semantic", "depth"):
        raise KeyError(f"unknown camera channel {channel!r}; known: rgb, instance, semantic, depth")
    return root / "cameras" / camera / channel / f"{frame_stem(frame)}.png"


def lidar_path(root: Path, lidar: str, frame: int) -> Path:
    return root / "lidars" / lidar / f"{frame_stem(frame)}.parquet"


def radar_path(root: Path, radar: str, frame: int) -> Path:
    return root / "radars" / radar / f"{frame_stem(frame)}.parquet"


def require_columns(present, columns: dict[str, str], what: str) -> None:
    """Fail naming every one of ``columns`` that is not in ``present``."""
    missing = [c for c in columns if c not in present]
    if missing:
        raise RecordError(f"{what}: missing columns {', '.join(missing)}")


def conform(frame: pd.DataFrame, columns: dict[str, str], what: str) -> pd.DataFrame:
    """Select and type ``columns`` (in order); fail naming any that are missing."""
    require_columns(frame.columns, columns, what)
    return frame[list(columns)].astype(columns)


class DatasetRecord:
    """Read access to one canonical record (validated on open)."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        info_path = self.root / RECORD_FILE
        if not info_path.is_file():
            raise RecordError(f"{self.root}: not a roadsynth dataset record (no {RECORD_FILE}); "
                              "make one with `roadsynth render`")
        try:
            data = json.loads(info_path.read_text())
        except json.JSONDecodeError as exc:
            raise RecordError(f"{info_path}: not valid JSON ({exc})") from None
        version = data.get("schema_version")
        if version != SCHEMA_VERSION:
            raise RecordError(f"{info_path}: schema_version {version!r} is not supported "
                              f"(this roadsynth reads version {SCHEMA_VERSION}); re-render the record")
        self.info = RecordInfo.from_dict(data, str(info_path))
        for name in ("frames.parquet", "labels.parquet"):
            if not (self.root / name).is_file():
                raise RecordError(f"{self.root}: incomplete record, {name} is missing")

    @property
    def frames(self) -> pd.DataFrame:
        path = self.root / "frames.parquet"
        frames = conform(read_parquet(path), FRAME_COLUMNS, str(path))
        require_finite(frames, str(path), keys=("frame",))  # times and ego poses become every export's
        return frames

    @property
    def labels(self) -> pd.DataFrame:
        """One row per (frame, sensor, object); with ``radar_detections`` where the record has radars."""
        return conform(read_parquet(self.root / "labels.parquet"), label_columns(bool(self.info.radars)),
                       str(self.root / "labels.parquet"))

    def image_path(self, camera: str, channel: str, frame: int) -> Path:
        """The path of an image, checked whole (every PNG chunk's CRC) and of the camera's size: exporters link or
        copy the file without decoding it."""
        path = camera_path(self.root, camera, channel, frame)
        if not path.is_file():
            raise RecordError(f"{path}: missing from the record")
        cam = self.info.camera(camera)
        try:
            check_png(path.read_bytes(), str(path), width=cam.width_px, height=cam.height_px)
        except ValueError as exc:
            raise RecordError(f"{exc} (frame {frame}, camera {camera}, {channel} image)") from None
        return path

    def _decoded(self, camera: str, channel: str, frame: int, flags: int) -> np.ndarray:
        import cv2

        path = self.image_path(camera, channel, frame)
        image = cv2.imread(str(path), flags)
        if image is None:
            raise RecordError(f"{path}: the image does not decode (frame {frame}, camera {camera}, {channel} image)")
        return image

    def rgb(self, camera: str, frame: int) -> np.ndarray:
        """(H, W, 3) uint8 RGB."""
        import cv2

        return self._decoded(camera, "rgb", frame, cv2.IMREAD_COLOR)[:, :, ::-1]

    def instance(self, camera: str, frame: int) -> np.ndarray:
        """(H, W) int32 track id per pixel, 0 where no object."""
        import cv2

        return self._decoded(camera, "instance", frame, cv2.IMREAD_UNCHANGED).astype(np.int32)

    def semantic(self, camera: str, frame: int) -> np.ndarray:
        """(H, W) uint8 SemanticClass."""
        import cv2

        return self._decoded(camera, "semantic", frame, cv2.IMREAD_UNCHANGED)

    def depth_m(self, camera: str, frame: int) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) float32 z-depth in metres and (H, W) bool validity mask: no hit (0) and the saturated value
        (65535: 255.996 m or farther, not a measurement) are invalid."""
        import cv2

        raw = self._decoded(camera, "depth", frame, cv2.IMREAD_UNCHANGED)
        return raw.astype(np.float32) / DEPTH_SCALE, (raw > 0) & (raw < np.iinfo(np.uint16).max)

    def radar_detections(self, radar: str, frame: int) -> pd.DataFrame:
        """One radar scan: :data:`RADAR_COLUMNS` (radar frame), one row per detection."""
        if radar not in [r.name for r in self.info.radars]:
            raise KeyError(f"no radar {radar!r}; radars: {', '.join(r.name for r in self.info.radars) or '(none)'}")
        path = radar_path(self.root, radar, frame)
        if not path.is_file():
            raise RecordError(f"{path}: missing from the record")
        table = conform(read_parquet(path), RADAR_COLUMNS, str(path))
        require_finite(table, f"{path} (frame {frame}, radar {radar})", keys=())
        return table

    def radar_columns(self, radar: str, frame: int) -> dict[str, np.ndarray]:
        """:meth:`radar_detections` as one read-only numpy array per column (:data:`RADAR_COLUMNS` dtypes), without
        building a DataFrame: for readers that only pack or copy the columns (the nuScenes export)."""
        if radar not in [r.name for r in self.info.radars]:
            raise KeyError(f"no radar {radar!r}; radars: {', '.join(r.name for r in self.info.radars) or '(none)'}")
        return _read_columns(radar_path(self.root, radar, frame), RADAR_COLUMNS, f"frame {frame}, radar {radar}",
                             "radar scan", "detection(s)")

    def points(self, lidar: str, frame: int) -> pd.DataFrame:
        """One LiDAR sweep: x_m, y_m, z_m (LiDAR frame), intensity, ring, instance_id, semantic."""
        return pd.DataFrame(self.point_columns(lidar, frame))

    def point_columns(self, lidar: str, frame: int) -> dict[str, np.ndarray]:
        """:meth:`points` as one read-only numpy array per column (schema dtypes; views of the decoded Arrow
        buffers where no cast is needed), without building a DataFrame: for readers that only pack or copy the
        columns (the log exporters)."""
        return _read_columns(lidar_path(self.root, lidar, frame), POINT_COLUMNS, f"frame {frame}, LiDAR {lidar}",
                             "LiDAR sweep", "point(s)")


def _read_columns(path: Path, schema: dict[str, str], where: str, what: str, rows: str) -> dict[str, np.ndarray]:
    """The ``schema`` columns of the Parquet file ``path`` as numpy arrays; ``where``, ``what`` and ``rows`` name the
    frame and sensor, the kind of file and its rows in errors."""
    if not path.is_file():
        raise RecordError(f"{path}: missing from the record")
    # Straight from Arrow to numpy (no pandas conversion of the table); cast only what differs. A plain
    # ParquetFile read skips read_table's dataset discovery (a large share of a sweep's read).
    try:
        with open_parquet(path) as parquet:
            table = parquet.read()
    except (pa.ArrowException, OSError) as exc:
        raise RecordError(f"{damage_message(path, exc, what)} ({where})") from None
    require_columns(table.column_names, schema, str(path))
    columns = {c: np.asarray(table.column(c).to_numpy(), dtype=dtype) for c, dtype in schema.items()}
    for name, values in columns.items():
        if values.dtype.kind == "f" and not np.isfinite(values).all():
            raise RecordError(f"{path}: field {name} is not finite in {int((~np.isfinite(values)).sum())} "
                              f"{rows} ({where})")
    return columns
