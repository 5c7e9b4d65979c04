"""Environmental conditions: lighting, fog, sensor noise and LiDAR degradation, by name.

A :class:`Condition` bundles what changes between a morning and a foggy night: the :class:`Lighting`
(sun, sky, ambient, vehicle and street lights), Koschmieder fog applied with the exact per-ray distance,
image noise, and LiDAR range / attenuation / noise factors. The presets below (morning, noon, dusk, night,
fog, rain) are a first model; configs/conditions/ YAML files are meant to deserialise into this class.

Fog (Koschmieder): L = L0 * T + L_fog * (1 - T), T = exp(-beta * d), beta = 3.912 / visibility (the
distance at which contrast falls to 2 %); rays that hit nothing see the fog colour (d = infinity).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pipeline.sensors.lidar import LidarConfig
from pipeline.sensors.shading import Lighting

KOSCHMIEDER = 3.912  # -ln(0.02): contrast threshold of 2 %


@dataclass(frozen=True)
class Condition:
    """Attributes:
    name: condition name.
    lighting: sun, sky, ambient and lights.
    fog_visibility_m: meteorological visibility, metres; None = clear air.
    fog_rgb: fog (airlight) colour, linear RGB.
    image_noise_std: Gaussian noise added to linear radiance (grows at night).
    lidar_range_scale, lidar_attenuation_scale, lidar_noise_scale, lidar_dropout_add: LiDAR degradation.
    """

    name: str
    lighting: Lighting
    fog_visibility_m: float | None = None
    fog_rgb: tuple[float, float, float] = (0.62, 0.65, 0.68)
    image_noise_std: float = 0.004
    lidar_range_scale: float = 1.0
    lidar_attenuation_scale: float = 1.0
    lidar_noise_scale: float = 1.0
    lidar_dropout_add: float = 0.0

    def __post_init__(self) -> None:
        if self.fog_visibility_m is not None and self.fog_visibility_m <= 0:
            raise ValueError(f"condition {self.name!r}: fog_visibility_m must be positive")
        if self.image_noise_std < 0 or self.lidar_noise_scale < 0 or self.lidar_attenuation_scale < 0:
            raise ValueError(f"condition {self.name!r}: noise and attenuation scales must be >= 0")
        if not 0.0 < self.lidar_range_scale <= 1.0 or not 0.0 <= self.lidar_dropout_add < 1.0:
            raise ValueError(f"condition {self.name!r}: need 0 < lidar_range_scale <= 1, 0 <= lidar_dropout_add < 1")

    def fog(self, radiance: np.ndarray, distance_m: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """Apply fog to (N, 3) float32 radiance given (N,) distances along the rays and the (N,) hit mask."""
        if self.fog_visibility_m is None:
            return radiance
        beta = KOSCHMIEDER / self.fog_visibility_m
        transmittance = np.where(hit, np.exp(-beta * np.where(hit, distance_m, 0.0)), 0.0).astype(np.float32)
        fog = np.asarray(self.fog_rgb, np.float32) * self.lighting.exposure
        return radiance * transmittance[:, None] + fog * (1.0 - transmittance[:, None])

    def noisy(self, radiance: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Add sensor noise (Gaussian in linear radiance) drawn from ``rng``."""
        if self.image_noise_std == 0:
            return radiance
        noise = rng.standard_normal(radiance.shape, dtype=np.float32)
        noise *= np.float32(self.image_noise_std)
        return radiance + noise

    def lidar(self, config: LidarConfig) -> LidarConfig:
        """The LiDAR config under this condition."""
        return dataclasses.replace(
            config,
            range_max_m=config.range_max_m * self.lidar_range_scale,
            attenuation_per_m=config.attenuation_per_m * self.lidar_attenuation_scale,
            range_noise_std_m=config.range_noise_std_m * self.lidar_noise_scale,
            dropout_prob=min(0.99, config.dropout_prob + self.lidar_dropout_add),
        )


CONDITIONS: dict[str, Condition] = {
    c.name: c
    for c in (
        Condition("morning", Lighting(sun_elevation_deg=12.0, sun_azimuth_deg=80.0, sun_rgb=(2.6, 2.1, 1.5),
                                      ambient_rgb=(0.35, 0.38, 0.48), sky_zenith_rgb=(0.2, 0.32, 0.6),
                                      sky_horizon_rgb=(0.85, 0.72, 0.6))),
        Condition("noon", Lighting(sun_elevation_deg=65.0, sun_azimuth_deg=170.0)),
        Condition("dusk", Lighting(sun_elevation_deg=3.0, sun_azimuth_deg=260.0, sun_rgb=(1.6, 0.8, 0.4),
                                   ambient_rgb=(0.15, 0.14, 0.2), sky_zenith_rgb=(0.08, 0.1, 0.25),
                                   sky_horizon_rgb=(0.7, 0.38, 0.2), lights_on=True), image_noise_std=0.008),
        Condition("night", Lighting(sun_elevation_deg=-20.0, sun_rgb=(0.0, 0.0, 0.0), ambient_rgb=(0.02, 0.022, 0.035),
                                    sky_zenith_rgb=(0.002, 0.003, 0.008), sky_horizon_rgb=(0.01, 0.012, 0.02),
                                    lights_on=True, exposure=2.5),
                  image_noise_std=0.012, lidar_noise_scale=1.5),
        Condition("fog", Lighting(sun_elevation_deg=40.0, sun_rgb=(0.8, 0.8, 0.8), ambient_rgb=(0.55, 0.56, 0.58),
                                  shadows=False), fog_visibility_m=80.0, lidar_range_scale=0.5,
                  lidar_attenuation_scale=8.0, lidar_dropout_add=0.05),
        Condition("rain", Lighting(sun_elevation_deg=35.0, sun_rgb=(0.6, 0.6, 0.62), ambient_rgb=(0.4, 0.42, 0.46),
                                   sky_zenith_rgb=(0.35, 0.37, 0.4), sky_horizon_rgb=(0.5, 0.52, 0.55),
                                   shadows=False), fog_visibility_m=600.0, image_noise_std=0.006,
                  lidar_range_scale=0.8, lidar_attenuation_scale=3.0, lidar_noise_scale=2.0, lidar_dropout_add=0.03),
    )
}


def get_condition(name: str) -> Condition:
    """A preset by name; unknown names fail listing the known ones."""
    try:
        return CONDITIONS[name]
    except KeyError:
        raise KeyError(f"unknown condition {name!r}; known: {', '.join(CONDITIONS)}") from None
