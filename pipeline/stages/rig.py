"""Adapter from the validated rig config (pipeline.core.config) to the renderer's sensor models and actor meshes."""

from __future__ import annotations

import zlib
from pathlib import Path

import numpy as np

from pipeline.core.config import RigConfig
from pipeline.core.config.sensors import CameraConfig as CameraSpec
from pipeline.core.config.sensors import LidarConfig as LidarSpec
from pipeline.core.config.sensors import MountPose
from pipeline.core.digests import path_sha256
from pipeline.core.geometry import R_CAMERA_FROM_BODY, Transform
from pipeline.core.record import CameraInfo, LidarInfo
from pipeline.sensors.camera import Camera, CameraConfig
from pipeline.sensors.lidar import Lidar, LidarConfig
from pipeline.world.actors import DEFAULT_MESHES, ActorMeshes, Model


def _mount(pose: MountPose) -> Transform:
    return Transform.from_xyz_rpy(pose.xyz_m, pose.rpy_rad)


def camera_from_spec(spec: CameraSpec) -> Camera:
    intrinsics = None
    if spec.K is not None:
        k = np.asarray(spec.K, dtype=np.float64)
        if k[0, 1] != 0 or k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1:
            raise ValueError(f"camera {spec.name!r}: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
        intrinsics = (k[0, 0], k[1, 1], k[0, 2], k[1, 2])
    return Camera(CameraConfig(
        name=spec.name, width_px=spec.width_px, height_px=spec.height_px,
        hfov_deg=spec.hfov_deg if spec.hfov_deg is not None else 90.0, intrinsics=intrinsics,
        distortion=tuple(spec.distortion), mount=_mount(spec.mount), samples_per_pixel=spec.samples_per_pixel,
        samples_everywhere=spec.samples_everywhere, jitter_seed=zlib.crc32(spec.name.encode()), quality=spec.quality,
    ))


def lidar_from_spec(spec: LidarSpec) -> Lidar:
    return Lidar(LidarConfig(
        name=spec.name, channels=spec.channels, fov_upper_deg=spec.upper_fov_deg, fov_lower_deg=spec.lower_fov_deg,
        horizontal_resolution_deg=spec.horizontal_resolution_deg, range_max_m=spec.range_m,
        rotation_hz=spec.rotation_hz, attenuation_per_m=spec.attenuation_per_m,
        range_noise_std_m=spec.range_noise_std_m, dropout_prob=spec.dropout, mount=_mount(spec.mount),
    ))


def build_sensors(rig: RigConfig) -> tuple[list[Camera], list[Lidar]]:
    return [camera_from_spec(c) for c in rig.cameras], [lidar_from_spec(lidar) for lidar in rig.lidars]


def build_actor_meshes(rig: RigConfig) -> ActorMeshes:
    """The actor models of a rig: its ``actor_meshes`` files (pipeline.world.user_meshes) replacing or joining
    their classes' built-in body families, the built-in library (shared) where it names none. Each model is named
    by its file's stem."""
    if not rig.actor_meshes:
        return DEFAULT_MESHES
    from pipeline.world.user_meshes import load_user_mesh

    replace: dict = {}
    extra: dict = {}
    for i, entry in enumerate(rig.actor_meshes):
        if path_sha256(entry.file) != entry.sha256:  # the config (so the record's meta) must describe these bytes
            raise ValueError(f"{entry.file}: actor_meshes[{i}]: the file changed since the rig was read "
                             f"(sha256 {entry.sha256})")
        mesh = load_user_mesh(entry.file, entry.cls, forward_axis=entry.forward_axis, up_axis=entry.up_axis,
                              material=entry.material, where=f"actor_meshes[{i}]")
        (replace if entry.replace else extra).setdefault(entry.cls, []).append(Model(Path(entry.path).stem, mesh))
    return ActorMeshes(replace, extra)


def _rows(matrix: np.ndarray) -> list[list[float]]:
    return [[round(float(v), 12) for v in row] for row in matrix]


def camera_info(camera: Camera) -> CameraInfo:
    """Record description: K, distortion and T_ego_sensor (optical frame -> ego)."""
    cfg = camera.config
    optical_to_ego = cfg.mount @ Transform(R_CAMERA_FROM_BODY.T, np.zeros(3))
    return CameraInfo(name=cfg.name, width_px=cfg.width_px, height_px=cfg.height_px, K=_rows(camera.K),
                      distortion=[float(d) for d in cfg.distortion], T_ego_sensor=_rows(optical_to_ego.matrix))


def lidar_info(lidar: Lidar) -> LidarInfo:
    cfg = lidar.config
    return LidarInfo(name=cfg.name, channels=cfg.channels, range_m=cfg.range_max_m, rotation_hz=cfg.rotation_hz,
                     T_ego_sensor=_rows(cfg.mount.matrix))
