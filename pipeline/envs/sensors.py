"""``sensors=["camera", "lidar", "radar"]``: the rig's sensors rendered from the live SUMO state, with ground truth.

Each step renders one frame with the render stage's per-frame code (:func:`pipeline.stages.render_frames.
render_frame`): the same static world (built from the run's road geometry and seed), actor models, condition and
random draws (seed, condition, frame, sensor) as ``roadsynth render`` of the same run, so a frame of a recorded
episode (``record=``) renders to the same pixels and labels in the env and in the render stage.

Observations:
    camera: (H, W, 3) uint8 sRGB of the rig's first camera (600 x 800 x 3 for the default rig).
    lidar: (N, 4) float32 x, y, z (metres, LiDAR frame: x forward, y left, z up) and intensity [0, 1] of the rig's
        first LiDAR, one row per beam (N = channels x columns, row = ring x columns + column); zeros where the beam
        has no return. lidar_mask: (N,) int8, 1 where the row holds a return.
    radar: (K, 7) float32 of the rig's first radar's detections (K = its ``max_detections``), columns RADAR_FIELDS:
        x, y, z (metres, radar frame), radial velocity and its ego-compensated value (m/s, negative = approaching),
        RCS (dBsm) and SNR (dB); zeros below the scan's detections. radar_mask: (K,) int8, 1 where a row holds one.
Ground truth (``info["sensors"]``): ``labels``, the frame's label rows with the record's columns and types
(pipeline.core.record.LABEL_COLUMNS: boxes 3D and 2D, visibility, occlusion, truncation, distance, LiDAR points)
as a pyarrow Table (``.to_pandas()``; a Table, not a DataFrame, because Gymnasium compares infos with ``==``);
per camera ``camera_instance_id`` (H, W) int32, ``camera_semantic`` (H, W) uint8, ``camera_depth_m`` (H, W) float32
(0 where no hit); per LiDAR row ``lidar_instance_id`` (N,) int32 and ``lidar_semantic`` (N,) uint8 (0 where no
return); per radar row ``radar_instance_id`` (K,) int32 (0: clutter or no detection). With a radar, the label rows
carry the radars' columns too (``radar_detections``, and the radar's own rows).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
from gymnasium import spaces

from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.core.record import label_columns
from pipeline.sensors.conditions import Condition
from pipeline.stages.render_frames import (
    SignalState,
    Trajectories,
    body_sized_trajectories,
    render_frame,
    rig_actor_meshes,
)
from pipeline.stages.rig import build_sensors
from pipeline.world.scene import StaticScene
from pipeline.world.static import load_static_geometry, load_static_world

SENSOR_NAMES = ("camera", "lidar", "radar")
# Columns of the "radar" observation, one row per detection (radar frame; docs/envs.md).
RADAR_FIELDS = ("x_m", "y_m", "z_m", "radial_velocity_mps", "radial_velocity_comp_mps", "rcs_dbsm", "snr_db")


def check_sensors(sensors) -> tuple[str, ...]:
    """The requested sensors as a tuple, each known and named once."""
    requested = tuple(sensors or ())
    unknown = sorted(set(requested) - set(SENSOR_NAMES))
    if unknown or len(set(requested)) != len(requested):
        raise ValueError(f"sensors must name each of {', '.join(SENSOR_NAMES)} at most once, got {list(requested)}")
    return requested


class LiveSensors:
    """Renders the requested sensors of ``rig`` under ``condition`` (NAMEs or YAML PATHs, as for ``render``)."""

    def __init__(self, sensors: tuple[str, ...], rig: str | Path, condition: str | Path) -> None:
        rig_config, rig_path = load_config(RigConfig, rig, "rigs")
        for name, found in (("camera", rig_config.cameras), ("lidar", rig_config.lidars), ("radar", rig_config.radars)):
            if name in sensors and not found:
                raise ValueError(f"{rig_path}: sensors asks for a {name}, but the rig has none")
        # Only the first camera, LiDAR and radar, and only those asked for, are rendered.
        self.rig = rig_config.model_copy(update={"cameras": rig_config.cameras[:1] if "camera" in sensors else [],
                                                 "lidars": rig_config.lidars[:1] if "lidar" in sensors else [],
                                                 "radars": rig_config.radars[:1] if "radar" in sensors else []})
        self.radars = list(self.rig.radars)
        condition_config, _ = load_config(ConditionConfig, condition, "conditions")
        self.condition = Condition(condition_config)
        self.cameras, self.lidars = build_sensors(self.rig)
        self.meshes = rig_actor_meshes(self.rig, self.condition.umbrellas > 0.0)
        self._world_key: tuple[str, int] | None = None

    def spaces(self) -> dict[str, spaces.Space]:
        out: dict[str, spaces.Space] = {}
        if self.cameras:
            cfg = self.cameras[0].config
            out["camera"] = spaces.Box(0, 255, (cfg.height_px, cfg.width_px, 3), np.uint8)
        if self.lidars:
            n = self.beams
            reach = np.float32(self.lidars[0].config.range_m * 1.5)  # range noise never gets near this
            low = np.array([-reach, -reach, -reach, 0.0], np.float32)
            out["lidar"] = spaces.Box(np.tile(low, (n, 1)), np.tile(np.array([reach, reach, reach, 1.0], np.float32),
                                                                   (n, 1)), dtype=np.float32)
            out["lidar_mask"] = spaces.MultiBinary(n)
        if self.radars:
            k = self.radars[0].max_detections
            out["radar"] = spaces.Box(-np.inf, np.inf, (k, len(RADAR_FIELDS)), np.float32)
            out["radar_mask"] = spaces.MultiBinary(k)
        return out

    @property
    def beams(self) -> int:
        lidar = self.lidars[0]
        return lidar.config.channels * lidar.columns

    def start(self, roads_dir: Path, seed: int) -> None:
        """Build the static world of the run (``roads_dir``: its road geometry tables; ``seed``: the run seed)."""
        key = (str(roads_dir), seed)
        if key != self._world_key:
            self.world = load_static_world(roads_dir, seed=seed)
            self.static = StaticScene(self.world.meshes, load_static_geometry(self.world, roads_dir, seed=seed))
            self.signals = SignalState(self.world, self.static, pd.DataFrame(columns=["frame", "tls_id", "state"]))
            self._world_key = key
        self.seed = seed

    def render(self, trajectories: pd.DataFrame, frame: int,
               tls_states: dict[str, str]) -> tuple[dict[str, np.ndarray], dict[str, object]]:
        """The observation entries and ground truth of ``frame`` from its trajectory rows (simulate's columns)."""
        ego, others = Trajectories(body_sized_trajectories(trajectories, self.meshes, self.seed,
                                                           self.condition.umbrellas)).frame(frame)
        self.signals.apply_states(tls_states)
        out = render_frame(self.world, self.static, self.cameras, self.lidars, self.condition, self.meshes, self.seed,
                           frame, ego, others, radars=self.radars)
        columns = label_columns(radars=bool(self.radars))
        labels = pd.DataFrame({k: np.concatenate([part[k] for part in out.labels]) for k in columns})
        truth: dict[str, object] = {"labels": pa.Table.from_pandas(labels.astype(columns), preserve_index=False)}
        obs: dict[str, np.ndarray] = {}
        if out.cameras:
            cam = out.cameras[0]
            obs["camera"] = cam.rgb
            truth.update(camera_instance_id=cam.instance_id, camera_semantic=cam.semantic, camera_depth_m=cam.depth_m)
        if out.scans:
            scan, k = out.scans[0], self.radars[0].max_detections
            rows = np.column_stack([scan.points_m, scan.radial_velocity_mps, scan.radial_velocity_comp_mps,
                                    scan.rcs_dbsm, scan.snr_db]).astype(np.float32)
            obs["radar"] = np.zeros((k, len(RADAR_FIELDS)), np.float32)
            obs["radar"][:len(rows)] = rows
            obs["radar_mask"] = (np.arange(k) < len(rows)).astype(np.int8)
            ids = np.zeros(k, np.int32)
            ids[:len(rows)] = scan.instance_id
            truth.update(radar_instance_id=ids)
        if out.sweeps:
            obs["lidar"], obs["lidar_mask"], ids, semantic = self._beam_rows(out.sweeps[0])
            truth.update(lidar_instance_id=ids, lidar_semantic=semantic)
        return obs, truth

    def _beam_rows(self, sweep) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n, columns = self.beams, self.lidars[0].columns
        row = sweep.ring.astype(np.int64) * columns + sweep.column.astype(np.int64)
        points = np.zeros((n, 4), np.float32)
        points[row, :3] = sweep.points_m
        points[row, 3] = sweep.intensity
        mask = np.zeros(n, np.int8)
        mask[row] = 1
        ids = np.zeros(n, np.int32)
        ids[row] = sweep.instance_id
        semantic = np.zeros(n, np.uint8)
        semantic[row] = sweep.semantic
        return points, mask, ids, semantic
