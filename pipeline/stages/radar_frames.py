"""The render stage's radar side: the rig's radar scans of a frame, written with their label rows.

Kept apart from :mod:`pipeline.stages.render_frames`, which calls it only where the rig has radars: a rig without
radars renders exactly as before (no radar folder, no ``radar_detections`` label column, the same draws). What a
scan writes into the record is :mod:`pipeline.core.record_writers.radar`.

A radar scans once per record frame (its ``cycle_hz`` is recorded, not simulated). Velocities come from the
simulated run: each vehicle's speed along its heading (:func:`pipeline.sensors.radar.heading_velocity`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from pipeline.core.config import ConditionConfig, RadarConfig
from pipeline.core.geometry import Transform
from pipeline.core.record import radar_path
from pipeline.core.record_writers.radar import radar_label_rows, with_radar_detections, write_radar_scan
from pipeline.core.record_writers.rows import rider_counts
from pipeline.sensors.radar import (
    RadarScan,
    actors_in_radar_reach,
    heading_velocity,
    render_radar,
    weather_attenuation_db_per_km,
)
from pipeline.world.actors import Actors
from pipeline.world.scene import FrameScene

RADAR_RNG_TAG = 2000  # radar k of the rig draws from frame_rng(seed, condition, frame, RADAR_RNG_TAG + k)


def radar_reach(radars: list[RadarConfig], actors: Actors, ego_pose: Transform) -> np.ndarray:
    """(A,) bool actors a radar may see, to OR into the frame scene's ``active`` mask."""
    return actors_in_radar_reach(actors, ego_pose, radars)


def render_scans(radars: list[RadarConfig], scene: FrameScene, ego_pose: Transform, ego: dict,
                 others: dict[str, np.ndarray], condition: ConditionConfig,
                 rng: Callable[[int], np.random.Generator]) -> list[RadarScan]:
    """One scan per radar of the frame; ``ego`` the ego's trajectory values, ``others`` the actors' columns (the
    scene's actor order), ``rng(tag)`` the generator of a sensor tag (radar k: RADAR_RNG_TAG + k)."""
    ego_velocity = heading_velocity(np.array([ego["speed_mps"]]), np.array([ego["yaw_rad"]]))[0]
    actor_velocity = heading_velocity(others["speed_mps"], others["yaw_rad"])
    attenuation = weather_attenuation_db_per_km(condition)
    return [render_radar(scene, config, ego_pose, rng(RADAR_RNG_TAG + k), ego_velocity_mps=ego_velocity,
                         actor_velocity_mps=actor_velocity, attenuation_db_per_km=attenuation)
            for k, config in enumerate(radars)]


def scan_rows(frame: int, radars: list[RadarConfig], scans: list[RadarScan], others: dict[str, np.ndarray],
              ego_pose: Transform, lidar_points: np.ndarray, labels: list[dict[str, np.ndarray]]) -> None:
    """Give the frame's camera and LiDAR rows (``labels``) their objects' detections summed over the radars, then
    add each radar's rows to ``labels``."""
    counts = np.sum([scan.detections_per_actor for scan in scans], axis=0)
    riders = np.sum([rider_counts(scan.instance_id, scan.semantic, others["track_id"]) for scan in scans], axis=0)
    for part in labels:
        with_radar_detections(part, others["track_id"], counts, riders)
    for config, scan in zip(radars, scans, strict=True):
        labels.append(radar_label_rows(frame, config, scan, others, ego_pose, lidar_points))


def write_scans(root: Path, frame: int, radars: list[RadarConfig], scans: list[RadarScan]) -> None:
    """Write the frame's scans into the record at ``root``."""
    for config, scan in zip(radars, scans, strict=True):
        write_radar_scan(radar_path(root, config.name, frame), scan)
