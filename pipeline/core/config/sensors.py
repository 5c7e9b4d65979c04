"""Sensor rig and environmental condition configuration.

A mount pose is the sensor body's pose in the ego frame (x forward, y left, z up; metres, radians).
A camera's optical frame (OpenCV) is derived from its body frame (see pipeline.core.geometry).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, model_serializer, model_validator

from pipeline.core.config.actor_meshes import ActorMeshConfig
from pipeline.core.config.base import ConfigModel
from pipeline.core.photometry import candela_to_intensity


class _Model(ConfigModel):
    pass


class MountPose(_Model):
    xyz_m: tuple[float, float, float]
    rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)


class ImageSensorConfig(_Model):
    """The camera's image sensor, aperture and auto-exposure (:mod:`pipeline.sensors.exposure`).

    Defaults: onsemi's AR0132AT, an automotive 1/3-inch CMOS sensor (datasheet AR0132AT/D Rev. 9, Table 1: 3.75 um
    pixels, SNR max 43.9 dB, i.e. a full well of 10^(43.9/10) = 24,500 electrons, and > 115 dB dynamic range in its
    HDR mode, so that highlights are not clipped here); quantum efficiency and read noise as is typical of such pixels
    (the datasheet gives neither: a front-side pixel's peak QE is ~0.6; read noise a few electrons); an f/2.0 lens
    transmitting 90 %. Exposure limits as the issue on physical cameras asks of automotive cameras: 1/10000 to
    1/30 s (one frame at 30 Hz), analogue gain up to 16x.
    """

    f_number: float = Field(2.0, ge=0.7, le=22.0, description="lens aperture (f-number)")
    lens_transmission: float = Field(0.9, gt=0.0, le=1.0, description="share of the light the lens passes")
    pixel_pitch_um: float = Field(3.75, gt=0.5, le=20.0, description="pixel size, micrometres")
    quantum_efficiency: float = Field(0.6, gt=0.0, le=1.0, description="electrons per photon within a colour "
                                      "filter's passband (each filter passes about a third of the visible band)")
    full_well_e: float = Field(24500.0, gt=100.0, description="electrons of a full pixel at gain 1; the linear "
                               "image's 1.0 (an HDR sensor: brighter values are kept, not clipped)")
    read_noise_e: float = Field(4.0, ge=0.0, le=100.0, description="read-out noise, electrons (std)")
    exposure_time_s: tuple[float, float] = Field((1e-4, 1 / 30), description="shortest and longest exposure time, "
                                                 "seconds; the auto-exposure lengthens the time first, then the gain")
    max_gain: float = Field(16.0, ge=1.0, le=256.0, description="largest analogue gain")
    metering_key: float = Field(0.18, gt=0.0, le=1.0, description="log-average luminance of the linear image that "
                                "the auto-exposure aims at (times the condition's lens.exposure compensation): 0.18, "
                                "the normal key of Reinhard et al.'s photographic tone reproduction (2002), mid-grey")

    @model_validator(mode="after")
    def _check_times(self) -> ImageSensorConfig:
        lo, hi = self.exposure_time_s
        if not 0.0 < lo <= hi <= 1.0:
            raise ValueError(f"exposure_time_s must be (shortest, longest) with 0 < shortest <= longest <= 1 s, got "
                             f"{self.exposure_time_s}")
        return self


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
    samples_per_pixel: int = Field(1, ge=1, le=64, description="anti-aliasing samples, taken at edge pixels")
    samples_everywhere: bool = Field(False, description="take the samples at every pixel (shadow edges too)")
    quality: Literal["fast", "realistic"] = Field(
        "realistic", description="realistic: sky occlusion and mirror reflections traced; fast: neither (quicker)")
    psf_sigma_px: float = Field(
        0.0, ge=0.0, le=5.0, description="the optics' point-spread function (lens, the sensor's low-pass filter and "
        "demosaicing): a Gaussian of this standard deviation in pixels on the linear image; 0 = perfect optics")
    sensor: ImageSensorConfig = Field(default_factory=ImageSensorConfig, description="the camera's image sensor and "
                                      "auto-exposure (pipeline.sensors.exposure)")
    mount: MountPose

    @model_validator(mode="after")
    def _check_intrinsics(self) -> CameraConfig:
        if (self.K is None) == (self.hfov_deg is None):
            raise ValueError("give exactly one of hfov_deg and K")
        if self.K is not None:
            (fx, s, _), (r, fy, _), bottom = self.K
            if s != 0 or r != 0 or tuple(bottom) != (0, 0, 1) or fx <= 0 or fy <= 0:
                raise ValueError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {self.K}")
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
    wavelength_nm: float = Field(905.0, ge=300.0, le=2000.0, description="laser wavelength, nm (the fog's extinction "
                                 "depends on it: pipeline.sensors.weather)")
    range_noise_std_m: float = Field(0.02, ge=0.0)
    dropout: float = Field(0.02, ge=0.0, lt=1.0, description="chance that a return is lost")
    # The droplets' back-scatter in fog and rain (pipeline.sensors.backscatter): the detection threshold is the return
    # of a surface of range_reflectivity at range_m in clear air (Velodyne HDL-64E: 120 m for 80 %, cars and foliage).
    range_reflectivity: float = Field(0.8, gt=0.0, le=1.0, description="Lambertian reflectivity of the target "
                                      "the LiDAR detects at range_m in clear air (its detection threshold)")
    pulse_half_width_ns: float = Field(20.0, gt=0.0, le=200.0, description="half-power width of the laser pulse, ns")
    # Rasshofer et al. 2011's Eqs. 11-12 for a biaxial head: 0.1 m between transmitter and receiver, 1 cm apertures,
    # 2 and 3.5 degree fields of view (the geometry in Hahner et al. 2021's fog simulation).
    overlap_m: tuple[float, float] = Field((1.67, 7.63), description="ranges r1 <= r2, metres, where the "
                                           "receiver's field of view starts to overlap the beam and overlaps it wholly")
    mount: MountPose

    @model_validator(mode="after")
    def _check_fov(self) -> LidarConfig:
        if not self.lower_fov_deg < self.upper_fov_deg:
            raise ValueError(f"lower_fov_deg ({self.lower_fov_deg}) must be below upper_fov_deg ({self.upper_fov_deg})")
        columns = 360.0 / self.horizontal_resolution_deg
        if abs(columns - round(columns)) > 1e-6:
            raise ValueError(f"horizontal_resolution_deg ({self.horizontal_resolution_deg}) must divide 360")
        if not 0.0 <= self.overlap_m[0] <= self.overlap_m[1] <= 100.0:
            raise ValueError(f"overlap_m ({list(self.overlap_m)}): expected 0 <= r1 <= r2 <= 100 metres")
        return self


class RadarConfig(_Model):
    """Automotive radar (77 GHz long-range class): a ray-cast scan over a field of view, detections merged per
    range-azimuth-Doppler resolution cell (:mod:`pipeline.sensors.radar`). Radar frame = its mount's body frame
    (x forward, y left, z up); azimuth is atan2(y, x), elevation asin(z / range).

    The scan casts a grid of rays ``ray_step_deg`` apart over the field of view: each ray stands for the patch of
    surface it meets (solid angle step^2 cos(elevation)), so the RCS an object returns does not depend on the step
    as long as the object spans several rays. The SNR follows the radar equation, scaled so that a 0 dBsm target
    at 100 m has ``snr_0dbsm_100m_db``; a cell is detected with the Swerling-1 probability
    Pd = Pfa^(1 / (1 + SNR)) of a square-law detector at ``false_alarm_probability``.
    """

    name: str = Field(pattern=r"^[A-Za-z0-9_]+$")
    range_min_m: float = Field(0.5, ge=0.0, description="nearer returns are not reported, metres")
    range_max_m: float = Field(200.0, gt=0.0, le=1000.0, description="farther returns are not reported, metres")
    azimuth_fov_deg: float = Field(120.0, gt=0.0, le=180.0, description="full horizontal field of view, degrees")
    elevation_fov_deg: float = Field(8.0, gt=0.0, le=60.0, description="full vertical field of view, degrees")
    ray_step_deg: float = Field(0.2, ge=0.02, le=2.0, description="spacing of the cast rays, degrees")
    range_resolution_m: float = Field(0.5, gt=0.0, le=10.0, description="size of a range cell, metres")
    azimuth_resolution_deg: float = Field(2.0, gt=0.0, le=30.0, description="size of an azimuth cell, degrees")
    velocity_resolution_mps: float = Field(0.25, gt=0.0, le=5.0, description="size of a Doppler cell, m/s")
    range_accuracy_m: float = Field(0.15, ge=0.0, le=5.0, description="range noise std, metres")
    azimuth_accuracy_deg: float = Field(0.3, ge=0.0, le=10.0, description="azimuth noise std, degrees")
    elevation_accuracy_deg: float = Field(1.0, ge=0.0, le=10.0, description="elevation noise std, degrees")
    velocity_accuracy_mps: float = Field(0.1, ge=0.0, le=5.0, description="radial velocity noise std, m/s")
    snr_0dbsm_100m_db: float = Field(10.0, ge=-50.0, le=100.0, description="SNR of a 0 dBsm target at 100 m, dB")
    false_alarm_probability: float = Field(1e-6, ge=1e-9, lt=1.0, description="per cell; sets the threshold")
    max_detections: int = Field(250, ge=1, le=100000, description="per scan; the strongest (by SNR) are kept")
    cycle_hz: float = Field(20.0, gt=0.0, le=1000.0, description="scan rate (recorded; the record scans per frame)")
    mount: MountPose

    @model_validator(mode="after")
    def _check_ranges(self) -> RadarConfig:
        if not self.range_min_m < self.range_max_m:
            raise ValueError(f"range_min_m ({self.range_min_m}) must be below range_max_m ({self.range_max_m})")
        if self.ray_step_deg > self.azimuth_resolution_deg:
            raise ValueError(f"ray_step_deg ({self.ray_step_deg}) must not exceed azimuth_resolution_deg "
                             f"({self.azimuth_resolution_deg}): every azimuth cell needs a ray")
        return self

    @property
    def azimuth_rad(self) -> np.ndarray:
        """(W,) float64 ray azimuths, left to right seen from above (+ fov/2 .. - fov/2), ``ray_step_deg`` apart,
        symmetric about 0."""
        return np.radians(_symmetric_steps(self.azimuth_fov_deg, self.ray_step_deg))[::-1].copy()

    @property
    def elevation_rad(self) -> np.ndarray:
        """(H,) float64 ray elevations, top to bottom, ``ray_step_deg`` apart, symmetric about 0."""
        return np.radians(_symmetric_steps(self.elevation_fov_deg, self.ray_step_deg))[::-1].copy()

    @property
    def ray_count(self) -> int:
        return len(self.azimuth_rad) * len(self.elevation_rad)


def _symmetric_steps(fov_deg: float, step_deg: float) -> np.ndarray:
    """Angles ``step_deg`` apart, symmetric about 0, within [-fov/2, fov/2] (at least one: 0)."""
    half = int(np.floor(0.5 * fov_deg / step_deg + 1e-9))
    return np.arange(-half, half + 1) * step_deg


class RigConfig(_Model):
    """The ego's sensors, and optionally the users' own meshes for actor classes (``actor_meshes``, see
    :mod:`pipeline.core.config.actor_meshes`; procedural bodies draw the rest)."""

    name: str
    cameras: list[CameraConfig] = Field(default_factory=list)
    lidars: list[LidarConfig] = Field(default_factory=list)
    radars: list[RadarConfig] = Field(default_factory=list)
    actor_meshes: list[ActorMeshConfig] = Field(default_factory=list)

    @model_validator(mode="after")
    def _check_names(self) -> RigConfig:
        names = ([c.name for c in self.cameras] + [lidar.name for lidar in self.lidars]
                 + [radar.name for radar in self.radars])
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"sensor names must be unique; repeated: {', '.join(duplicates)}")
        if not names:
            raise ValueError("a rig needs at least one camera or LiDAR")
        for entry in self.actor_meshes:
            first = next(e for e in self.actor_meshes if e.cls == entry.cls)
            if entry.replace != first.replace:
                raise ValueError(f"actor_meshes: the entries of class {entry.cls.value} disagree on replace "
                                 f"({first.path}: {first.replace}, {entry.path}: {entry.replace})")
        return self

    @model_serializer(mode="wrap")
    def _without_empty_radars(self, handler):
        """A rig without radars dumps as before radars existed, so that its records' meta.json (the resolved
        config and its hash) and the render's resume key stay byte-identical."""
        data = handler(self)
        if not self.radars and isinstance(data, dict):
            data.pop("radars", None)
        return data


