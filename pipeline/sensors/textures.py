"""Procedural surface textures of the static world: albedo varied by position, as a photograph shows it.

Flat albedo reads as a diagram: real asphalt has grain, darker repair patches and cracks; markings are worn;
grass has dry and lush patches; concrete and façades weather; brick walls are courses of bricks, each its own shade,
in lighter mortar; behind window glass lie darker and lighter rooms, blinds have slats; foliage is clumps of light
and shade. Each
textured material multiplies (or, for worn markings, blends) its albedo by a function of the hit's world
position: sums of value-noise octaves (a hashed lattice, smoothly interpolated), written here, so a surface looks
the same from every frame and every camera, and the same seed-free pattern is reproducible bit for bit.

Anti-aliasing: an octave finer than the pixel's footprint on the surface would only add noise that flickers
between frames, so each octave fades out as its wavelength falls from 4 to 2 footprints (footprint = distance x
the pixel's angle / cos(incidence), the cosine floored at 0.2). Far road is smooth, near road is grainy.

Only static hits (``instance_id == 0``) are textured; actors keep their paint. Only the camera's albedo changes:
ground truth, depth and the LiDAR's reflectivity do not. The ``realistic`` camera quality textures; ``fast``
does not (:mod:`pipeline.sensors.render`).
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import as_input, kernel
from pipeline.world.materials import MATERIAL_NAMES, material_arrays, material_index

# Texture kinds per material (0 = flat).
FLAT, ASPHALT, MARKING, GRASS, WEATHERED, FOLIAGE, WINDOW, BLIND, BRICK = range(9)
TEXTURE_OF_MATERIAL = {
    "asphalt": ASPHALT,
    "lane_paint": MARKING,
    "grass": GRASS,
    "concrete": WEATHERED, "kerb": WEATHERED, "barrier": WEATHERED, "building": WEATHERED,
    "building_light": WEATHERED, "building_dark": WEATHERED, "plaster_white": WEATHERED, "plaster_ochre": WEATHERED,
    "plaster_grey": WEATHERED, "plaster_rose": WEATHERED,
    "brick": BRICK, "brick_dark": BRICK,
    "foliage": FOLIAGE, "foliage_light": FOLIAGE, "foliage_dark": FOLIAGE,
    "building_glass": WINDOW, "glass_tinted": WINDOW, "window_lit": WINDOW,
    "window_blind": BLIND,
}
# Brick courses: 65 mm bricks and 10 mm joints (a 75 mm course), 215 mm bricks in running bond; mortar is lighter.
BRICK_COURSE_M, BRICK_LENGTH_M, JOINT_M = 0.075, 0.225, 0.01
MORTAR_RGB = np.array([0.50, 0.48, 0.44], np.float32)
MIN_COS_INCIDENCE = 0.2  # grazing hits count their footprint as at this cosine (the road far ahead)


def _kinds() -> np.ndarray:
    kinds = np.zeros(len(MATERIAL_NAMES), np.int8)
    for name, kind in TEXTURE_OF_MATERIAL.items():
        kinds[material_index(name)] = kind
    return kinds


_KINDS = _kinds()
_ASPHALT_RGB = material_arrays()["albedo"][material_index("asphalt")].copy()


def textured_albedo(rays: np.ndarray, t_m: np.ndarray, hit: np.ndarray, instance_id: np.ndarray,
                    material: np.ndarray, normal: np.ndarray, color: np.ndarray, pixel_angle_rad: float) -> np.ndarray:
    """(N, 3) float32 albedo of N camera hits with the static world's textures applied (a new array).

    ``rays`` (N, 6) float32 [origin | unit direction], world frame; ``t_m``, ``hit``, ``instance_id``, ``material``,
    ``normal`` and ``color`` as in :class:`pipeline.world.scene.Hits`; ``pixel_angle_rad``: the angle one pixel
    subtends (1 / focal length in pixels), which sets each hit's footprint.
    """
    if pixel_angle_rad <= 0:
        raise ValueError(f"pixel_angle_rad must be positive, got {pixel_angle_rad}")
    return _texture(as_input(rays, np.float32), as_input(t_m, np.float32), as_input(hit, bool),
                    as_input(instance_id, np.int32), as_input(material, np.int32), as_input(normal, np.float32),
                    as_input(color, np.float32), _KINDS, _ASPHALT_RGB, MORTAR_RGB, np.float64(pixel_angle_rad))


@kernel("float64(int64, int64, int64, int64)")
def _lattice(ix, iy, iz, seed):
    """A value in [-1, 1) hashed from a lattice point (integer mixing, the same on every machine)."""
    h = (ix * 0x27D4EB2D + iy * 0x165667B1 + iz * 0x61C88647 + seed * 0x9E3779B1) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x2C1B3C6D) & 0xFFFFFFFF
    h ^= h >> 12
    h = (h * 0x297A2D39) & 0xFFFFFFFF
    h ^= h >> 15
    return h * (2.0 / 4294967296.0) - 1.0


@kernel("float64(float64)")
def _smooth(f):
    return f * f * (3.0 - 2.0 * f)


@kernel("float64(float64, float64, int64)")
def noise2(x, y, seed):
    """Value noise in [-1, 1] at (x, y) (lattice spacing 1), smoothly interpolated."""
    fx, fy = np.floor(x), np.floor(y)
    ix, iy = np.int64(fx), np.int64(fy)
    u, v = _smooth(x - fx), _smooth(y - fy)
    a = _lattice(ix, iy, 0, seed) + u * (_lattice(ix + 1, iy, 0, seed) - _lattice(ix, iy, 0, seed))
    b = _lattice(ix, iy + 1, 0, seed) + u * (_lattice(ix + 1, iy + 1, 0, seed) - _lattice(ix, iy + 1, 0, seed))
    return a + v * (b - a)


@kernel("float64(float64, float64, float64, int64)")
def noise3(x, y, z, seed):
    """Value noise in [-1, 1] at (x, y, z) (lattice spacing 1), smoothly interpolated."""
    fz = np.floor(z)
    iz = np.int64(fz)
    w = _smooth(z - fz)
    fx, fy = np.floor(x), np.floor(y)
    ix, iy = np.int64(fx), np.int64(fy)
    u, v = _smooth(x - fx), _smooth(y - fy)
    out = 0.0
    for dz in range(2):
        k = iz + dz
        a = _lattice(ix, iy, k, seed) + u * (_lattice(ix + 1, iy, k, seed) - _lattice(ix, iy, k, seed))
        b = _lattice(ix, iy + 1, k, seed) + u * (_lattice(ix + 1, iy + 1, k, seed) - _lattice(ix, iy + 1, k, seed))
        layer = a + v * (b - a)
        out = layer if dz == 0 else out + w * (layer - out)
    return out


@kernel("float64(float64, float64)")
def _keep(wavelength_m, footprint_m):
    """Weight of an octave of ``wavelength_m`` at a pixel footprint: 1 from 4 footprints up, 0 below 2."""
    r = wavelength_m / footprint_m
    return 0.0 if r <= 2.0 else 1.0 if r >= 4.0 else 0.5 * (r - 2.0)


@kernel("float64(float64, float64, float64)")
def _step(lo, hi, x):
    t = (x - lo) / (hi - lo)
    t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
    return t * t * (3.0 - 2.0 * t)


@kernel("float64(float64, float64, float64, float64, int64)")
def _octave2(x, y, wavelength_m, footprint_m, seed):
    k = _keep(wavelength_m, footprint_m)
    return 0.0 if k == 0.0 else k * noise2(x / wavelength_m, y / wavelength_m, seed)


@kernel("float64(float64, float64, float64, float64, float64, int64)")
def _octave3(x, y, z, wavelength_m, footprint_m, seed):
    k = _keep(wavelength_m, footprint_m)
    return 0.0 if k == 0.0 else k * noise3(x / wavelength_m, y / wavelength_m, z / wavelength_m, seed)


CRACK_WIDTH_M = 0.015


@kernel("float64(float64, float64, int64)")
def _crack_field(x, y, seed):
    """The zero set of this field, in metres' coordinates, is the crack network: value noise of 2.2 m cells over a
    domain warped by a finer noise, so the lines wander and kink like cracks, not like contour lines."""
    xw = x + 0.3 * noise2(x / 0.6, y / 0.6, seed + 1)
    yw = y + 0.3 * noise2(x / 0.6, y / 0.6, seed + 2)
    return noise2(xw / 2.2, yw / 2.2, seed)


@kernel("float64(float64, float64, float64)")
def _crack(x, y, footprint_m):
    """Share of a pixel of ``footprint_m`` at (x, y) that a crack darkens: the distance to the field's zero set (its
    value over its gradient) against half the crack's width or half the footprint, whichever is wider, times the
    share of the footprint the crack covers."""
    e = 0.01
    v = _crack_field(x, y, 8)
    gx = (_crack_field(x + e, y, 8) - v) / e
    gy = (_crack_field(x, y + e, 8) - v) / e
    g = np.sqrt(gx * gx + gy * gy)
    if g == 0.0:
        return 0.0
    half = 0.5 * max(CRACK_WIDTH_M, footprint_m)
    d = abs(v) / g
    return 0.0 if d >= half else min(1.0, CRACK_WIDTH_M / footprint_m) * (1.0 - d / half)


@kernel("float64(float64, float64, float64, float64)")
def _brick(s, z, footprint_m, out_mortar):
    """Brick pattern at (s along the wall, z): the albedo factor of the brick's face (each brick its own shade), or
    with ``out_mortar`` > 0 the share of the pixel that is mortar, both faded to their means as the footprint grows
    past a course."""
    course = np.floor(z / BRICK_COURSE_M)
    u = s / BRICK_LENGTH_M + 0.5 * (course - 2.0 * np.floor(course / 2.0))
    brick = np.floor(u)
    joint_z, joint_s = JOINT_M / BRICK_COURSE_M, JOINT_M / BRICK_LENGTH_M
    mean = joint_z + joint_s - joint_z * joint_s  # the mortar's share of a wall
    k = _keep(BRICK_COURSE_M, footprint_m)
    if out_mortar > 0.0:
        fz, fs = z / BRICK_COURSE_M - course, u - brick
        mortar = 1.0 if fz < joint_z or fs < joint_s else 0.0
        return k * mortar + (1.0 - k) * mean
    return 1.0 + k * 0.14 * _lattice(np.int64(brick), np.int64(course), 0, 51)


@kernel("float32[:, ::1](float32[:, ::1], float32[::1], boolean[::1], int32[::1], int32[::1], float32[:, ::1], "
        "float32[:, ::1], int8[::1], float32[::1], float32[::1], float64)")
def _texture(rays, t_m, hit, instance_id, material, normal, color, kinds, asphalt_rgb, mortar_rgb, pixel_angle_rad):
    """:func:`textured_albedo`'s loop over the hits."""
    out = color.copy()
    for i in range(t_m.size):
        if not hit[i] or instance_id[i] != 0:
            continue
        kind = kinds[material[i]]
        if kind == 0:
            continue
        t = np.float64(t_m[i])
        x = np.float64(rays[i, 0]) + np.float64(rays[i, 3]) * t
        y = np.float64(rays[i, 1]) + np.float64(rays[i, 4]) * t
        z = np.float64(rays[i, 2]) + np.float64(rays[i, 5]) * t
        cos_i = abs(np.float64(rays[i, 3]) * normal[i, 0] + np.float64(rays[i, 4]) * normal[i, 1]
                    + np.float64(rays[i, 5]) * normal[i, 2])
        f = t * pixel_angle_rad / max(cos_i, 0.2)
        if kind == 1:  # asphalt: blotches, darker repair patches, grain, cracks
            m = 1.0 + 0.16 * _octave2(x, y, 7.0, f, 1) + 0.08 * _octave2(x, y, 2.5, f, 2)
            m *= 1.0 - 0.22 * _step(0.35, 0.45, noise2(x / 13.0, y / 13.0, 3))
            m += 0.12 * _octave2(x, y, 0.3, f, 4) + 0.14 * _octave2(x, y, 0.09, f, 5) + 0.12 * _octave2(x, y, 0.03,
                                                                                                          f, 6)
            crack_weight = _step(0.0, 0.3, noise2(x / 17.0, y / 17.0, 7))
            if crack_weight > 0.0 and f < 0.2:
                m *= 1.0 - 0.6 * crack_weight * _crack(x, y, f)
            m = min(max(m, 0.4), 1.8)
            for c in range(3):
                out[i, c] = np.float32(color[i, c] * m)
        elif kind == 2:  # markings: worn through to the asphalt in places, dirty elsewhere
            wear = 0.6 * noise2(x / 0.5, y / 0.5, 11) + 0.4 * _octave2(x, y, 0.15, f, 12)
            worn = 0.7 * _step(0.15, 0.6, wear)
            dirt = 0.9 + 0.1 * _octave2(x, y, 0.3, f, 13)
            for c in range(3):
                out[i, c] = np.float32((color[i, c] * (1.0 - worn) + asphalt_rgb[c] * worn) * dirt)
        elif kind == 3:  # grass: lush and dry patches, tufts
            m = 1.0 + 0.25 * _octave2(x, y, 5.0, f, 21) + 0.15 * _octave2(x, y, 1.2, f, 22) + 0.15 * _octave2(
                x, y, 0.25, f, 23)
            dry = 0.6 * _step(0.1, 0.7, noise2(x / 9.0, y / 9.0, 24))
            out[i, 0] = np.float32((color[i, 0] * (1.0 - dry) + 0.20 * dry) * m)
            out[i, 1] = np.float32((color[i, 1] * (1.0 - dry) + 0.19 * dry) * m)
            out[i, 2] = np.float32((color[i, 2] * (1.0 - dry) + 0.08 * dry) * m)
        elif kind == 4:  # concrete, kerbs, barriers, façades: weathering stains
            m = 1.0 + 0.08 * _octave3(x, y, z, 2.5, f, 31) + 0.05 * _octave3(x, y, z, 0.6, f, 32) + 0.04 * _octave3(
                x, y, z, 0.15, f, 33)
            for c in range(3):
                out[i, c] = np.float32(color[i, c] * m)
        elif kind == 5:  # foliage: clumps in light and shade
            m = 1.0 + 0.3 * _octave3(x, y, z, 0.4, f, 41) + 0.2 * _octave3(x, y, z, 1.5, f, 42)
            m = max(m, 0.3)
            for c in range(3):
                out[i, c] = np.float32(color[i, c] * m)
        elif kind == 6:  # window glass: the rooms behind, darker and lighter (furniture, walls, shade)
            m = 1.0 + 0.6 * _octave3(x, y, z, 1.1, f, 61) + 0.35 * _octave3(x, y, z, 0.35, f, 62)
            m = min(max(m, 0.35), 2.2)
            for c in range(3):
                out[i, c] = np.float32(color[i, c] * m)
        elif kind == 7:  # blinds and curtains: slats 5 cm apart, their colour varying from window to window
            m = 1.0 + 0.25 * _octave3(x, y, z, 1.6, f, 71) + 0.12 * _keep(0.05, f) * np.sin(z * (2.0 * np.pi / 0.05))
            for c in range(3):
                out[i, c] = np.float32(color[i, c] * m)
        else:  # brick: courses in running bond along the wall (its horizontal direction from the normal), stained
            s = x * -np.float64(normal[i, 1]) + y * np.float64(normal[i, 0])
            mortar = _brick(s, z, f, 1.0)
            shade = _brick(s, z, f, 0.0)
            m = 1.0 + 0.08 * _octave3(x, y, z, 2.5, f, 31) + 0.05 * _octave3(x, y, z, 0.6, f, 32)
            for c in range(3):
                out[i, c] = np.float32(((1.0 - mortar) * color[i, c] * shade + mortar * mortar_rgb[c]) * m)
    return out
