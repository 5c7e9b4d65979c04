"""Environmental conditions: lighting, night lights, fog, rain, lens and sensor effects, LiDAR degradation.

A condition is a YAML file under configs/conditions/ (or any path) validated into
:class:`pipeline.core.config.ConditionConfig`; :func:`condition_from_config` turns it into the
:class:`Condition` the renderer uses; :func:`get_condition` does both for a NAME or PATH. Users add a
condition by adding a YAML file.

Fog (Koschmieder): L = L0 * T + L_fog * (1 - T), T = exp(-beta * d), beta = 3.912 / visibility (the
distance at which contrast falls to 2 %), with d the exact distance along each ray; rays that hit nothing
see the fog colour (d = infinity).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from pipeline.core.config import ConditionConfig, load_config
from pipeline.core.config.sensors import (
    HeadlightConfig,
    LensConfig,
    LidarConditionConfig,
    LidarConfig,
    RainConfig,
    SensorNoiseConfig,
    StreetLampConfig,
)
from pipeline.core.geometry import Transform
from pipeline.sensors.lidar import Lidar
from pipeline.sensors.lights import SpotLights, ego_headlights, street_lamp_lights, vehicle_headlights
from pipeline.sensors.post import sensor_noise
from pipeline.sensors.shading import Lighting
from pipeline.world.actors import Actors

KOSCHMIEDER = 3.912  # -ln(0.02): contrast threshold of 2 %
SHIPPED = ("morning", "noon", "dusk", "night", "fog", "rain")


@dataclass(frozen=True)
class Condition:
    """Attributes:
    name: condition name.
    lighting: sun, sky, ambient, exposure, glowing lamps, road wetness.
    fog_visibility_m: meteorological visibility, metres; None = clear air.
    fog_rgb: fog (airlight) colour, linear RGB (before exposure).
    headlights: headlight cones (None = off). street_lamps: street-lamp pools (None = off).
    rain: streaks and drops (None = dry; wetness is ``lighting.wetness``).
    noise: sensor noise. lens: exposure, vignetting, bloom, flare, motion blur.
    lidar_effects: LiDAR degradation factors.
    """

    name: str
    lighting: Lighting
    fog_visibility_m: float | None = None
    fog_rgb: tuple[float, float, float] = (0.62, 0.65, 0.68)
    headlights: HeadlightConfig | None = None
    street_lamps: StreetLampConfig | None = None
    rain: RainConfig | None = None
    noise: SensorNoiseConfig = field(default_factory=SensorNoiseConfig)
    lens: LensConfig = field(default_factory=LensConfig)
    lidar_effects: LidarConditionConfig = field(default_factory=LidarConditionConfig)

    def __post_init__(self) -> None:
        if self.fog_visibility_m is not None and self.fog_visibility_m <= 0:
            raise ValueError(f"condition {self.name!r}: fog_visibility_m must be positive")
        if self.lens.exposure != self.lighting.exposure:
            # One exposure: the shading applies it, the noise model reads it as the gain.
            object.__setattr__(self, "lens", self.lens.model_copy(update={"exposure": self.lighting.exposure}))

    def fog(self, radiance: np.ndarray, distance_m: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """Apply fog to (N, 3) float32 radiance given (N,) distances along the rays and the (N,) hit mask."""
        if self.fog_visibility_m is None:
            return radiance
        beta = KOSCHMIEDER / self.fog_visibility_m
        transmittance = np.where(hit, np.exp(-beta * np.where(hit, distance_m, 0.0)), 0.0).astype(np.float32)
        fog = np.asarray(self.fog_rgb, np.float32) * self.lighting.exposure
        # Per channel on (N,) arrays: numpy broadcasts over a trailing axis of 3 several times slower.
        channels = cv2.split(np.ascontiguousarray(radiance, np.float32).reshape(-1, 1, 3))
        haze = 1.0 - transmittance
        return cv2.merge([c.reshape(-1) * transmittance + fog[k] * haze for k, c in enumerate(channels)]).reshape(-1, 3)

    def noisy(self, radiance: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Shot + read noise (no grain) on radiance of any shape, drawn from ``rng`` (see
        :func:`pipeline.sensors.post.sensor_noise`; the renderer applies the full model through the post effects)."""
        return sensor_noise(radiance, self.noise.model_copy(update={"grain_std": 0.0}), self.lens.exposure, rng)

    def frame_lights(
        self,
        actors: Actors,
        ego_pose: Transform,
        camera_xyz_m: np.ndarray,
        street_lights_m: np.ndarray | None = None,
        ego_size_m: tuple[float, float, float] | None = None,
    ) -> SpotLights:
        """The spot lights of one frame: the ego's and other vehicles' headlights, the nearest street lamps."""
        parts = []
        if self.headlights is not None:
            if self.headlights.ego:
                parts.append(ego_headlights(ego_pose, self.headlights, *(() if ego_size_m is None else (ego_size_m,))))
            if self.headlights.others:
                parts.append(vehicle_headlights(actors, self.headlights, camera_xyz_m, ego_pose.rotation[:, 0]))
        if self.street_lamps is not None and street_lights_m is not None:
            parts.append(street_lamp_lights(street_lights_m, self.street_lamps, camera_xyz_m))
        return SpotLights.concatenate(parts)

    def lidar(self, lidar: Lidar) -> LidarConfig:
        """``lidar``'s config under this condition (range, attenuation, noise, drop-out; intensity factor and
        detection threshold are applied by :func:`pipeline.sensors.lidar.render_lidar`)."""
        fx, config = self.lidar_effects, lidar.config
        return config.model_copy(update={
            "range_m": max(config.range_m * fx.range_factor, lidar.range_min_m + 1e-3),
            "attenuation_per_m": config.attenuation_per_m * fx.attenuation_factor,
            "range_noise_std_m": config.range_noise_std_m * fx.noise_factor,
            "dropout": min(0.99, config.dropout + fx.extra_dropout),
        })