RGB = tuple[float, float, float]


def _rgb(description: str, default: RGB) -> RGB:
    return Field(default, description=f"{description}; linear RGB, each channel >= 0")


class _ConditionPart(_Model):
    @model_validator(mode="after")
    def _check_rgb(self) -> _ConditionPart:
        for name in type(self).model_fields:
            if name.endswith("_rgb") and getattr(self, name) is not None and min(getattr(self, name)) < 0:
                raise ValueError(f"{name}: colour channels must be >= 0, got {getattr(self, name)}")
        return self


class _Light(_ConditionPart):
    """A light given either in the renderer's units (``intensity``) or in candela (``intensity_cd``)."""

    @model_validator(mode="after")
    def _from_candela(self) -> _Light:
        if self.intensity_cd is None:
            return self
        # Candela are luminous intensity: the light's colour is scaled to unit luminance (Rec. 709 Y) first.
        r, g, b = self.color_rgb
        luminance = 0.2126 * r + 0.7152 * g + 0.0722 * b
        if luminance <= 0:
            raise ValueError(f"intensity_cd needs a colour with some luminance, got color_rgb {self.color_rgb}")
        derived = candela_to_intensity(self.intensity_cd) / luminance
        # A dumped config holds both; they must agree (a user who gives both and means different things is told).
        if "intensity" in self.model_fields_set and abs(self.intensity - derived) > 1e-9 * max(derived, 1.0):
            raise ValueError(f"give intensity (renderer units) or intensity_cd (candela), not both: intensity "
                             f"{self.intensity} disagrees with intensity_cd {self.intensity_cd} (= {derived:.6g})")
        object.__setattr__(self, "intensity", derived)
        return self


