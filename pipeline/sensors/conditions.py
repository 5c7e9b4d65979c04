"""Environmental conditions: lighting, night lights, fog, rain, lens and sensor effects, LiDAR degradation.

A condition is a YAML file under configs/conditions/ (or any path) validated into
:class:`pipeline.core.config.ConditionConfig`; :class:`Condition` wraps it with the values the renderer derives
from it; :func:`get_condition` does both for a NAME or PATH. Users add a
condition by adding a YAML file.

Fog and rain dim the air (:mod:`pipeline.sensors.weather`): L = L0 * T + L_air * (1 - T), T = exp(-beta * d), with
beta the fog's (3.912 / visibility, the distance at which contrast falls to 2 %) plus the rain's (Marshall-Palmer drops
at the rain's rate) and d the exact distance along each ray; rays that hit nothing see the airlight L_air (d =
infinity), the sky's radiance at the horizon unless the fog gives its colour. The LiDAR's two-way extinction comes
from the same values at its wavelength.
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
from pipeline.core.photometry import clear_sky_sun_lux, lux_to_irradiance
from pipeline.sensors.lidar import Lidar
from pipeline.sensors.lights import SpotLights, ego_headlights, street_lamp_lights, vehicle_headlights
from pipeline.sensors.post import luminance
from pipeline.sensors.shadows import sun_disc
from pipeline.sensors.sky import gradient_params, preetham_params, sky_rays
from pipeline.sensors.spray import NO_SPRAY, SprayClouds, spray_clouds
from pipeline.sensors.weather import (
    KOSCHMIEDER,
    fog_extinction_per_m,
    rain_extinction_per_m,
    road_water_mm,
    road_wetness,
)
from pipeline.world.actors import Actors

SHIPPED = ("morning", "noon", "dusk", "night", "fog", "rain")
# Fog droplets' forward lobe: a peak of ~lambda / 2r (radii of 5-10 um: 1.5-3 degrees) with a long tail, as the sum of
# Gaussians (weight, sigma in degrees) that the aureoles of lamps in fog show (a core, then a slow fall-off).
HALO_LOBES = ((0.5, 1.0), (0.3, 3.0), (0.2, 8.0))
HALO_FORWARD_SHARE = 0.25  # of a source's scattered light, within that lobe (assumed: not measured)
HALO_MIN_TRANSMITTANCE = 0.05  # sources seen through less are taken at this (their direct image is gone in the noise)


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
        """Sun irradiance, linear RGB: colour x intensity (or the clear-sky sun's illuminance at the sun's elevation,
        :func:`pipeline.core.photometry.clear_sky_sun_lux`); zero with the sun at or below the horizon."""
        if self.sun_elevation_deg <= 0:
            return (0.0, 0.0, 0.0)
        sun = self.config.sun
        if sun.intensity is None:  # the clear-sky sun at its elevation, its colour of unit luminance
            color = np.asarray(sun.color_rgb, np.float64)
            scale = lux_to_irradiance(clear_sky_sun_lux(self.sun_elevation_deg)) / max(float(luminance(color)), 1e-9)
            return tuple(float(v) for v in color * scale)
        return tuple(float(v) for v in np.asarray(sun.color_rgb) * sun.intensity)

    @property
    def shadows(self) -> bool:
        """Cast shadow rays towards the sun."""
        return self.config.sun.shadows

    @property
    def sun_shadows(self) -> bool:
        """The sun casts shadows: shadow rays are on and the sun is above the horizon."""
        return self.shadows and self.sun_elevation_deg > 0

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
    def rain_rate_mm_h(self) -> float:
        """The rain's rate, mm/h; 0 without rain."""
        return self.config.rain.rate_mm_h if self.config.rain is not None else 0.0

    @property
    def umbrellas(self) -> float:
        """The share of people under an open umbrella (the rain's ``umbrellas``); 0 without rain."""
        return self.config.rain.umbrellas if self.config.rain is not None else 0.0

    @property
    def wetness(self) -> float:
        """0 dry .. 1 drowned road-like surfaces: the rain's ``wetness``, or the share of the road's texture its water
        fills at its rate (:func:`pipeline.sensors.weather.road_wetness`); 0 without rain."""
        rain = self.config.rain
        if rain is None:
            return 0.0
        return rain.wetness if rain.wetness is not None else road_wetness(rain.rate_mm_h)

    def spray(self, actors: Actors, velocity_mps: np.ndarray | None, active: np.ndarray | None = None) -> SprayClouds:
        """The spray clouds of a frame's moving vehicles (:func:`pipeline.sensors.spray.spray_clouds`) on the road's
        water at the rain's rate; none without rain or with ``rain.spray`` 0, or where ``wetness`` is given and 0."""
        rain = self.rain
        if rain is None or rain.spray == 0 or rain.wetness == 0:
            return NO_SPRAY
        return spray_clouds(actors, velocity_mps, road_water_mm(rain.rate_mm_h), rain.spray, active)

    # -- weather and sensor effects ---------------------------------------------------------------
    @property
    def fog_visibility_m(self) -> float | None:
        """Meteorological visibility, metres; None = clear air."""
        return self.config.fog.visibility_m if self.config.fog is not None else None

    def extinction_per_m(self, wavelength_nm: float = 550.0) -> float:
        """The air's extinction coefficient at ``wavelength_nm``, 1/m: the fog's plus the rain's (0: clear air)."""
        beta = 0.0
        if self.fog_visibility_m is not None:
            beta += fog_extinction_per_m(self.fog_visibility_m, wavelength_nm)
        return beta + rain_extinction_per_m(self.rain_rate_mm_h)

    @property
    def visibility_m(self) -> float | None:
        """The meteorological visibility of fog and rain together, metres (3.912 / extinction); None = clear air."""
        beta = self.extinction_per_m()
        return KOSCHMIEDER / beta if beta > 0 else None

    @cached_property
    def airlight_rgb(self) -> tuple[float, float, float]:
        """The radiance of an infinitely long ray through the fog or rain, linear RGB before exposure: the fog's
        ``color_rgb``, else the sky's radiance at the horizon (the mean over azimuths just above it)."""
        fog = self.config.fog
        if fog is not None and fog.color_rgb is not None:
            return fog.color_rgb
        az = np.radians(np.arange(0.0, 360.0, 15.0))
        el = np.radians(1.0)
        dirs = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.full_like(az, np.sin(el))])
        return tuple(float(v) for v in sky_rays(dirs.astype(np.float32), self.sky_params).mean(axis=0))

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
        """Dim (N, 3) float32 radiance through the fog and rain along (N,) distances, given the (N,) hit mask."""
        beta = self.extinction_per_m()
        if beta == 0:
            return radiance
        transmittance = np.where(hit, np.exp(-beta * np.where(hit, distance_m, 0.0)), 0.0).astype(np.float32)
        air = np.asarray(self.airlight_rgb, np.float32) * self.exposure
        # Per channel on (N,) arrays: numpy broadcasts over a trailing axis of 3 several times slower.
        channels = cv2.split(np.ascontiguousarray(radiance, np.float32).reshape(-1, 1, 3))
        haze = 1.0 - transmittance
        return cv2.merge([c.reshape(-1) * transmittance + air[k] * haze for k, c in enumerate(channels)]).reshape(-1, 3)

    def halos(self, radiance: np.ndarray, distance_m: np.ndarray, sources: np.ndarray, image_shape: tuple[int, int],
              fy_px: float, spray_transmittance: np.ndarray | None = None) -> None:
        """Add, in place, to a frame's fogged (H*W, 3) float32 ``radiance`` the light that the fog and rain scatter
        forwards from its glowing ``sources`` ((H*W,) bool: lamps, lit windows) at (H*W,) ``distance_m``: the haloes
        round lamps in fog. A source of radiance L0 seen through a transmittance T loses L0 (1 - T) from its direct
        image; HALO_FORWARD_SHARE of that reaches the camera within the droplets' forward lobe (HALO_LOBES: their
        diffraction peak and its tail, widened by multiple scattering), the rest joins the airlight.
        ``spray_transmittance`` (H*W,) float32, optional: each pixel's transmittance through spray
        (:mod:`pipeline.sensors.spray`, composited with the same airlight), by which T is multiplied: lamps glow in
        the spray behind vehicles as in fog."""
        beta = self.extinction_per_m()
        if beta == 0 or not sources.any():
            return
        h, w = image_shape
        rows = np.flatnonzero(sources)
        t = np.exp(-beta * distance_m[rows])
        if spray_transmittance is not None:
            t = t * spray_transmittance[rows]
        t = np.maximum(t, HALO_MIN_TRANSMITTANCE).astype(np.float32)[:, None]
        air = np.asarray(self.airlight_rgb, np.float32) * np.float32(self.exposure)
        direct = np.maximum(radiance[rows] - air * (1.0 - t), 0.0) / t  # the source's radiance before the fog
        layer = np.zeros((h * w, 3), np.float32)
        layer[rows] = direct * ((1.0 - t) * np.float32(HALO_FORWARD_SHARE))
        layer = layer.reshape(h, w, 3)
        small = cv2.resize(layer, (w // 4, h // 4), interpolation=cv2.INTER_AREA)  # the wide lobes at quarter size
        halo = np.zeros_like(layer)
        for weight, sigma_deg in HALO_LOBES:
            sigma = float(fy_px * np.radians(sigma_deg))
            if sigma < 8.0:
                halo += np.float32(weight) * cv2.GaussianBlur(layer, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
            else:
                wide = cv2.GaussianBlur(small, (0, 0), sigma / 4.0, borderType=cv2.BORDER_CONSTANT)
                halo += np.float32(weight) * cv2.resize(wide, (w, h), interpolation=cv2.INTER_LINEAR)
        radiance += halo.reshape(-1, 3)

    def frame_lights(
        self,
        actors: Actors,
        ego_pose: Transform,
        camera_xyz_m: np.ndarray,
        street_lights_m: np.ndarray | None = None,
        ego_size_m: tuple[float, float, float] | None = None,
        *,
        ego_lamp_pair: bool = False,
    ) -> SpotLights:
        """The spot lights of one frame: the ego's and other vehicles' headlights, the nearest street lamps.
        ``ego_lamp_pair``: the ego's two headlamps apart (the beams in fog, seen from just behind them), not as one
        light between them (enough for what they light)."""
        parts = []
        if self.headlights is not None:
            if self.headlights.ego:
                parts.append(ego_headlights(ego_pose, self.headlights, *(() if ego_size_m is None else (ego_size_m,)),
                                            pair=ego_lamp_pair))
            if self.headlights.others:
                parts.append(vehicle_headlights(actors, self.headlights, camera_xyz_m, ego_pose.rotation[:, 0]))
        if self.street_lamps is not None and street_lights_m is not None:
            parts.append(street_lamp_lights(street_lights_m, self.street_lamps, camera_xyz_m))
        return SpotLights.concatenate(parts)

    def lidar(self, lidar: Lidar) -> LidarConfig:
        """``lidar``'s config under this condition: the air's two-way extinction at the LiDAR's wavelength (fog and
        rain, :mod:`pipeline.sensors.weather`) added to its attenuation and shortening its range
        (:func:`lidar_range_m`), then the condition's ``lidar`` factors (range, attenuation, noise, drop-out; intensity
        factor and detection threshold are applied by :func:`pipeline.sensors.lidar.render_lidar`)."""
        fx, config = self.lidar_effects, lidar.config
        beta = self.extinction_per_m(config.wavelength_nm)
        return config.model_copy(update={
            "range_m": max(lidar_range_m(config.range_m, beta) * fx.range_factor, lidar.range_min_m + 1e-3),
            "attenuation_per_m": (config.attenuation_per_m + 2.0 * beta) * fx.attenuation_factor,
            "range_noise_std_m": config.range_noise_std_m * fx.noise_factor,
            "dropout": min(0.99, config.dropout + fx.extra_dropout),
        })


def lidar_range_m(clear_range_m: float, extinction_per_m: float) -> float:
    """A LiDAR's range through air of ``extinction_per_m`` (at its wavelength): the distance R at which the target it
    just detects at ``clear_range_m`` R0 in clear air is just detected again, the return's power ~ exp(-2 beta R) / R^2
    equal to 1 / R0^2: R = W(beta R0) / beta (W: Lambert's function)."""
    if extinction_per_m <= 0:
        return clear_range_m
    from scipy.special import lambertw

    return float(lambertw(extinction_per_m * clear_range_m).real) / extinction_per_m


def get_condition(name_or_path: str | Path) -> Condition:
    """A condition by NAME (configs/conditions/NAME.yaml) or PATH, read afresh; unknown names and invalid files
    fail with a :class:`pipeline.core.config.ConfigError` naming the file and key (or listing the names)."""
    return Condition(load_config(ConditionConfig, name_or_path, "conditions")[0])
