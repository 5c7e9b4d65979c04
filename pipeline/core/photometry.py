"""The renderer's linear units in photometric units, and back.

The renderer shades in relative linear RGB: a Lambertian surface of albedo rho under an irradiance E (in the
renderer's units) has the radiance rho * E, and the day conditions' sun has the intensity 2.6. That scale is tied
to the world by one anchor, the sun: **intensity 2.6 is a direct-beam illuminance of 100,000 lx** (the clear-sky
sun high in the sky; the figure lighting handbooks give for direct sunlight, e.g. the IES Lighting Handbook's
"direct sunlight 32,000-100,000 lx"). Hence

- an irradiance of 1 unit is LUX_PER_UNIT = 100,000 / 2.6 = 38,462 lx;
- a radiance of 1 unit is CD_M2_PER_UNIT = LUX_PER_UNIT / pi = 12,243 cd/m^2 (white paper, rho = 1, under
  1 unit of irradiance: L = rho E / pi);
- a spot light's intensity (the irradiance it gives at 1 m, in units) of 1 is LUX_PER_UNIT candela.

Luminance here is the Rec. 709 Y of the linear RGB (the renderer's primaries). With these, the night conditions'
lights are given in candela, lux and cd/m^2 (configs/conditions/*.yaml) and the camera's sensor counts electrons
from them (:mod:`pipeline.sensors.exposure`).
"""

from __future__ import annotations

import math

SUN_ANCHOR_INTENSITY = 2.6  # the day conditions' sun.intensity ...
SUN_ANCHOR_LUX = 100_000.0  # ... is this direct-beam illuminance
LUX_PER_UNIT = SUN_ANCHOR_LUX / SUN_ANCHOR_INTENSITY
CD_M2_PER_UNIT = LUX_PER_UNIT / math.pi


def candela_to_intensity(candela: float) -> float:
    """A light's luminous intensity (cd) as the renderer's intensity (irradiance at 1 m, units)."""
    return candela / LUX_PER_UNIT


def lux_to_irradiance(lux: float) -> float:
    """Illuminance (lx) as the renderer's irradiance (units)."""
    return lux / LUX_PER_UNIT


def luminance_to_radiance(cd_m2: float) -> float:
    """Luminance (cd/m^2) as the renderer's radiance (units)."""
    return cd_m2 / CD_M2_PER_UNIT


def radiance_to_luminance(radiance: float) -> float:
    """The renderer's radiance (units) as luminance (cd/m^2)."""
    return radiance * CD_M2_PER_UNIT


# The clear-sky sun (IES Lighting Handbook, daylight chapter): a direct normal illuminance E = E0 exp(-c m) with the
# extraterrestrial solar illuminance E0 and the atmosphere's extinction coefficient c for a clear sky, m the relative
# air mass at the sun's elevation (Kasten and Young 1989). At 65 degrees it gives the anchor's 100 klx within 1 %.
SOLAR_ILLUMINANCE_LUX = 127_500.0
CLEAR_SKY_EXTINCTION = 0.21


def air_mass(elevation_deg: float) -> float:
    """The relative optical air mass towards a sun ``elevation_deg`` above the horizon (Kasten and Young 1989)."""
    if elevation_deg <= 0:
        raise ValueError(f"the sun must be above the horizon for an air mass, got an elevation of {elevation_deg} deg")
    return 1.0 / (math.sin(math.radians(elevation_deg)) + 0.50572 * (elevation_deg + 6.07995) ** -1.6364)


def clear_sky_sun_lux(elevation_deg: float) -> float:
    """The clear-sky sun's direct normal illuminance, lx, at ``elevation_deg`` (0 at or below the horizon)."""
    if elevation_deg <= 0:
        return 0.0
    return SOLAR_ILLUMINANCE_LUX * math.exp(-CLEAR_SKY_EXTINCTION * air_mass(elevation_deg))