class SunConfig(_ConditionPart):
    """The sun: direction (azimuth CCW from east = world +x, elevation above the horizon), colour, strength.

    The azimuth follows the world frame (x east, y north), not a compass: 0 = east, 90 = north, 180 = west,
    270 = south; a compass bearing b (clockwise from north) is azimuth 90 - b.
    """

    azimuth_deg: float = Field(135.0, ge=-360.0, le=360.0,
                               description="CCW from east (world +x; 90 = north), degrees; not a compass bearing")
    elevation_deg: float = Field(45.0, ge=-90.0, le=90.0, description="above the horizon, degrees; <= 0: no sun")
    color_rgb: RGB = _rgb("colour of the sunlight (scaled by intensity)", (1.0, 0.94, 0.85))
    intensity: float | None = Field(2.6, ge=0.0, description="irradiance scale; 1 lights white paper to ~1 at "
                                    "exposure 1 (2.6 = 100 klx: pipeline.core.photometry); None = the clear-sky sun "
                                    "at its elevation (pipeline.core.photometry.clear_sky_sun_lux), colour_rgb scaled "
                                    "to luminance 1")
    shadows: bool = Field(True, description="cast shadow rays towards the sun")
    angular_radius_deg: float = Field(0.27, ge=0.0, le=5.0, description="the sun disc's angular radius, degrees "
                                      "(0.27: the real sun; its shadows have penumbrae); 0 = a point: hard shadows")


