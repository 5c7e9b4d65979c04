"""A radar's part of the record: one Parquet scan per frame (radar frame, RADAR_COLUMNS), its label rows, the
``radar_detections`` counts the other sensors' rows carry, and its record.json entry.

Written only where the rig has radars: a record without them keeps the columns and files it had before radars
existed. Label rows have no 2D fields (null): an actor has one when its box centre is within the radar's range and
azimuth field of view, or when it has at least one detection.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from pipeline.core.classes import RIDER, RIDER_TRACK_OFFSET
from pipeline.core.config import RadarConfig
from pipeline.core.geometry import Transform, wrap_angle
from pipeline.core.record import RADAR_COLUMNS, RadarInfo
from pipeline.core.record_writers.rows import BOX_KEYS, identity_columns, matrix_rows
from pipeline.core.tables import write_sweep

SCAN_SCHEMA = pa.schema([pa.field(c, pa.from_numpy_dtype(np.dtype(t)), nullable=False)
                         for c, t in RADAR_COLUMNS.items()])


def radar_mount(config: RadarConfig) -> Transform:
    """The radar frame -> ego frame (``T_ego_sensor``)."""
    return Transform.from_xyz_rpy(config.mount.xyz_m, config.mount.rpy_rad)


def radar_info(config: RadarConfig) -> RadarInfo:
    """record.json's description of a radar."""
    return RadarInfo(name=config.name, range_min_m=config.range_min_m, range_max_m=config.range_max_m,
                     azimuth_fov_deg=config.azimuth_fov_deg, elevation_fov_deg=config.elevation_fov_deg,
                     range_resolution_m=config.range_resolution_m,
                     azimuth_resolution_deg=config.azimuth_resolution_deg,
                     velocity_resolution_mps=config.velocity_resolution_mps, max_detections=config.max_detections,
                     cycle_hz=config.cycle_hz, T_ego_sensor=matrix_rows(radar_mount(config).matrix))


def write_radar_scan(path: Path, scan) -> None:
    """Write one scan's detections (a :class:`pipeline.sensors.radar.RadarScan`; RADAR_COLUMNS) to ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = {"x_m": scan.points_m[:, 0], "y_m": scan.points_m[:, 1], "z_m": scan.points_m[:, 2],
               "range_m": scan.range_m, "azimuth_rad": scan.azimuth_rad, "elevation_rad": scan.elevation_rad,
               "radial_velocity_mps": scan.radial_velocity_mps,
               "radial_velocity_comp_mps": scan.radial_velocity_comp_mps, "rcs_dbsm": scan.rcs_dbsm,
               "snr_db": scan.snr_db, "instance_id": scan.instance_id, "semantic": scan.semantic}
    arrays = [pa.array(np.ascontiguousarray(columns[c], dtype=t)) for c, t in RADAR_COLUMNS.items()]
    write_sweep(pa.Table.from_arrays(arrays, schema=SCAN_SCHEMA), path)


def radar_label_rows(frame: int, config: RadarConfig, scan, cols: dict[str, np.ndarray], ego_pose: Transform,
                     lidar_points: np.ndarray) -> dict[str, np.ndarray]:
    """Label columns of one radar scan: box centre and yaw about +z in the radar frame, distance, the object's
    LiDAR points (``lidar_points``, per actor, summed over the rig's LiDARs) and its detections; no 2D fields."""
    world_to_radar = (ego_pose @ radar_mount(config)).inverse()
    centre = world_to_radar.apply(np.column_stack([cols["x_m"], cols["y_m"], cols["z_m"]]))
    dist = np.linalg.norm(centre, axis=1)
    in_view = np.abs(np.arctan2(centre[:, 1], centre[:, 0])) <= np.radians(0.5 * config.azimuth_fov_deg)
    keep = np.flatnonzero(((dist <= config.range_max_m) & in_view) | (scan.detections_per_actor > 0))
    heading = world_to_radar.apply_vectors(np.column_stack([np.cos(cols["yaw_rad"]), np.sin(cols["yaw_rad"]),
                                                            np.zeros(len(centre))]))
    out = identity_columns(frame, config.name, "radar", cols, keep)
    null = np.full(len(keep), np.nan)  # NaN becomes null when typed Float64 / Int64
    out.update({"sensor_x_m": centre[keep, 0], "sensor_y_m": centre[keep, 1], "sensor_z_m": centre[keep, 2],
                "sensor_yaw_rad": wrap_angle(np.arctan2(heading[keep, 1], heading[keep, 0])),
                "distance_m": dist[keep], "visible": np.zeros(len(keep), bool), "lidar_points": lidar_points[keep],
                "radar_detections": scan.detections_per_actor[keep]})
    for key in ("visible_px", "unoccluded_px", "occlusion", "truncation") + BOX_KEYS:
        out[key] = null
    for key in BOX_KEYS:
        out[f"amodal_{key}"] = out[f"amodal_clip_{key}"] = out[f"cycle_{key}"] = out[f"cycle_amodal_{key}"] = null
    return out


def with_radar_detections(part: dict[str, np.ndarray], track_ids: np.ndarray, counts: np.ndarray,
                          rider_counts: np.ndarray | None = None) -> None:
    """Add ``radar_detections`` to a camera's or LiDAR's label columns ``part``: the detections of its rows' objects
    (``counts`` per actor of the frame, whose track ids are ``track_ids``) summed over the rig's radars; a rider's
    row (class rider) those on its rider (``rider_counts`` per actor; none: 0)."""
    rider = part["cls"] == RIDER
    track = np.where(rider, part["track_id"] - RIDER_TRACK_OFFSET, part["track_id"])
    order = np.argsort(track_ids, kind="stable")
    which = order[np.searchsorted(track_ids, track, sorter=order)]
    riders = np.zeros_like(counts) if rider_counts is None else rider_counts
    part["radar_detections"] = np.where(rider, riders[which], counts[which])
