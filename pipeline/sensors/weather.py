"""The physics of fog and rain that every sensor takes its weather from: extinction, drop sizes and speeds, water on
the road. Pure functions of a condition's physical values (visibility in metres, rain rate in mm/h); the camera
(:mod:`pipeline.sensors.conditions`, :mod:`pipeline.sensors.rain`, :mod:`pipeline.sensors.wet`), the LiDAR
(:mod:`pipeline.sensors.lidar`) and the radar (:mod:`pipeline.sensors.radar`, ITU-R models of its own) read them.

- **Fog** (Koschmieder): the extinction coefficient beta = 3.912 / V for a meteorological visibility V (2 % contrast).
  At another wavelength, Kim, McArthur and Korevaar (2001, SPIE 4214): beta(lambda) = 3.912 / V (lambda / 550 nm)^-q
  with q = 0 for V < 0.5 km (fog droplets are large against the wavelength), V - 0.5 up to 1 km, 0.16 V + 0.34 up to
  6 km, 1.3 beyond (V in km).
- **Rain**: drop diameters D follow Marshall and Palmer (1948), N(D) = N0 exp(-Lambda D), N0 = 8000 m^-3 mm^-1,
  Lambda = 4.1 R^-0.21 mm^-1 for a rate R in mm/h. Drops are large against visible and near-infrared wavelengths, so
  each removes twice its cross-section from a beam (the extinction paradox, Q_ext = 2): beta = integral of
  2 (pi D^2 / 4) N(D) dD = pi N0 / Lambda^3, i.e. 0.37 R^0.63 per km (visibility 2.5 km at 10 mm/h, 0.9 km at
  50 mm/h), the same for the camera and the LiDAR. Drops fall at their terminal speed, v(D) = 9.65 - 10.3
  exp(-0.6 D) m/s (Atlas, Srivastava and Sekhon 1973, D in mm).
- **Water on the road**: Gallaway's water film depth (Gallaway et al. 1979, FHWA-RD-79-31, in metric form):
  WFD = 0.01485 T^0.11 L^0.43 I^0.59 S^-0.42 - T (mm) for a macrotexture depth T (mm), a drainage path L (m), a
  rainfall intensity I (mm/h) and a cross slope S (m/m). The road's wetness w is the share of its texture the water
  fills, (WFD + T) / T, at most 1: above 1 the texture is drowned and the road a mirror sheet.
"""

from __future__ import annotations

import math

import numpy as np

KOSCHMIEDER = 3.912  # -ln(0.02): contrast threshold of 2 %
VISIBLE_NM = 550.0
MP_N0_PER_M3_MM = 8000.0  # Marshall-Palmer intercept
# The road's water (Gallaway's formula): dense asphalt's mean texture depth (0.5-1.0 mm), one lane to the kerb or
# crown, the usual 2.5 % cross fall.
ROAD_TEXTURE_DEPTH_MM = 0.7
ROAD_DRAINAGE_PATH_M = 3.5
ROAD_CROSS_SLOPE = 0.025


def fog_extinction_per_m(visibility_m: float, wavelength_nm: float = VISIBLE_NM) -> float:
    """Fog's extinction coefficient, 1/m, at ``wavelength_nm`` for a meteorological ``visibility_m``
    (Koschmieder; Kim et al. 2001 away from 550 nm)."""
    if not visibility_m > 0:
        raise ValueError(f"visibility must be > 0 metres, got {visibility_m}")
    v_km = visibility_m / 1000.0
    if v_km < 0.5:
        q = 0.0
    elif v_km < 1.0:
        q = v_km - 0.5
    elif v_km < 6.0:
        q = 0.16 * v_km + 0.34
    else:
        q = 1.3
    return KOSCHMIEDER / visibility_m * (wavelength_nm / VISIBLE_NM) ** -q


def marshall_palmer_slope_per_mm(rate_mm_h: float) -> float:
    """Lambda of the Marshall-Palmer drop-size distribution, 1/mm, at ``rate_mm_h`` > 0."""
    return 4.1 * rate_mm_h ** -0.21


def drops_per_m3(rate_mm_h: float, min_diameter_mm: float = 0.0) -> float:
    """Raindrops per cubic metre with a diameter of at least ``min_diameter_mm``, at ``rate_mm_h``."""
    if rate_mm_h <= 0:
        return 0.0
    lam = marshall_palmer_slope_per_mm(rate_mm_h)
    return MP_N0_PER_M3_MM / lam * math.exp(-lam * min_diameter_mm)


def rain_extinction_per_m(rate_mm_h: float) -> float:
    """Rain's extinction coefficient, 1/m (geometric optics, Q_ext = 2, any wavelength well below the drops')."""
    if rate_mm_h <= 0:
        return 0.0
    return math.pi * MP_N0_PER_M3_MM / marshall_palmer_slope_per_mm(rate_mm_h) ** 3 * 1e-6


def terminal_velocity_mps(diameter_mm):
    """A raindrop's terminal fall speed, m/s (Atlas et al. 1973), of diameters in mm (arrays or floats)."""
    return np.maximum(9.65 - 10.3 * np.exp(-0.6 * np.asarray(diameter_mm, np.float64)), 0.0)


def water_film_depth_mm(rate_mm_h: float, texture_mm: float = ROAD_TEXTURE_DEPTH_MM,
                        drainage_m: float = ROAD_DRAINAGE_PATH_M, slope: float = ROAD_CROSS_SLOPE) -> float:
    """Gallaway's water film depth above the texture's peaks, mm (negative: the water stays within the texture)."""
    if rate_mm_h <= 0:
        return -texture_mm
    return 0.01485 * texture_mm ** 0.11 * drainage_m ** 0.43 * rate_mm_h ** 0.59 * slope ** -0.42 - texture_mm


def road_wetness(rate_mm_h: float, texture_mm: float = ROAD_TEXTURE_DEPTH_MM) -> float:
    """The share of the road's texture the rain's water fills, 0 (dry) .. 1 (drowned: a mirror sheet)."""
    if rate_mm_h <= 0:
        return 0.0
    return min(1.0, (water_film_depth_mm(rate_mm_h, texture_mm) + texture_mm) / texture_mm)


def road_water_mm(rate_mm_h: float, texture_mm: float = ROAD_TEXTURE_DEPTH_MM) -> float:
    """The water a road holds at ``rate_mm_h``, mm: what fills its texture plus Gallaway's film above the texture's
    peaks (the water a tyre meets); 0 without rain."""
    if rate_mm_h <= 0:
        return 0.0
    return max(water_film_depth_mm(rate_mm_h, texture_mm) + texture_mm, 0.0)