class SkyConfig(_ConditionPart):
    """Background radiance (rays that hit nothing) and the fill light it gives every surface.

    ``model`` "gradient" blends ``horizon_rgb`` to ``zenith_rgb``; "preetham" is the analytic daylight sky of Preetham,
    Shirley and Smits (1999) from the sun's direction and ``turbidity``, scaled so that the light it gives a surface
    facing up matches ``ambient_rgb``'s luminance (:mod:`pipeline.sensors.sky`); it needs the sun above the horizon.
    """

    model: Literal["gradient", "preetham"] = Field(
        "gradient", description="gradient: zenith_rgb to horizon_rgb; preetham: physical daylight sky from the sun")
    turbidity: float = Field(3.0, ge=1.7, le=10.0, description="haze of the preetham sky: 2 very clear, 3 clear, "
                             "6 hazy (Preetham et al. 1999; below 1.7 the model fails)")
    zenith_rgb: RGB = _rgb("sky radiance straight up (gradient)", (0.18, 0.32, 0.65))
    horizon_rgb: RGB = _rgb("sky radiance at the horizon (gradient)", (0.65, 0.75, 0.85))
    ambient_rgb: RGB = _rgb("ambient (sky fill) irradiance on every surface", (0.45, 0.5, 0.6))


class HeadlightConfig(_Light):
    """Vehicle low beams: elliptical spot cones with a soft edge, aimed slightly down, 1/d^2 fall-off, and a beam
    pattern inside the cone: brightest just below the cut-off, fading downwards and to the sides."""

    ego: bool = Field(True, description="the ego's two headlights light the scene")
    others: bool = Field(True, description="other vehicles' headlights light the scene")
    intensity: float = Field(60.0, ge=0.0, description="on-axis irradiance at 1 m per lamp (x color_rgb), the "
                             "renderer's units; or give intensity_cd")
    intensity_cd: float | None = Field(None, ge=0.0, description="the beam's peak luminous intensity per lamp, "
                                       "candela (sets intensity: pipeline.core.photometry; color_rgb scaled to "
                                       "luminance 1)")
    color_rgb: RGB = _rgb("headlight colour", (1.0, 0.95, 0.85))
    half_angle_h_deg: float = Field(32.0, gt=0.0, lt=89.0, description="horizontal half-width of the cone, degrees")
    half_angle_v_deg: float = Field(9.0, gt=0.0, lt=89.0, description="half-height of the cone below its axis, degrees")
    half_angle_up_deg: float = Field(
        3.0, gt=0.0, lt=89.0, description="half-height above the axis, degrees: the low beam's cut-off (axis + this)")
    soft_edge: float = Field(0.5, gt=0.0, le=1.0, description="fraction of the cone radius over which it fades out")
    pitch_down_deg: float = Field(2.5, ge=-10.0, le=45.0, description="low-beam aim below the horizontal, degrees")
    range_m: float = Field(80.0, gt=0.0, description="cut-off distance of the light, metres")
    max_other_vehicles: int = Field(8, ge=0, le=64, description="other vehicles lit, nearest to the camera first")
    shadows: bool = Field(False, description="shadow rays for other vehicles' headlights (the ego's never need them)")
    # The beam pattern inside the cone (pipeline/sensors/lights.py). The defaults give a uniform cone.
    peak_band_deg: float = Field(
        1.0, gt=0.0, le=45.0, description="band below the cut-off where the beam is at its peak intensity, degrees")
    vertical_falloff: float = Field(
        0.0, ge=0.0, le=4.0,
        description="below the peak band the intensity falls as (peak_band / angle below the cut-off) ** this "
                    "(0: uniform)")
    horizontal_falloff_deg: float | None = Field(
        None, gt=0.0, le=90.0,
        description="width of the bright middle of the beam: intensity x (floor + (1 - floor) exp(-(angle / this)^2))"
                    " across it, degrees (None: uniform across)")
    horizontal_floor: float = Field(
        1.0, ge=0.0, le=1.0, description="share of the peak intensity the beam keeps far to the sides")
    # Above the cut-off (pipeline/sensors/lights.py, above_cutoff_lights). The defaults give none.
    above_cutoff_share: float = Field(
        0.0, ge=0.0, le=0.1,
        description="intensity above the cut-off, uniform up to above_cutoff_deg over it, as a share of the peak "
                    "intensity: the light a real low beam sends over its cut-off (ECE R112 allows up to 625 cd, "
                    "1 lx at 25 m), which lights what stands in front of the car above its lamps (0: none)")
    above_cutoff_deg: float = Field(8.0, gt=0.0, le=45.0,
                                    description="how far above the cut-off that light reaches, degrees")


