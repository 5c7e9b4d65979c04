"""A camera's part of the record: its four PNG images per frame, its label rows and its record.json entry.

Images (docs/dataset.md): rgb (8-bit sRGB), instance (uint16 track id, 0 = no object), semantic (uint8
SemanticClass) and depth (uint16 z-depth x DEPTH_SCALE, 0 = no hit). Label rows: one per actor the camera's ground
truth describes, with its sensor-frame box, tight and amodal 2D boxes (a ridden cycle's also without its rider), pixel
counts, occlusion and truncation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.core.geometry import R_CAMERA_FROM_BODY, Transform, wrap_angle
from pipeline.core.jit import as_input, kernel
from pipeline.core.png import write_png
from pipeline.core.record import DEPTH_SCALE, CameraInfo, camera_path
from pipeline.core.record_writers.rows import BOX_KEYS, as_riders, identity_columns, matrix_rows

# One fixed PNG row filter per image kind (libpng's adaptive choice per row costs more than it saves): Up for the
# noisy RGB image, Sub for depth (smooth along rows), none for the label images (runs of one value).
PNG_FILTER = {"rgb": "up", "instance": "none", "semantic": "none", "depth": "sub"}
# zlib's strategy per image (pipeline.core.png.STRATEGIES): the camera's noisy image coded by byte frequencies alone.
PNG_STRATEGY = {"rgb": "huffman", "instance": "default", "semantic": "default", "depth": "default"}


def camera_info(camera) -> CameraInfo:
    """Record description of a camera (:class:`pipeline.sensors.camera.Camera`): K, distortion and T_ego_sensor
    (optical frame -> ego)."""
    cfg = camera.config
    optical_to_ego = camera.mount @ Transform(R_CAMERA_FROM_BODY.T, np.zeros(3))
    return CameraInfo(name=cfg.name, width_px=cfg.width_px, height_px=cfg.height_px, K=matrix_rows(camera.K),
                      distortion=[float(d) for d in cfg.distortion], T_ego_sensor=matrix_rows(optical_to_ego.matrix))


def camera_label_rows(frame: int, name: str, cam, cols: dict[str, np.ndarray], lidar_points: np.ndarray,
                      rider_points: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Label columns of one camera frame (``cam``: a :class:`pipeline.sensors.render.CameraFrame`); ``lidar_points``
    (K,) counts each actor's points over the rig's LiDARs, ``rider_points`` (K,) those on its rider (none: 0). A
    rider's row (the labels' ``rider``) is :func:`as_riders`'."""
    lab = cam.labels
    out = identity_columns(frame, name, "camera", cols, lab.actor_index)
    rider_points = np.zeros_like(lidar_points) if rider_points is None else rider_points
    as_riders(out, lab.rider, cam.cam_to_world.apply(lab.center_cam[lab.rider]), lab.size[lab.rider])
    heading = lab.rotation_cam[:, :, 0]  # the box's forward axis in the optical frame
    tight = np.where(lab.visible[:, None], lab.box_tight, np.nan)  # NaN becomes null when typed Float64
    out.update({
        "sensor_x_m": lab.center_cam[:, 0], "sensor_y_m": lab.center_cam[:, 1], "sensor_z_m": lab.center_cam[:, 2],
        # KITTI rotation_y: the heading in the optical frame is (cos ry, 0, -sin ry).
        "sensor_yaw_rad": wrap_angle(np.arctan2(-heading[:, 2], heading[:, 0])),
        "distance_m": lab.distance_m.astype(np.float64), "visible": lab.visible,
        "visible_px": lab.visible_px, "unoccluded_px": lab.unoccluded_px,
        "occlusion": lab.occlusion.astype(np.float64), "truncation": lab.truncation.astype(np.float64),
        "lidar_points": np.where(lab.rider, rider_points[lab.actor_index], lidar_points[lab.actor_index]),
    })
    for j, key in enumerate(BOX_KEYS):
        out[key], out[f"amodal_{key}"], out[f"amodal_clip_{key}"] = (
            tight[:, j], lab.box_amodal[:, j], lab.box_amodal_clipped[:, j])
        out[f"cycle_{key}"], out[f"cycle_amodal_{key}"] = lab.box_cycle[:, j], lab.box_cycle_amodal[:, j]
    return out


def write_camera_frame(root: Path, name: str, frame: int, cam) -> None:
    """Write one camera frame's four images under the record folder ``root``."""
    if cam.instance_id.max(initial=0) > np.iinfo(np.uint16).max:
        raise ValueError(f"track id {cam.instance_id.max()} does not fit the uint16 instance image")
    depth = depth_png(as_input(cam.depth_m, np.float32), as_input(cam.depth_valid, bool), np.float32(DEPTH_SCALE))
    images = {"rgb": cam.rgb, "instance": cam.instance_id.astype(np.uint16),
              "semantic": cam.semantic.astype(np.uint8), "depth": depth}
    for kind, image in images.items():
        path = camera_path(root, name, kind, frame)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_png(path, image, PNG_FILTER[kind], PNG_STRATEGY[kind])


@kernel("uint16[:, ::1](float32[:, ::1], bool_[:, ::1], float32)")
def depth_png(depth_m, valid, scale):
    """The depth PNG's (H, W) uint16 values: round(depth * scale) clipped to [1, 65535] where valid, 0 elsewhere."""
    out = np.zeros(depth_m.shape, np.uint16)
    for y in range(depth_m.shape[0]):
        for x in range(depth_m.shape[1]):
            if valid[y, x]:
                out[y, x] = min(max(np.rint(depth_m[y, x] * scale), np.float32(1)), np.float32(65535))
    return out
