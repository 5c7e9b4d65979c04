"""A LiDAR's part of the record: one Parquet sweep per frame (LiDAR frame, POINT_COLUMNS), its label rows and its
record.json entry.

Label rows have no 2D fields (null): an actor has one when its box centre is within the range the sweep was
rendered with, or when it owns at least one point of the sweep.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from pipeline.core.geometry import Transform, wrap_angle
from pipeline.core.record import POINT_COLUMNS, LidarInfo
from pipeline.core.record_writers.rows import BOX_KEYS, actor_boxes, identity_columns, matrix_rows
from pipeline.core.tables import write_sweep

# A sweep's columns are never null: declared so (Parquet's "required"), they are written without definition levels,
# a large part of a sweep's write time (see write_sweep, docs/performance.md).
SWEEP_SCHEMA = pa.schema([pa.field(c, pa.from_numpy_dtype(np.dtype(t)), nullable=False)
                          for c, t in POINT_COLUMNS.items()])


def lidar_info(lidar) -> LidarInfo:
    """Record description of a LiDAR (:class:`pipeline.sensors.lidar.Lidar`)."""
    cfg = lidar.config
    return LidarInfo(name=cfg.name, channels=cfg.channels, range_m=cfg.range_m, rotation_hz=cfg.rotation_hz,
                     T_ego_sensor=matrix_rows(lidar.mount.matrix))


def lidar_label_rows(frame: int, name: str, mount: Transform, sweep, cols: dict[str, np.ndarray],
                     ego_pose: Transform) -> dict[str, np.ndarray]:
    """Label columns of one LiDAR sweep (a :class:`pipeline.sensors.lidar.LidarSweep` of the LiDAR mounted at
    ``mount`` on the ego at ``ego_pose``); no 2D fields (null). An actor has a row when its box centre is within the
    range the sweep was rendered with (``sweep.range_max_m``: the rig's range times the condition's factor), or
    when it owns at least one point of the sweep (its centre may lie beyond the range)."""
    world_to_lidar = (ego_pose @ mount).inverse()
    boxes = actor_boxes(cols)
    local = boxes.transformed(world_to_lidar) if abs(world_to_lidar.rotation[2, 2] - 1) < 1e-9 else None
    centre = world_to_lidar.apply(boxes.center)
    dist = np.linalg.norm(centre, axis=1)
    keep = np.flatnonzero((dist <= sweep.range_max_m) | (sweep.points_per_actor > 0))
    heading = world_to_lidar.apply_vectors(np.column_stack([np.cos(boxes.yaw_rad), np.sin(boxes.yaw_rad),
                                                            np.zeros(len(boxes))]))
    yaw = local.yaw_rad if local is not None else np.arctan2(heading[:, 1], heading[:, 0])
    out = identity_columns(frame, name, "lidar", cols, keep)
    null = np.full(len(keep), np.nan)  # NaN becomes null when typed Float64 / Int64
    out.update({
        "sensor_x_m": centre[keep, 0], "sensor_y_m": centre[keep, 1], "sensor_z_m": centre[keep, 2],
        "sensor_yaw_rad": wrap_angle(yaw[keep]), "distance_m": dist[keep], "visible": np.zeros(len(keep), bool),
        "lidar_points": sweep.points_per_actor[keep],
    })
    for key in ("visible_px", "unoccluded_px", "occlusion", "truncation") + BOX_KEYS:
        out[key] = null
    for key in BOX_KEYS:
        out[f"amodal_{key}"] = out[f"amodal_clip_{key}"] = out[f"cycle_{key}"] = out[f"cycle_amodal_{key}"] = null
    return out


def write_lidar_sweep(path: Path, sweep) -> None:
    """Write one sweep's points (POINT_COLUMNS) to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = {
        "x_m": sweep.points_m[:, 0], "y_m": sweep.points_m[:, 1], "z_m": sweep.points_m[:, 2],
        "intensity": sweep.intensity, "ring": sweep.ring, "instance_id": sweep.instance_id, "semantic": sweep.semantic,
    }
    # Straight to Arrow (no DataFrame): half the time of a DataFrame.
    arrays = [pa.array(np.ascontiguousarray(columns[c], dtype=t)) for c, t in POINT_COLUMNS.items()]
    write_sweep(pa.Table.from_arrays(arrays, schema=SWEEP_SCHEMA), path)
