"""The camera's image sensor and auto-exposure, in electrons.

Light to electrons. A surface of luminance L (cd/m^2) imaged through a lens of f-number N and transmission T gives
the focal plane the illuminance E = pi T L / (4 N^2) (the camera equation, on axis; the fall-off towards the corners
is the lens's vignetting, applied with the optics). Over the exposure time t a pixel of pitch p collects
E t p^2 lumen-seconds, i.e. E t p^2 PHOTONS_PER_LUMEN_S photons, of which its colour filter passes about a third
and the photodiode turns the share QE into electrons:

    electrons = radiance * CD_M2_PER_UNIT * pi T / (4 N^2) * t * p^2 * PHOTONS_PER_LUMEN_S * QE / 3

per channel of the renderer's linear RGB (radiance in the renderer's units, :mod:`pipeline.core.photometry`).
The analogue gain g multiplies the electrons before read-out, and the linear image's 1.0 is a full pixel at gain 1,
so the image is ``radiance * scale`` with ``scale = electrons per (unit radiance) * g / full_well``.

Noise follows from the signal. Photon arrival is Poisson (variance = the electrons), the read-out adds Gaussian
noise of ``read_noise_e`` electrons; both are amplified by the gain. In the image's units, a pixel of value v has
the variance ``v * g / full_well + (g * read_noise_e / full_well)^2``: the shot noise's standard deviation grows as
the square root of the signal, and every term with the gain.

Auto-exposure. The camera meters each frame as before (the log-average luminance of the linear image) and aims at
``metering_key`` times the condition's exposure compensation (``lens.exposure``). It lengthens the exposure time
first, within ``exposure_time_s`` (a longer exposure blurs motion but adds no noise), then raises the gain up to
``max_gain``. Where the light is too little even then, the frame stays darker than the key: at night the camera
cannot gather the light a day frame has, and the gain that it does apply shows as noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.core.config.sensors import ImageSensorConfig
from pipeline.core.photometry import CD_M2_PER_UNIT
from pipeline.sensors.post import luminance

# Photons in one lumen-second of daylight: D65's luminous efficacy over 380-780 nm is ~205 lm/W (CIE 1931
# photopic V(lambda)), its mean photon energy in that band ~3.6e-19 J (550 nm): 1 / (205 * 3.6e-19).
PHOTONS_PER_LUMEN_S = 1.35e16
FILTER_SHARE = 1.0 / 3.0  # a Bayer filter passes about a third of the visible band to its photodiode


def electrons_per_unit_second(sensor: ImageSensorConfig) -> float:
    """Electrons per second a pixel collects per channel from a surface of radiance 1 (renderer units)."""
    focal_lux = math.pi * sensor.lens_transmission * CD_M2_PER_UNIT / (4.0 * sensor.f_number ** 2)
    pixel_m2 = (sensor.pixel_pitch_um * 1e-6) ** 2
    return focal_lux * pixel_m2 * PHOTONS_PER_LUMEN_S * sensor.quantum_efficiency * FILTER_SHARE


@dataclass(frozen=True)
class Exposure:
    """One frame's exposure: time (s), analogue gain, and what they make of the radiance."""

    time_s: float
    gain: float
    scale: float  # the linear image per unit of radiance
    shot_scale: float  # variance per unit of image value: gain / full well
    read_variance: float  # (gain * read noise / full well)^2, in the image's units


def exposure_for(sensor: ImageSensorConfig, time_s: float, gain: float) -> Exposure:
    """The :class:`Exposure` of ``sensor`` at the exposure time ``time_s`` and the analogue gain ``gain``."""
    per_e = gain / sensor.full_well_e
    return Exposure(time_s=float(time_s), gain=float(gain),
                    scale=float(electrons_per_unit_second(sensor) * time_s * per_e),
                    shot_scale=float(per_e), read_variance=float((per_e * sensor.read_noise_e) ** 2))


AE_STEPS_PER_STOP = 16  # the auto-exposure's resolution: 1/16 of a stop (4.4 %)
METERING_FLOOR = 1e-8  # radiance units (1.2e-4 cd/m^2, darker than a natural night sky): keeps log 0 away


def log_average_luminance(radiance: np.ndarray) -> float:
    """The metering: the log-average Rec. 709 luminance of an (H, W, 3) float32 linear image over every 4th pixel
    and row (+METERING_FLOOR against log 0)."""
    sub = np.asarray(radiance, np.float32)[::4, ::4]
    return float(np.exp(np.mean(np.log(METERING_FLOOR + np.maximum(luminance(sub), 0.0).astype(np.float64)))))


def auto_exposure(radiance: np.ndarray, sensor: ImageSensorConfig, compensation: float = 1.0, *,
                  shaded_with: float = 1.0) -> Exposure:
    """The exposure the camera chooses for the (H, W, 3) float32 ``radiance`` (renderer units; already multiplied
    by ``shaded_with``, which the exposure divides out again: the light the sensor gets is the scene's): time
    first, then gain, each within its limits, aiming the image's log-average luminance at ``metering_key`` x
    ``compensation``."""
    wanted = sensor.metering_key * compensation  # the image's log-average luminance aimed at
    per_second = electrons_per_unit_second(sensor) / sensor.full_well_e  # image per unit radiance per second, gain 1
    scene = log_average_luminance(radiance / np.float32(shaded_with) if shaded_with != 1.0 else radiance)
    shortest, longest = sensor.exposure_time_s
    product = wanted / scene / per_second  # time x gain that would hit the key
    # In steps of 1/AE_STEPS_PER_STOP of a stop, as an exposure controller's registers take it (integration time in
    # rows, gain in steps): a frame whose metering barely changes (a few anti-aliased pixels) keeps its exposure.
    product = 2.0 ** (round(math.log2(product) * AE_STEPS_PER_STOP) / AE_STEPS_PER_STOP)
    time_s = min(max(product, shortest), longest)
    gain = min(max(product / time_s, 1.0), sensor.max_gain)
    return exposure_for(sensor, time_s, gain)
