"""The sun's and the sky's share of a camera frame's radiance: a compiled pass over the rays.

:func:`pipeline.sensors.shading.shade` calls :func:`pipeline.sensors.shadows.sun_rays` for the hits that face the sun
and the shadow rays that start from them (each towards a point of the sun's disc), casts those, then
:func:`sky_and_sun` for ``albedo * (ambient + sun * n.l * sunlit) + sun * specular * sunlit`` on hits and the sky
(:mod:`pipeline.sensors.sky`) on misses. In numpy these were ~25 array passes over the image's rays; compiled
(:mod:`pipeline.core.jit`), two (this one and ``sun_rays``). All arithmetic is float32, as it was in numpy.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import kernel
from pipeline.sensors.sky import sky_radiance


@kernel("float32(float32, float32)")
def _power(x, exponent):
    """``x ** exponent`` (float32): by repeated squaring for whole exponents up to 1024 (every material's
    shininess; much faster than powf, within a few float32 ulps of it), else powf."""
    if not (exponent == np.floor(exponent) and 0 < exponent <= 1024):
        return x ** exponent
    n = np.int64(exponent)
    result = np.float32(1)
    base = x
    while n > 0:
        if n & 1:
            result *= base
        base *= base
        n >>= 1
    return result


@kernel("float32[:, ::1](float32[:, ::1], bool_[::1], float32[:, ::1], int32[::1], float32[:, ::1], float32[::1], "
        "int64[::1], float32[::1], float32[::1], float32[::1], float32[::1], float32[::1], float32[::1], "
        "float32[::1])")
def sky_and_sun(rays, hit, normal, material, color, n_dot_l, lit, sunlit, specular, shininess, sun, sun_rgb,
                ambient_rgb, sky):
    """(N, 3) float32 linear radiance: on hits, ``color * (ambient + sun_rgb * max(n.l, 0) * sunlit) + sun_rgb *
    specular * sunlit``, the highlight Blinn-Phong, ``specular[m] * clip(n.h, 0, 1) ** shininess[m]``
    (:func:`_power`) with h the half-vector of the sun and the view direction, on sunlit hits of materials m with
    specular > 0; on misses, the sky (:func:`pipeline.sensors.sky.sky_radiance` of the ray's direction).

    Args:
        rays: (N, 6) float32; hit: (N,) bool; normal: (N, 3) float32; material: (N,) int32; color: (N, 3)
            float32 albedo.
        n_dot_l, lit: from :func:`sun_rays`; sunlit: (M,) float32 per ``lit`` ray, the share of the sun's disc its
            shadow rays saw (1 unshadowed, 0 in full shadow).
        specular, shininess: (K,) float32 per material. sun: (3,) float32 towards the sun. sun_rgb, ambient_rgb:
            (3,) float32 linear RGB. sky: (SKY_PARAMS,) float32 (:mod:`pipeline.sensors.sky`).
    """
    n = hit.size
    direct = np.empty(n, np.float32)
    for i in range(n):
        direct[i] = max(n_dot_l[i], np.float32(0))
    spec = np.zeros(n, np.float32)
    for j in range(lit.size):
        i = lit[j]
        share = sunlit[j]
        if not share > 0:
            direct[i] = 0
            continue
        if share < 1:
            direct[i] *= share
        m = material[i]
        if not specular[m] > 0:
            continue
        h0, h1, h2 = sun[0] - rays[i, 3], sun[1] - rays[i, 4], sun[2] - rays[i, 5]
        n_dot_h = (normal[i, 0] * h0 + normal[i, 1] * h1 + normal[i, 2] * h2) / (
            np.sqrt(h0 * h0 + h1 * h1 + h2 * h2) + np.float32(1e-12))
        n_dot_h = min(max(n_dot_h, np.float32(0)), np.float32(1))
        spec[i] = specular[m] * _power(n_dot_h, shininess[m])
        if share < 1:
            spec[i] *= share
    out = np.empty((n, 3), np.float32)
    for i in range(n):
        if hit[i]:
            for k in range(3):
                out[i, k] = color[i, k] * (ambient_rgb[k] + sun_rgb[k] * direct[i]) + sun_rgb[k] * spec[i]
        else:
            out[i, 0], out[i, 1], out[i, 2] = sky_radiance(rays[i, 3], rays[i, 4], rays[i, 5], sky)
    return out
