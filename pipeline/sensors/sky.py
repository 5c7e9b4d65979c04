"""The sky: the radiance of a direction that meets nothing, for camera rays, mirror rays and the wet road's sheen.

One representation serves every place that sees the sky: a condition's sky is a (SKY_PARAMS,) float32 parameter
vector (:func:`sky_params`, built once per condition), and one compiled function, :func:`sky_radiance`, turns a
direction into radiance from it. The compiled passes call it directly (:func:`pipeline.sensors.sunlight.sky_and_sun`
for camera and mirror rays that miss); numpy code calls :func:`sky_rays`.

Two models (``sky.model`` of :class:`pipeline.core.config.sensors.SkyConfig`):

- **gradient**: horizon + (zenith - horizon) * sqrt(up) for the direction's upward component ``up`` (clipped to
  [0, 1]), from the configured ``zenith_rgb`` and ``horizon_rgb``; the same whatever the sun does. Night, fog and
  rain keep it.
- **preetham**: the analytic daylight model of Preetham, Shirley and Smits (1999, "A Practical Analytic Model for
  Daylight", appendix A.2), from the sun's direction and the air's ``turbidity`` T. Luminance Y and chromaticity
  x, y each follow Perez et al.'s distribution F(theta, gamma) = (1 + A e^(B / cos theta)) (1 + C e^(D gamma) +
  E cos^2 gamma) of the view's zenith angle theta and its angle gamma from the sun, with coefficients linear in T,
  relative to the zenith: Y = Y_z F(theta, gamma) / F(0, theta_s); Y_z (kcd/m^2) and x_z, y_z are the paper's
  formulas of T and the sun's zenith angle theta_s. xyY becomes CIE XYZ and then linear sRGB (Rec. 709
  primaries, D65 white), the renderer's RGB. The sky is brightest and whitest around the sun and towards the
  horizon, deepest blue overhead and away from the sun. Directions below the horizon (a mirror ray pointing down
  that meets nothing) see the horizon above them, as in the gradient.

Scale: the paper's luminance is absolute (kcd/m^2); the renderer's radiance is relative (~1 = white paper in full
sun at exposure 1), and its sun (``sun.intensity``) and sky fill (``sky.ambient_rgb``) are set per condition. The
model is scaled so that its cosine-weighted mean luminance over the upper hemisphere, the irradiance it gives a
surface facing up divided by pi, equals the Rec. 709 luminance of ``ambient_rgb``: the sky one sees gives the fill
light the condition sets, and a frame's exposure stays where it was (for the shipped day conditions the gradient's
own cosine-weighted mean lies within 20 % of their ambient). The ambient keeps its configured colour: it stands for
the sky and for the light that sunlit ground and walls bounce (warm), which the renderer does not trace; the pure
sky's mean colour would make every shadow much bluer (at noon blue/red 2.5 instead of 1.3).
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import as_input, kernel
from pipeline.sensors.post import luminance

SKY_MODELS = ("gradient", "preetham")
# The parameter vector: [model, zenith rgb, horizon rgb, sun direction, Perez A..E for Y, x, y, zenith value / F(0,
# theta_s) for Y, x, y, scale]. Unused entries are 0.
_MODEL, _ZENITH, _HORIZON, _SUN, _PEREZ, _ZENITH_YXY, _SCALE = 0, 1, 4, 7, 10, 25, 28
SKY_PARAMS = 29
# CIE XYZ -> linear sRGB (IEC 61966-2-1; Rec. 709 primaries, D65 white).
XYZ_TO_RGB = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])
MIN_COS_ZENITH = 1e-3  # the Perez term e^(B / cos theta) is taken at no lower cos theta (it is ~0 there already)
# Perez coefficients (rows A..E) as (slope, intercept) in the turbidity T: Preetham et al. 1999, appendix A.2.
_PEREZ_Y = ((0.1787, -1.4630), (-0.3554, 0.4275), (-0.0227, 5.3251), (0.1206, -2.5771), (-0.0670, 0.3703))
_PEREZ_X = ((-0.0193, -0.2592), (-0.0665, 0.0008), (-0.0004, 0.2125), (-0.0641, -0.8989), (-0.0033, 0.0452))
_PEREZ_SMALL_Y = ((-0.0167, -0.2608), (-0.0950, 0.0092), (-0.0079, 0.2102), (-0.0441, -1.6537), (-0.0109, 0.0529))
# Zenith chromaticity: x_z = [T^2, T, 1] M [theta_s^3, theta_s^2, theta_s, 1]^T (same appendix).
_ZENITH_X = np.array([[0.00166, -0.00375, 0.00209, 0.0], [-0.02903, 0.06377, -0.03202, 0.00394],
                      [0.11693, -0.21196, 0.06052, 0.25886]])
_ZENITH_SMALL_Y = np.array([[0.00275, -0.00610, 0.00317, 0.0], [-0.04214, 0.08970, -0.04153, 0.00516],
                            [0.15346, -0.26756, 0.06670, 0.26688]])


def perez_coefficients(turbidity: float) -> np.ndarray:
    """(3, 5) float64: the Perez coefficients A..E of the luminance Y and the chromaticities x, y (rows)."""
    t = float(turbidity)
    return np.array([[a * t + b for a, b in rows] for rows in (_PEREZ_Y, _PEREZ_X, _PEREZ_SMALL_Y)])


def perez(coefficients: np.ndarray, theta: np.ndarray, gamma: np.ndarray) -> np.ndarray:
    """Perez et al.'s F(theta, gamma) = (1 + A e^(B / cos theta)) (1 + C e^(D gamma) + E cos^2 gamma) for the (5,)
    ``coefficients`` A..E, the view's zenith angle ``theta`` and its angle ``gamma`` from the sun (radians, any
    broadcastable shapes; float64)."""
    a, b, c, d, e = coefficients
    cos_theta = np.maximum(np.cos(theta), MIN_COS_ZENITH)
    return (1.0 + a * np.exp(b / cos_theta)) * (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2)


def zenith_luminance_kcd(turbidity: float, sun_zenith_rad: float) -> float:
    """The zenith's luminance Y_z (kcd/m^2): (4.0453 T - 4.9710) tan chi - 0.2155 T + 2.4192, chi = (4/9 - T/120)
    (pi - 2 theta_s)."""
    t = float(turbidity)
    chi = (4.0 / 9.0 - t / 120.0) * (np.pi - 2.0 * sun_zenith_rad)
    return float((4.0453 * t - 4.9710) * np.tan(chi) - 0.2155 * t + 2.4192)


def zenith_chromaticity(turbidity: float, sun_zenith_rad: float) -> tuple[float, float]:
    """The zenith's CIE chromaticity (x_z, y_z) for the turbidity and the sun's zenith angle (radians)."""
    t, s = float(turbidity), float(sun_zenith_rad)
    tt, ss = np.array([t * t, t, 1.0]), np.array([s ** 3, s ** 2, s, 1.0])
    return float(tt @ _ZENITH_X @ ss), float(tt @ _ZENITH_SMALL_Y @ ss)


def xyy_to_rgb(x: np.ndarray, y: np.ndarray, luminance: np.ndarray) -> np.ndarray:
    """(..., 3) float64 linear sRGB of chromaticities x, y and luminance Y (broadcastable): xyY -> XYZ -> RGB."""
    xyz = np.stack(np.broadcast_arrays(x / y * luminance, luminance, (1.0 - x - y) / y * luminance), axis=-1)
    return xyz @ XYZ_TO_RGB.T


def gradient_params(zenith_rgb, horizon_rgb) -> np.ndarray:
    """(SKY_PARAMS,) float32 parameters of the gradient sky between the (3,) zenith and horizon colours."""
    params = np.zeros(SKY_PARAMS, np.float32)
    params[_ZENITH:_ZENITH + 3] = zenith_rgb
    params[_HORIZON:_HORIZON + 3] = horizon_rgb
    return params


def preetham_params(sun: np.ndarray, turbidity: float, mean_luminance: float) -> np.ndarray:
    """(SKY_PARAMS,) float32 parameters of the Preetham sky for the unit direction ``sun`` (3,) (above the horizon)
    and ``turbidity``, scaled so that its cosine-weighted mean luminance over the upper hemisphere is
    ``mean_luminance`` (see the module docstring)."""
    sun = np.asarray(sun, np.float64)
    if not sun[2] > 0:
        raise ValueError(f"the Preetham sky needs the sun above the horizon, got the direction {sun.tolist()}")
    theta_s = float(np.arccos(min(sun[2], 1.0)))
    coefficients = perez_coefficients(turbidity)
    zenith = np.array([zenith_luminance_kcd(turbidity, theta_s), *zenith_chromaticity(turbidity, theta_s)])
    params = np.zeros(SKY_PARAMS, np.float32)
    params[_MODEL] = 1.0
    params[_SUN:_SUN + 3] = sun
    params[_PEREZ:_PEREZ + 15] = coefficients.reshape(-1)
    params[_ZENITH_YXY:_ZENITH_YXY + 3] = zenith / [perez(c, 0.0, theta_s) for c in coefficients]
    params[_SCALE] = 1.0
    unscaled = float(luminance(sky_rays(_COSINE_DIRECTIONS, params).astype(np.float64)).mean())
    params[_SCALE] = mean_luminance / unscaled
    return params


def _cosine_directions(rings: int = 64, per_ring: int = 128) -> np.ndarray:
    """(rings * per_ring, 3) float32 directions over the upper hemisphere with equal cosine-weighted solid angle
    each (the midpoints of equal-area cells of the unit disc, lifted onto the hemisphere): their plain mean of a
    function is its cosine-weighted mean."""
    r = np.sqrt((np.arange(rings) + 0.5) / rings)[:, None]
    phi = (2.0 * np.pi * (np.arange(per_ring) + 0.5) / per_ring)[None, :]
    x, y = r * np.cos(phi), r * np.sin(phi)
    z = np.sqrt(1.0 - r * r) * np.ones_like(phi)
    return np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)


@kernel("float32(float32[::1], int64, float32, float32, float32)")
def _perez_relative(params, k, cos_theta, gamma, cos_gamma):
    """Quantity ``k`` (0: Y, 1: x, 2: y) of the Preetham sky ``params``: its zenith value / F(0, theta_s) times
    F(theta, gamma) (:func:`perez`, in float32)."""
    p = _PEREZ + 5 * k
    a, b, c, d, e = params[p], params[p + 1], params[p + 2], params[p + 3], params[p + 4]
    f = (np.float32(1) + a * np.exp(b / cos_theta)) * (
        np.float32(1) + c * np.exp(d * gamma) + e * cos_gamma * cos_gamma)
    return params[_ZENITH_YXY + k] * f


@kernel("UniTuple(float32, 3)(float32, float32, float32, float32[::1])")
def sky_radiance(d0, d1, d2, params):
    """Linear RGB (float32) of the sky in the unit direction (d0, d1, d2), world frame (z up), for the parameters
    ``params`` ((SKY_PARAMS,) float32: :func:`gradient_params` or :func:`preetham_params`)."""
    up = min(max(d2, np.float32(0)), np.float32(1))
    if params[_MODEL] == 0:
        s = np.sqrt(up)
        return (params[_HORIZON] + (params[_ZENITH] - params[_HORIZON]) * s,
                params[_HORIZON + 1] + (params[_ZENITH + 1] - params[_HORIZON + 1]) * s,
                params[_HORIZON + 2] + (params[_ZENITH + 2] - params[_HORIZON + 2]) * s)
    # Below the horizon: the horizon above the direction.
    norm = np.sqrt(d0 * d0 + d1 * d1 + up * up)
    cos_gamma = np.float32(0)
    if norm > 0:
        cos_gamma = (d0 * params[_SUN] + d1 * params[_SUN + 1] + up * params[_SUN + 2]) / norm
        up = up / norm
    cos_gamma = min(max(cos_gamma, np.float32(-1)), np.float32(1))
    gamma = np.arccos(cos_gamma)
    cos_theta = max(up, np.float32(MIN_COS_ZENITH))
    lum = _perez_relative(params, 0, cos_theta, gamma, cos_gamma) * params[_SCALE]
    x = _perez_relative(params, 1, cos_theta, gamma, cos_gamma)
    y = _perez_relative(params, 2, cos_theta, gamma, cos_gamma)
    big_x = x / y * lum
    big_z = (np.float32(1) - x - y) / y * lum
    r = np.float32(3.2406) * big_x - np.float32(1.5372) * lum - np.float32(0.4986) * big_z
    g = np.float32(-0.9689) * big_x + np.float32(1.8758) * lum + np.float32(0.0415) * big_z
    bl = np.float32(0.0557) * big_x - np.float32(0.2040) * lum + np.float32(1.0570) * big_z
    return max(r, np.float32(0)), max(g, np.float32(0)), max(bl, np.float32(0))


@kernel("float32[:, ::1](float32[:, ::1], float32[::1])")
def _sky_rays(directions, params):
    out = np.empty((directions.shape[0], 3), np.float32)
    for i in range(directions.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = sky_radiance(directions[i, 0], directions[i, 1], directions[i, 2], params)
    return out


def sky_rays(directions: np.ndarray, params: np.ndarray) -> np.ndarray:
    """(N, 3) float32 sky radiance of (N, 3) unit directions (world frame) for the sky ``params``."""
    return _sky_rays(as_input(directions, np.float32).reshape(-1, 3), as_input(params, np.float32))


_COSINE_DIRECTIONS = _cosine_directions()