class StreetLampConfig(_Light):
    """Street lamps (positions from the static world): downward spot lights lighting pools below them."""

    intensity: float = Field(40.0, ge=0.0, description="on-axis irradiance at 1 m (x color_rgb), the renderer's "
                             "units; or give intensity_cd")
    intensity_cd: float | None = Field(None, ge=0.0, description="the lamp's luminous intensity within its cone, "
                                       "candela (sets intensity: pipeline.core.photometry; color_rgb scaled to "
                                       "luminance 1)")
    color_rgb: RGB = _rgb("lamp colour (sodium-ish warm by default)", (1.0, 0.75, 0.45))
    half_angle_deg: float = Field(70.0, gt=0.0, lt=89.0, description="half-angle of the downward cone, degrees")
    soft_edge: float = Field(0.5, gt=0.0, le=1.0, description="fraction of the cone radius over which it fades out")
    range_m: float = Field(25.0, gt=0.0, description="cut-off distance of the light, metres")
    max_lamps: int = Field(16, ge=0, le=128, description="lamps lit per frame, nearest to the camera first")
    max_distance_m: float = Field(120.0, gt=0.0, description="lamps farther from the camera light nothing")
    shadows: bool = Field(True, description="shadow rays from lit surfaces to each lamp")


class VehicleLightConfig(_Model):
    """Lamps that glow (emissive; they light nothing by themselves)."""

    glow: bool = Field(False, description="head and tail lights of every vehicle and street lamps glow")
    tail_glow: float = Field(1.0, ge=0.0, description="tail-light emission scale")
    head_glow: float = Field(1.0, ge=0.0, description="headlight emission scale")
    lamp_glow: float = Field(1.0, ge=0.0, description="street-lamp emission scale")


