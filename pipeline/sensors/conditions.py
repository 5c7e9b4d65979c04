"""Environmental conditions: lighting, night lights, fog, rain, lens and sensor effects, LiDAR degradation.

A condition is a YAML file under configs/conditions/ (or any path) validated into
:class:`pipeline.core.config.ConditionConfig`; :class:`Condition` wraps it with the values the renderer derives
from it; :func:`get_condition` does both for a NAME or PATH. Users add a
condition by adding a YAML file.

Fog (Koschmieder): L = L0 * T + L_fog * (1 - T), T = exp(-beta * d), beta = 3.912 / visibility (the
distance at which contrast falls to 2 %), with d the exact distance along each ray; rays that hit nothing
see the fog colour (d = infinity).
"""

from __future__ import annotations

from functools import cached_property
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
    StreetLampConfig,
)
from pipeline.core.geometry import Transform
from pipeline.sensors.lidar import Lidar
from pipeline.sensors.lights import SpotLights, ego_headlights, street_lamp_lights, vehicle_headlights
from pipeline.sensors.post import luminance
from pipeline.sensors.shadows import sun_disc
from pipeline.sensors.sky import gradient_params, preetham_params
from pipeline.world.actors import Actors

KOSCHMIEDER = 3.912  # -ln(0.02): contrast threshold of 2 %
SHIPPED = ("morning", "noon", "dusk", "night", "fog", "rain")


class Condition:
    """One condition as the renderer uses it: the validated :class:`~pipeline.core.config.ConditionConfig` (its one
    definition of every field, default and check) and the values derived from it, as properties.

    Shading (:func:`pipeline.sensors.shading.shade`) reads the sun, sky, exposure, glow and wetness properties;
    the camera's fog and spot lights and the LiDAR's degradation are methods here.
    """

    def __init__(self, config: ConditionConfig) -> None:
        self.config = config

    @property
    def name(self) -> str:
        return self.config.name

    # -- light: sun, sky, exposure, glowing lamps, wet road ---------------------------------------
    @property
    def sun_elevation_deg(self) -> float:
        return self.config.sun.elevation_deg

    @property
    def sun_azimuth_deg(self) -> float:
        """CCW from east (world +x), degrees."""
        return self.config.sun.azimuth_deg

    @property
    def sun_direction(self) -> np.ndarray:
        """(3,) float32 unit vector towards the sun, world frame."""
        el, az = np.radians(self.sun_elevation_deg), np.radians(self.sun_azimuth_deg)
        return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], np.float32)

    @property
    def sun_rgb(self) -> tuple[float, float, float]:
        """Sun irradiance, linear RGB: colour x intensity; zero with the sun at or below the horizon."""
        if self.sun_elevation_deg <= 0:
            return (0.0, 0.0, 0.0)
        return tuple(float(v) for v in np.asarray(self.config.sun.color_rgb) * self.config.sun.intensity)

    @property
    def shadows(self) -> bool:
        """Cast shadow rays towards the sun."""
        return self.config.sun.shadows

    @property
    def sun_angular_radius_rad(self) -> float:
        """The sun disc's angular radius, radians (0: a point)."""
        return float(np.radians(self.config.sun.angular_radius_deg))

    @cached_property
    def sun_disc(self) -> np.ndarray:
        """(S, 3) float32 unit directions over the sun's disc that shadow rays sample
        (:func:`pipeline.sensors.shadows.sun_disc`; the one direction :attr:`sun_direction` for a point sun)."""
        return sun_disc(self.sun_direction, self.sun_angular_radius_rad)

    @property
    def ambient_rgb(self) -> tuple[float, float, float]:
        return self.config.sky.ambient_rgb

    @cached_property
    def sky_params(self) -> np.ndarray:
        """(SKY_PARAMS,) float32: the sky's parameters for :func:`pipeline.sensors.sky.sky_radiance` (the configured
        model; the Preetham sky scaled to the ambient's luminance)."""
        sky = self.config.sky
        if sky.model == "preetham":
            return preetham_params(self.sun_direction, sky.turbidity, float(luminance(np.asarray(sky.ambient_rgb))))
        return gradient_params(sky.zenith_rgb, sky.horizon_rgb)

    @property
    def exposure(self) -> float:
        """The exposure compensation: the shading multiplies the radiance by it, and the camera's auto-exposure
        divides it out of the light it meters and aims at its key times it (pipeline.sensors.exposure): the image is
        brighter by this factor wherever the sensor's limits allow."""
        return self.config.lens.exposure

    @property
    def lights_on(self) -> bool:
        """Vehicles' head and tail lights and street lamps glow (the light they cast comes from
        :meth:`frame_lights`)."""
        return self.config.vehicle_lights.glow

    @property
    def tail_glow(self) -> float:
        return self.config.vehicle_lights.tail_glow

    @property
    def head_glow(self) -> float:
        return self.config.vehicle_lights.head_glow

    @property
    def lamp_glow(self) -> float:
        return self.config.vehicle_lights.lamp_glow

    @property
    def wetness(self) -> float:
        """0 dry .. 1 soaked road-like surfaces: the rain's wetness, 0 without rain."""
        return self.config.rain.wetness if self.config.rain is not None else 0.0

    # -- weather and sensor effects ---------------------------------------------------------------
    @property
    def fog_visibility_m(self) -> float | None:
        """Meteorological visibility, metres; None = clear air."""
        return self.config.fog.visibility_m if self.config.fog is not None else None

    @property
    def fog_rgb(self) -> tuple[float, float, float] | None:
        """Airlight colour, linear RGB (before exposure); None = clear air."""
        return self.config.fog.color_rgb if self.config.fog is not None else None

    @property
    def headlights(self) -> HeadlightConfig | None:
        return self.config.headlights

    @property
    def street_lamps(self) -> StreetLampConfig | None:
        return self.config.street_lamps

    @property
    def rain(self) -> RainConfig | None:
        return self.config.rain

    @property
    def lens(self) -> LensConfig:
        return self.config.lens

    @property
    def lidar_effects(self) -> LidarConditionConfig:
        return self.config.lidar

    def fog(self, radiance: np.ndarray, distance_m: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """Apply fog to (N, 3) float32 radiance given (N,) distances along the rays and the (N,) hit mask."""
        if self.fog_visibility_m is None:
            return radiance
        beta = KOSCHMIEDER / self.fog_visibility_m
        transmittance = np.where(hit, np.exp(-beta * np.where(hit, distance_m, 0.0)), 0.0).astype(np.float32)
        fog = np.asarray(self.fog_rgb, np.float32) * self.exposure
        # Per channel on (N,) arrays: numpy broadcasts over a trailing axis of 3 several times slower.
        channels = cv2.split(np.ascontiguousarray(radiance, np.float32).reshape(-1, 1, 3))
        haze = 1.0 - transmittance
        return cv2.merge([c.reshape(-1) * transmittance + fog[k] * haze for k, c in enumerate(channels)]).reshape(-1, 3)

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


def get_condition(name_or_path: str | Path) -> Condition:
    """A condition by NAME (configs/conditions/NAME.yaml) or PATH, read afresh; unknown names and invalid files
    fail with a :class:`pipeline.core.config.ConfigError` naming the file and key (or listing the names)."""
    return Condition(load_config(ConditionConfig, name_or_path, "conditions")[0])