def condition_from_config(cfg: ConditionConfig) -> Condition:
    """The renderer's :class:`Condition` from a validated config."""
    sun = np.asarray(cfg.sun.color_rgb) * cfg.sun.intensity
    vl = cfg.vehicle_lights
    lighting = Lighting(
        sun_elevation_deg=cfg.sun.elevation_deg,
        sun_azimuth_deg=cfg.sun.azimuth_deg,
        sun_rgb=tuple(float(v) for v in sun) if cfg.sun.elevation_deg > 0 else (0.0, 0.0, 0.0),
        ambient_rgb=cfg.sky.ambient_rgb,
        sky_zenith_rgb=cfg.sky.zenith_rgb,
        sky_horizon_rgb=cfg.sky.horizon_rgb,
        exposure=cfg.lens.exposure,
        shadows=cfg.sun.shadows,
        lights_on=vl.glow,
        tail_glow=vl.tail_glow,
        head_glow=vl.head_glow,
        lamp_glow=vl.lamp_glow,
        wetness=cfg.rain.wetness if cfg.rain is not None else 0.0,
    )
    return Condition(
        name=cfg.name,
        lighting=lighting,
        fog_visibility_m=cfg.fog.visibility_m if cfg.fog is not None else None,
        fog_rgb=cfg.fog.color_rgb if cfg.fog is not None else (0.62, 0.65, 0.68),
        headlights=cfg.headlights,
        street_lamps=cfg.street_lamps,
        rain=cfg.rain,
        noise=cfg.noise,
        lens=cfg.lens,
        lidar_effects=cfg.lidar,
    )


def get_condition(name_or_path: str | Path) -> Condition:
    """A condition by NAME (configs/conditions/NAME.yaml) or PATH, read afresh; unknown names and invalid files
    fail with a :class:`pipeline.core.config.ConfigError` naming the file and key (or listing the names)."""
    return condition_from_config(load_config(ConditionConfig, name_or_path, "conditions")[0])