class FogConfig(_ConditionPart):
    """Koschmieder fog: T = exp(-3.912 d / visibility_m) with the exact distance d of each ray
    (:mod:`pipeline.sensors.weather`)."""

    visibility_m: float = Field(gt=0.0, description="meteorological visibility (2 % contrast), metres")
    color_rgb: RGB | None = Field(None, description="airlight colour, linear RGB before exposure; None = the sky's "
                                  "radiance at the horizon (the light the fog scatters is the sky's)")


class RainConfig(_Model):
    """Rain by its rate (:mod:`pipeline.sensors.weather`, :mod:`pipeline.sensors.rain`): Marshall-Palmer drops that
    dim the air (with any ``fog``), streak across the camera's exposure time and wet the road."""

    rate_mm_h: float = Field(gt=0.0, le=300.0, description="rainfall rate, mm/h (light < 2.5, moderate 2.5-7.6, "
                             "heavy > 7.6: the American Meteorological Society's glossary)")
    wetness: float | None = Field(None, ge=0.0, le=1.0, description="the road's wetness, 0 dry .. 1 a mirror sheet; "
                                  "None = from the rate (Gallaway's water film depth over the road's texture)")
    wind_mps: tuple[float, float] = Field((0.0, 0.0), description="horizontal wind (east, north), m/s: drops fall "
                                          "at their terminal speed plus the wind")
    drops: int = Field(0, ge=0, le=200, description="blurry raindrops on the lens (0 = none)")
    spray: float = Field(1.0, ge=0.0, le=10.0, description="the spray vehicles throw up from the wet road, times the "
                         "model's density (pipeline.sensors.spray; 0 = none)")
    umbrellas: float = Field(0.0, ge=0.0, le=1.0, description="the share of people who walk and stand under an open "
                             "umbrella (runners carry none); their labels include it (nuScenes' rule for carried "
                             "objects, not COCO's), so it is off unless asked for (docs/realism.md)")


