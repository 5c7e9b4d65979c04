"""Sensor rig and environmental condition configuration.

A mount pose is the sensor body's pose in the ego frame (x forward, y left, z up; metres, radians).
A camera's optical frame (OpenCV) is derived from its body frame (see pipeline.core.geometry).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class MountPose(_Model):
    xyz_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)


class CameraConfig(_Model):
    """Pinhole camera; intrinsics from ``hfov_deg`` or an explicit ``K`` (3x3 row-major)."""

    name: str = Field(pattern=r"^[A-Za-z0-9_]+$")
    width_px: int = Field(800, ge=16, le=8192)
    height_px: int = Field(600, ge=16, le=8192)
    hfov_deg: float | None = Field(90.0, gt=1.0, lt=179.0)
    K: tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]] | None = None
    distortion: tuple[float, float, float, float, float] = Field(
        (0.0, 0.0, 0.0, 0.0, 0.0), description="Brown-Conrady k1, k2, p1, p2, k3 (OpenCV order)"
    )
    samples_per_pixel: int = Field(1, ge=1, le=64)
    mount: MountPose

    @model_validator(mode="after")
    def _check_intrinsics(self) -> CameraConfig:
        if (self.K is None) == (self.hfov_deg is None):
            raise ValueError("give exactly one of hfov_deg and K")
        return self


class LidarConfig(_Model):
    """Rotating LiDAR. Intensity I = I0 * exp(-attenuation_per_m * d)."""

    name: str = Field(pattern=r"^[A-Za-z0-9_]+$")
    channels: int = Field(64, ge=1, le=256)
    upper_fov_deg: float = Field(2.0, ge=-90.0, le=90.0)
    lower_fov_deg: float = Field(-24.9, ge=-90.0, le=90.0)
    horizontal_resolution_deg: float = Field(0.2, gt=0.0, le=10.0)
    range_m: float = Field(120.0, gt=0.0)
    rotation_hz: float = Field(10.0, gt=0.0)
    attenuation_per_m: float = Field(0.004, ge=0.0)
    range_noise_std_m: float = Field(0.02, ge=0.0)
    dropout: float = Field(0.0, ge=0.0, lt=1.0)
    mount: MountPose

    @model_validator(mode="after")
    def _check_fov(self) -> LidarConfig:
        if not self.lower_fov_deg < self.upper_fov_deg:
            raise ValueError(f"lower_fov_deg ({self.lower_fov_deg}) must be below upper_fov_deg ({self.upper_fov_deg})")
        return self


class RigConfig(_Model):
    name: str
    cameras: list[CameraConfig] = Field(default_factory=list)
    lidars: list[LidarConfig] = Field(default_factory=list)

    @model_validator(mode="after")
    def _check_names(self) -> RigConfig:
        names = [c.name for c in self.cameras] + [lidar.name for lidar in self.lidars]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"sensor names must be unique; repeated: {', '.join(duplicates)}")
        if not names:
            raise ValueError("a rig needs at least one camera or LiDAR")
        return self


class ConditionConfig(_Model):
    """Lighting and weather. Directions: sun azimuth CCW from east (world +x), elevation above horizon."""

    name: str = Field(pattern=r"^[A-Za-z0-9_-]+$")
    sun_azimuth_deg: float = Field(135.0, ge=-360.0, le=360.0)
    sun_elevation_deg: float = Field(45.0, ge=-90.0, le=90.0)
    sun_color: tuple[float, float, float] = (1.0, 0.98, 0.95)
    sun_intensity: float = Field(1.0, ge=0.0)
    sky_color: tuple[float, float, float] = (0.55, 0.70, 0.90)
    ambient: float = Field(0.35, ge=0.0)
    headlights: bool = False
    street_lamps: bool = False
    fog_visibility_m: float | None = Field(None, gt=0.0, description="Koschmieder meteorological visibility")
    rain: float = Field(0.0, ge=0.0, le=1.0, description="rain intensity: wet road, streaks, visibility")
    noise_std: float = Field(0.01, ge=0.0, description="sensor noise, fraction of full scale")
    vignetting: float = Field(0.2, ge=0.0, le=1.0)
    motion_blur: bool = False
    lens_flare: bool = False
    lidar_range_factor: float = Field(1.0, gt=0.0, le=1.0)
    lidar_intensity_factor: float = Field(1.0, gt=0.0, le=1.0)
