"""The nuScenes sensor files: LiDAR ``.pcd.bin`` and radar ``.pcd``.

- LiDAR: float32 x, y, z, intensity, ring index per point (5 columns, little endian, no header), in the LiDAR
  frame, as nuScenes' ``LidarPointCloud.from_file``. nuScenes' intensities run 0-255, ours 0-1: written x 255.
  The ring is our beam index (0 = top beam).
- Radar: the PCD v0.7 binary files of nuScenes' Continental ARS 408 (``RadarPointCloud.from_file``): 18 fields
  ``x y z dyn_prop id rcs vx vy vx_comp vy_comp is_quality_valid ambig_state x_rms y_rms invalid_state pdh0 vx_rms
  vy_rms``, radar frame (x forward, y left). vx, vy: the radial velocity (negative = approaching) as a vector along
  the line of sight, its x and y parts; vx_comp, vy_comp: the same of the ego-compensated radial velocity.
  ``dyn_prop`` 0 (moving) where the compensated radial speed exceeds the radar's velocity resolution, else 1
  (stationary); ``id`` the detection's index in the scan; ``rcs`` in dBsm; states the ARS 408 reports that our model
  has no counterpart for are written as a valid, unambiguous cluster (``is_quality_valid`` 1, ``ambig_state`` 3,
  ``invalid_state`` 0) with unknown accuracies (``x_rms`` ... ``vy_rms``, ``pdh0``: 0 = invalid), so the devkit's
  default filters keep every detection.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

LIDAR_INTENSITY_SCALE = 255.0

RADAR_FIELDS = (("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("dyn_prop", "i1"), ("id", "<i2"), ("rcs", "<f4"),
                ("vx", "<f4"), ("vy", "<f4"), ("vx_comp", "<f4"), ("vy_comp", "<f4"), ("is_quality_valid", "i1"),
                ("ambig_state", "i1"), ("x_rms", "i1"), ("y_rms", "i1"), ("invalid_state", "i1"), ("pdh0", "i1"),
                ("vx_rms", "i1"), ("vy_rms", "i1"))
RADAR_DTYPE = np.dtype(list(RADAR_FIELDS))  # packed: no padding, 43 bytes a detection


def lidar_array(points: Mapping[str, np.ndarray]) -> np.ndarray:
    """(N, 5) little-endian float32 x, y, z, intensity x 255, ring of one sweep (``DatasetRecord.point_columns``):
    the ``.pcd.bin`` file's bytes in C order."""
    n = len(points["x_m"])
    out = np.empty((n, 5), dtype="<f4")
    out[:, 0], out[:, 1], out[:, 2] = points["x_m"], points["y_m"], points["z_m"]
    np.multiply(points["intensity"], LIDAR_INTENSITY_SCALE, out=out[:, 3], dtype="<f4", casting="unsafe")
    out[:, 4] = points["ring"]
    return out


def radar_pcd(scan: Mapping[str, np.ndarray], velocity_resolution_mps: float) -> bytes:
    """The PCD file of one radar scan (``DatasetRecord.radar_columns``). A newline follows the binary
    data: the devkit's reader requires bytes after the last field it unpacks."""
    n = len(scan["x_m"])
    xyz = np.stack([np.asarray(scan[c], dtype=np.float64) for c in ("x_m", "y_m", "z_m")], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        direction = xyz[:, :2] / np.asarray(scan["range_m"], dtype=np.float64)[:, None]
    direction = np.nan_to_num(direction)
    v = np.asarray(scan["radial_velocity_mps"], dtype=np.float64)[:, None] * direction
    v_comp_r = np.asarray(scan["radial_velocity_comp_mps"], dtype=np.float64)
    v_comp = v_comp_r[:, None] * direction
    data = np.zeros(n, dtype=RADAR_DTYPE)
    data["x"], data["y"], data["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    data["dyn_prop"] = np.where(np.abs(v_comp_r) > velocity_resolution_mps, 0, 1)
    data["id"] = np.arange(n) % 32768
    data["rcs"] = scan["rcs_dbsm"]
    data["vx"], data["vy"], data["vx_comp"], data["vy_comp"] = v[:, 0], v[:, 1], v_comp[:, 0], v_comp[:, 1]
    data["is_quality_valid"], data["ambig_state"] = 1, 3
    header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
              f"FIELDS {' '.join(name for name, _ in RADAR_FIELDS)}\n"
              f"SIZE {' '.join(str(np.dtype(t).itemsize) for _, t in RADAR_FIELDS)}\n"
              f"TYPE {' '.join('F' if t.endswith('f4') else 'I' for _, t in RADAR_FIELDS)}\n"
              f"COUNT {' '.join('1' for _ in RADAR_FIELDS)}\n"
              f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n")
    return header.encode("ascii") + data.tobytes() + b"\n"