class LensConfig(_Model):
    """Optics and exposure effects, applied to linear radiance before tone mapping."""

    # Six stops either way: beyond, every frame is black (1e-9 rendered one whose labels still said ten objects
    # were visible) or white; the render also checks the frames it writes.
    exposure: float = Field(1.0, ge=1 / 64, le=64.0, description="exposure compensation, from 1/64 to 64: the "
                            "camera's auto-exposure aims at its key times this (pipeline.sensors.exposure)")
    vignetting: float = Field(0.2, ge=0.0, lt=1.0, description="fraction of light lost at the image corners")
    bloom_threshold: float = Field(1.5, gt=0.0, description="linear radiance above which light blooms")
    bloom_strength: float = Field(0.0, ge=0.0, description="bloom added (0 = off)")
    bloom_sigma_px: float = Field(6.0, gt=0.0, description="bloom blur sigma, pixels")
    lens_flare: float = Field(0.0, ge=0.0, description="strength of ghosts from bright sources (0 = off)")
    wdr_gamma: float = Field(1.0, gt=0.0, le=1.0, description="wide-dynamic-range processing: luminance L becomes "
                             "p (L / p)^gamma about the pivot p = 0.5, lifting shadows and holding back highlights "
                             "(1 = off)")


class LidarConditionConfig(_Model):
    """LiDAR degradation (multiplying the rig's values)."""

    range_factor: float = Field(1.0, gt=0.0, le=1.0, description="x maximum range")
    intensity_factor: float = Field(1.0, gt=0.0, le=1.0, description="x returned intensity")
    attenuation_factor: float = Field(1.0, ge=0.0, description="x attenuation coefficient a in exp(-a d)")
    noise_factor: float = Field(1.0, ge=0.0, description="x range-noise std")
    extra_dropout: float = Field(0.0, ge=0.0, lt=1.0, description="added drop-out probability")
    min_intensity: float = Field(0.0, ge=0.0, lt=1.0, description="returns weaker than this are lost (0 = none)")


class ConditionConfig(_Model):
    """Lighting, weather and sensor effects of one condition (configs/conditions/NAME.yaml).

    Units: angles in degrees, distances in metres, colours linear RGB, radiance in the renderer's linear
    units (1 ~ white paper in full sun at exposure 1). Sections left out take their defaults; ``headlights``,
    ``street_lamps``, ``fog`` and ``rain`` are off when left out.
    """

    name: str = Field(pattern=r"^[A-Za-z0-9_-]+$", description="condition name, recorded with every image")
    description: str = Field("", description="free text")
    sun: SunConfig = Field(default_factory=SunConfig)
    sky: SkyConfig = Field(default_factory=SkyConfig)
    vehicle_lights: VehicleLightConfig = Field(default_factory=VehicleLightConfig)
    headlights: HeadlightConfig | None = Field(None, description="headlight cones (night, dusk); None = off")
    street_lamps: StreetLampConfig | None = Field(None, description="street-lamp light pools; None = off")
    fog: FogConfig | None = Field(None, description="Koschmieder fog; None = clear air")
    rain: RainConfig | None = Field(None, description="rain; None = dry")
    lens: LensConfig = Field(default_factory=LensConfig)
    lidar: LidarConditionConfig = Field(default_factory=LidarConditionConfig)

    @model_validator(mode="after")
    def _daylight_sky_needs_the_sun(self) -> ConditionConfig:
        if self.sky.model == "preetham" and not self.sun.elevation_deg > 0:
            raise ValueError(f"sky.model: preetham is a daylight sky and needs the sun above the horizon "
                             f"(sun.elevation_deg > 0), got sun.elevation_deg {self.sun.elevation_deg}")
        return self
