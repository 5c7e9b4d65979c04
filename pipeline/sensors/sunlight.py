"""The sun's and the sky's share of a camera frame's radiance: two compiled passes over the rays.

:func:`pipeline.sensors.shading.shade` calls :func:`sun_rays` for the hits that face the sun and the shadow rays
that start from them, casts those, then :func:`sky_and_sun` for ``albedo * (ambient + sun * n.l) + sun *
specular`` on hits and the sky on misses. In numpy these were ~25 array passes over the image's rays; compiled
(:mod:`pipeline.core.jit`), two. All arithmetic is float32, as it was in numpy.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import kernel


@kernel("Tuple((float32[::1], int64[::1], float32[:, ::1]))(float32[:, ::1], float32[:, ::1], float32[::1], "
        "float32[::1])")
def sun_rays(rays, normal, t_m, sun):
    """The hits facing the sun, and their shadow rays.

    Args:
        rays: (N, 6) float32 camera rays [origin | unit direction], world frame.
        normal: (N, 3) float32 hit normals (0 for misses); t_m: (N,) float32 hit distances.
        sun: (3,) float32 unit vector towards the sun.

    Returns:
        n_dot_l: (N,) float32 normal . sun (0 for misses).
        lit: (M,) int64 the rays with n_dot_l > 0, ascending.
        shadow: (M, 6) float32 their shadow rays [origin | sun]: from the hit point lifted off the surface along
        the normal by 1 mm + 0.1 mm per metre of distance (against self-intersection).
    """
    n = t_m.size
    n_dot_l = np.empty(n, np.float32)
    count = 0
    for i in range(n):
        d = normal[i, 0] * sun[0] + normal[i, 1] * sun[1] + normal[i, 2] * sun[2]
        n_dot_l[i] = d
        if d > 0:
            count += 1
    lit = np.empty(count, np.int64)
    shadow = np.empty((count, 6), np.float32)
    j = 0
    for i in range(n):
        if n_dot_l[i] > 0:
            lit[j] = i
            t = t_m[i]
            lift = np.float32(1e-3) + np.float32(1e-4) * t
            for k in range(3):
                shadow[j, k] = rays[i, k] + rays[i, 3 + k] * t + normal[i, k] * lift
                shadow[j, 3 + k] = sun[k]
            j += 1
    return n_dot_l, lit, shadow


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
        "int64[::1], bool_[::1], float32[::1], float32[::1], float32[::1], float32[::1], float32[::1], "
        "float32[::1], float32[::1])")
def sky_and_sun(rays, hit, normal, material, color, n_dot_l, lit, unshadowed, specular, shininess, sun, sun_rgb,
                ambient_rgb, zenith_rgb, horizon_rgb):
    """(N, 3) float32 linear radiance: on hits, ``color * (ambient + sun_rgb * max(n.l, 0) * unshadowed) + sun_rgb *
    specular``, the highlight Blinn-Phong, ``specular[m] * clip(n.h, 0, 1) ** shininess[m]`` (:func:`_power`)
    with h the half-vector of the sun and the view direction, on unshadowed sunlit hits of materials m with
    specular > 0; on misses, the sky: horizon + (zenith - horizon) * sqrt(clip(up, 0, 1)) for the ray's upward
    component.

    Args:
        rays: (N, 6) float32; hit: (N,) bool; normal: (N, 3) float32; material: (N,) int32; color: (N, 3)
            float32 albedo.
        n_dot_l, lit: from :func:`sun_rays`; unshadowed: (M,) bool per ``lit`` ray, its shadow ray was not blocked.
        specular, shininess: (K,) float32 per material. sun: (3,) float32 towards the sun. sun_rgb, ambient_rgb,
            zenith_rgb, horizon_rgb: (3,) float32 linear RGB.
    """
    n = hit.size
    direct = np.empty(n, np.float32)
    for i in range(n):
        direct[i] = max(n_dot_l[i], np.float32(0))
    spec = np.zeros(n, np.float32)
    for j in range(lit.size):
        i = lit[j]
        if not unshadowed[j]:
            direct[i] = 0
            continue
        m = material[i]
        if not specular[m] > 0:
            continue
        h0, h1, h2 = sun[0] - rays[i, 3], sun[1] - rays[i, 4], sun[2] - rays[i, 5]
        n_dot_h = (normal[i, 0] * h0 + normal[i, 1] * h1 + normal[i, 2] * h2) / (
            np.sqrt(h0 * h0 + h1 * h1 + h2 * h2) + np.float32(1e-12))
        n_dot_h = min(max(n_dot_h, np.float32(0)), np.float32(1))
        spec[i] = specular[m] * _power(n_dot_h, shininess[m])
    out = np.empty((n, 3), np.float32)
    for i in range(n):
        if hit[i]:
            for k in range(3):
                out[i, k] = color[i, k] * (ambient_rgb[k] + sun_rgb[k] * direct[i]) + sun_rgb[k] * spec[i]
        else:
            up = np.sqrt(min(max(rays[i, 5], np.float32(0)), np.float32(1)))
            for k in range(3):
                out[i, k] = horizon_rgb[k] + (zenith_rgb[k] - horizon_rgb[k]) * up
    return out
