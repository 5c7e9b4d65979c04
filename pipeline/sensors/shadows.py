"""Sun shadows with penumbrae: the sun is a disc, sampled by one shadow ray per lit pixel, smoothed over each surface.

The sun subtends 0.53 degrees: a shadow's edge is a penumbra as wide as the occluder's distance times that angle
(narrow where a tyre meets the road, a metre wide under a tall building's edge at low sun). Each lit hit casts one
shadow ray (:func:`sun_rays`) towards one of SUN_SAMPLES fixed directions over the disc (:func:`sun_disc`: one point in
each cell of a 4 x 4 grid, multi-jittered, mapped onto the disc), chosen by the pixel's place in a 4 x 4 tile of the
image (:func:`stratum`): every 2 x 2 block of pixels samples the four quarters of the disc, every 4 x 4 block all
sixteen cells. A pixel in a penumbra then sees the sun or not, a dither; on a camera's pixel grid
(:func:`sun_visibility`) that dither is averaged over the pixel's neighbourhood on the same surface (same object,
normals within about 18 degrees, depth within 3 %, as the sky occlusion is: :mod:`pipeline.sensors.indirect`), over
a window no wider than the penumbra itself, so the penumbra is a smooth ramp of the width the geometry gives it and a
contact shadow stays sharp:

- pixels whose SHADOW_FILTER_RADIUS_PX-window on their surface holds both sunlit and shadowed samples are the
  penumbra's candidates (the others keep their value: their mean would be the same);
- the shadowed ones among them cast their shadow ray again for the occluder's distance d;
- a candidate's penumbra on the image is at most w = d * 2 tan(radius) * g / (t * pixel angle) pixels wide: d the
  greatest occluder distance on its surface within the window, t its distance from the camera, g how far a turn of
  the sun's direction moves a shadow on the surface as the camera sees it (1 for a surface square to the sun and
  to the view; larger where the sun grazes it); it takes the mean over the window of radius min(round(w / 2),
  SHADOW_FILTER_RADIUS_PX), its outermost rows and columns at half weight so that every disc cell weighs the same.

Each of the SUN_SAMPLES directions has its own conservative shadow-ray tests (:meth:`FrameScene.sun_actor_candidates`
and the static world's sun map, one per direction), which are exact for rays along that direction. An anti-aliasing
sample borrows the smoothed share of its pixel, or of a neighbour, on its own surface (:func:`borrowed_shares`);
only a sample on a surface that no pixel centre nearby shows traces its own. With one direction (radius 0, or the fast
preset) every shadow ray points at the sun's centre, as before.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.core.jit import as_input, kernel
from pipeline.sensors.indirect import same_surface
from pipeline.world.scene import FrameScene, Hits

if TYPE_CHECKING:  # only its properties are read
    from pipeline.sensors.conditions import Condition

SUN_GRID = 4  # the disc is sampled on a SUN_GRID x SUN_GRID grid of cells
SUN_SAMPLES = SUN_GRID * SUN_GRID
SHADOW_FILTER_RADIUS_PX = 2  # the widest smoothing window: (2 r + 1)^2 pixels, every disc cell at least once
SHADOW_FILTER_NORMAL_COS = 0.95
SHADOW_FILTER_DEPTH = 0.03
SUN_MAP_RANGE_M = 100.0  # hits nearer than this test their sun shadow rays' cells (farther: a few pixel rows)


def sun_disc(sun: np.ndarray, angular_radius_rad: float) -> np.ndarray:
    """(S, 3) float32 unit directions over the sun's disc about the unit direction ``sun`` (3,), row ``k = SUN_GRID *
    v + u`` for cell (u, v) of a SUN_GRID x SUN_GRID grid over the unit square: a point in each cell, offset within it
    as in correlated multi-jittered sampling (Chiu, Shirley and Wang 1994: the S points also fall in S different
    columns and rows of an S x S grid, so a shadow edge in any direction sees many distinct steps, not SUN_GRID),
    mapped onto the disc by Shirley and Chiu's concentric map (equal areas); the one direction ``sun`` if the radius
    is 0."""
    sun = np.asarray(sun, np.float64)
    if angular_radius_rad <= 0:
        return sun[None].astype(np.float32)
    u, v = (g.reshape(-1) for g in np.meshgrid(np.arange(SUN_GRID), np.arange(SUN_GRID)))  # u fastest
    a = 2.0 * (u + (v + 0.5) / SUN_GRID) / SUN_GRID - 1.0  # in [-1, 1]
    b = 2.0 * (v + (u + 0.5) / SUN_GRID) / SUN_GRID - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    phi = np.where(first, (np.pi / 4) * b / np.where(first, a, 1.0),
                   np.pi / 2 - (np.pi / 4) * a / np.where(first, 1.0, b))
    e1, e2 = tangent_frame(sun)
    t = np.tan(angular_radius_rad)
    d = sun[None] + t * (r * np.cos(phi))[:, None] * e1[None] + t * (r * np.sin(phi))[:, None] * e2[None]
    return (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)


def tangent_frame(sun: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two (3,) float64 unit vectors across the unit direction ``sun`` (3,), at right angles to it and each other."""
    sun = np.asarray(sun, np.float64)
    e1 = np.cross([0.0, 0.0, 1.0] if abs(sun[2]) < 0.9 else [1.0, 0.0, 0.0], sun)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(sun, e1)


@kernel("int64(int64, int64, int64)")
def stratum(i, width, samples):
    """The disc direction (row of :func:`sun_disc`) of ray ``i``: for a camera's pixel-centre rays (row-major,
    ``width`` > 0 pixels a row) from the pixel's column and row modulo 4, so that every 2 x 2 block samples each
    half of the disc in both axes and every 4 x 4 block each cell; other rays (``width`` 0) as if in rows of 4.
    0 when there is one sample."""
    if samples == 1:
        return 0
    if width > 0:
        x, y = i % width, i // width
    else:
        x, y = i, i // 4
    u = 2 * (x & 1) + ((x >> 1) & 1)
    v = 2 * (y & 1) + ((y >> 1) & 1)
    return 4 * v + u


@kernel("Tuple((float32[::1], int64[::1], float32[:, ::1], int64[::1]))(float32[:, ::1], float32[:, ::1], "
        "float32[::1], float32[::1], float32[:, ::1], int64, int64)")
def sun_rays(rays, normal, t_m, sun, disc, width, period):
    """The hits facing the sun, and their shadow rays.

    Args:
        rays: (N, 6) float32 camera rays [origin | unit direction], world frame.
        normal: (N, 3) float32 hit normals (0 for misses); t_m: (N,) float32 hit distances.
        sun: (3,) float32 unit vector towards the sun's centre.
        disc: (S, 3) float32 unit directions over the sun's disc (:func:`sun_disc`).
        width: the rays are a camera's pixel centres, row-major, ``width`` a row (0: any rays); it chooses each
            ray's direction from ``disc`` (:func:`stratum`), from its row modulo ``period`` (rays that stack passes
            of ``period`` rays each choose as each pass alone would).

    Returns:
        n_dot_l: (N,) float32 normal . sun (0 for misses).
        lit: (M,) int64 the rays with n_dot_l > 0, ascending.
        shadow: (M, 6) float32 their shadow rays [origin | disc direction]: from the hit point lifted off the surface
        along the normal by 1 mm + 0.1 mm per metre of distance (against self-intersection).
        which: (M,) int64 the row of ``disc`` each shadow ray follows.
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
    which = np.empty(count, np.int64)
    samples = disc.shape[0]
    j = 0
    for i in range(n):
        if n_dot_l[i] > 0:
            lit[j] = i
            t = t_m[i]
            lift = np.float32(1e-3) + np.float32(1e-4) * t
            k = stratum(i % period, width, samples)
            which[j] = k
            for c in range(3):
                shadow[j, c] = rays[i, c] + rays[i, 3 + c] * t + normal[i, c] * lift
                shadow[j, 3 + c] = disc[k, c]
            j += 1
    return n_dot_l, lit, shadow, which


def sun_blocked(scene: FrameScene, shadow: np.ndarray, which: np.ndarray, disc: np.ndarray,
                t_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (M, 6) float32 ``shadow`` rays (:func:`pipeline.sensors.sunlight.sun_rays`; ray j along ``disc[which[j]]``)
    from hits at distances ``t_m`` ((M,) float32) that are blocked ((M,) bool), and the masks of the rays that may
    meet an actor and the static world ((M,) bool each; see :meth:`FrameScene.occluded_rays`)."""
    origin = [shadow[:, k] for k in range(3)]  # views: the tests below read them in place
    actor_rays, static_rays = np.zeros(len(t_m), bool), np.ones(len(t_m), bool)
    near = t_m < SUN_MAP_RANGE_M
    if len(t_m):  # one grid for all the disc's directions
        actor_rays = scene.sun_disc_actor_candidates(*origin, disc, which)
    for k in np.unique(which).tolist():
        rows = np.flatnonzero(which == k)
        direction = disc[k]
        # Near hits (most of the lit pixels) skip the static world where its projection along the sun lies below them.
        rows = rows[near[rows]]
        static_rays[rows] = scene.static.sun_candidates(*origin, direction, rows=rows, disc=disc)
    return scene.occluded_rays(shadow, actor_rays=actor_rays, static_rays=static_rays), actor_rays, static_rays


def sun_visibility(scene: FrameScene, rays: np.ndarray, hits: Hits, lit: np.ndarray, shadow: np.ndarray,
                   which: np.ndarray, disc: np.ndarray, angular_radius_rad: float, image_shape: tuple[int, int] | None,
                   pixel_angle_rad: float) -> np.ndarray:
    """(M,) float32: the share of the sun's disc each ``lit`` hit ((M,) int64 rows of the N camera ``rays``) sees,
    from its shadow ray (:func:`sun_blocked`); smoothed over penumbrae (see the module docstring) where the rays are
    a camera's pixel centres (``image_shape`` (H, W), N = H * W, ``pixel_angle_rad`` its angle per pixel) and the
    sun is a disc."""
    t_lit = as_input(hits.t_m, np.float32)[lit]
    blocked, actor_rays, static_rays = sun_blocked(scene, shadow, which, disc, t_lit)
    share = (~blocked).astype(np.float32)
    if image_shape is None or len(disc) == 1 or pixel_angle_rad <= 0 or not blocked.any():
        return share
    h, w = image_shape
    n = h * w
    if n != len(rays):
        raise ValueError(f"image_shape {image_shape} does not hold the {len(rays)} rays")
    value, traced = np.zeros(n, np.float32), np.zeros(n, bool)
    value[lit], traced[lit] = share, True
    instance = as_input(hits.instance_id, np.int32)
    normal = as_input(hits.normal, np.float32)
    t = np.where(hits.hit, hits.t_m, 0.0).astype(np.float32)
    surface = (instance, normal, t, h, w, np.float32(SHADOW_FILTER_NORMAL_COS), np.float32(SHADOW_FILTER_DEPTH))
    mixed = _mixed_windows(value, traced, *surface, SHADOW_FILTER_RADIUS_PX)
    if not mixed.any():
        return share
    # The occluders' distances, for the shadowed samples of the penumbrae.
    again = np.flatnonzero(blocked & mixed[lit])
    occluder = np.zeros(n, np.float32)
    if len(again):
        found = scene.cast_rays(np.take(shadow, again, axis=0), actor_rays=actor_rays[again],
                                static_rays=static_rays[again])
        occluder[lit[again]] = np.where(found.hit, found.t_m, 0.0)
    spread = np.float32(2.0 * np.tan(angular_radius_rad) / pixel_angle_rad)
    centre = np.mean(disc.astype(np.float64), axis=0)
    centre /= np.linalg.norm(centre)
    e1, e2 = (e.astype(np.float32) for e in tangent_frame(centre))
    smoothed = _smooth_penumbrae(value, traced, mixed, occluder, as_input(rays, np.float32), centre.astype(np.float32),
                                 e1, e2, spread, *surface, SHADOW_FILTER_RADIUS_PX)
    return smoothed[lit]


def sun_shares(scene: FrameScene, rays: np.ndarray, hits: Hits, condition: Condition, disc: np.ndarray,
               image_shape: tuple[int, int] | None = None, pixel_angle_rad: float = 0.0,
               given: np.ndarray | None = None, period: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The hits of (N, 6) float32 ``rays`` that face the sun and how much of it they see.

    Returns n_dot_l (N,) float32 and lit (M,) int64 (:func:`sun_rays`), and sunlit (M,) float32: the share of the
    sun's ``disc`` ((S, 3), the condition's or its centre alone) each lit hit sees, 1 without shadows; taken from
    ``given`` ((N,) float32 per ray, optional) where that is not NaN, else traced (:func:`sun_visibility`).
    ``period``: the rays are passes of this many rays stacked, each ray's disc direction chosen by its place in its
    pass (:func:`sun_rays`); default N.
    """
    normal, t_m = as_input(hits.normal, np.float32), as_input(hits.t_m, np.float32)
    width = image_shape[1] if image_shape is not None else 0
    n_dot_l, lit, shadow, which = sun_rays(as_input(rays, np.float32), normal, t_m, condition.sun_direction, disc,
                                           width, len(rays) if period is None else int(period))
    sunlit = np.ones(len(lit), np.float32)
    if not (condition.sun_shadows and len(lit)):
        return n_dot_l, lit, sunlit
    if given is None:
        sunlit = sun_visibility(scene, rays, hits, lit, shadow, which, disc, condition.sun_angular_radius_rad,
                                image_shape, pixel_angle_rad)
        return n_dot_l, lit, sunlit
    sunlit = given[lit].astype(np.float32)
    todo = np.flatnonzero(np.isnan(sunlit))
    if len(todo):
        sunlit[todo] = ~sun_blocked(scene, np.take(shadow, todo, axis=0), which[todo], disc, t_m[lit[todo]])[0]
    return n_dot_l, lit, sunlit


def pixel_shares(n: int, lit: np.ndarray, sunlit: np.ndarray) -> np.ndarray:
    """(N,) float32: ``sunlit`` ((M,), of the rays ``lit``) per ray of N, NaN for the rays that are not lit."""
    out = np.full(n, np.nan, np.float32)
    out[lit] = sunlit
    return out


@kernel("float32[::1](float32[::1], int32[::1], float32[:, ::1], float32[::1], int64[::1], int32[::1], "
        "float32[:, ::1], float32[::1], int64, int64, float32, float32)")
def borrowed_shares(centre, instance, normal, t_m, where, sample_instance, sample_normal, sample_t, height, width,
                    normal_cos, depth):
    """(K,) float32: for K sample rays of the pixels ``where`` (row-major on an H x W grid), the pixel-centre share of
    the sun ``centre`` ((H * W,) float32, smoothed; NaN where not lit) of the pixel or, failing it, the first of its 8
    neighbours whose centre hit lies on the sample's surface (same instance, normals' cosine above ``normal_cos``,
    depth within ``depth`` of the sample's ``sample_t``, relatively; 0 for a miss): an anti-aliasing sample takes its
    surface's smooth penumbra instead of a dither of its own. NaN where none does (the share is then traced)."""
    out = np.full(where.size, np.nan, np.float32)
    for k in range(where.size):
        p = where[k]
        y, x = p // width, p % width
        for step in range(9):
            # The pixel itself (cell 4 of its 3 x 3 block) first, then its neighbours (cells 0-3, 5-8).
            cell = 4 if step == 0 else (step - 1 if step <= 4 else step)
            yy, xx = y + cell // 3 - 1, x + cell % 3 - 1
            if yy < 0 or yy >= height or xx < 0 or xx >= width:
                continue
            q = yy * width + xx
            if not sample_t[k] > 0 or np.isnan(centre[q]) or instance[q] != sample_instance[k]:
                continue
            if abs(t_m[q] - sample_t[k]) > depth * sample_t[k]:
                continue
            if (normal[q, 0] * sample_normal[k, 0] + normal[q, 1] * sample_normal[k, 1]
                    + normal[q, 2] * sample_normal[k, 2]) < normal_cos:
                continue
            out[k] = centre[q]
            break
    return out


@kernel("boolean[::1](float32[::1], boolean[::1], int32[::1], float32[:, ::1], float32[::1], int64, int64, float32, "
        "float32, int64)")
def _mixed_windows(value, traced, instance, normal, t_m, height, width, normal_cos, depth, radius):
    """(H * W,) bool: the ``traced`` pixels of a row-major H x W grid with a traced pixel of another ``value`` within
    ``radius`` (a square window) on their surface (:func:`same_surface`)."""
    out = np.zeros(height * width, np.bool_)
    for y in range(height):
        for x in range(width):
            i = y * width + x
            if not traced[i]:
                continue
            for yy in range(max(0, y - radius), min(height, y + radius + 1)):
                for xx in range(max(0, x - radius), min(width, x + radius + 1)):
                    j = yy * width + xx
                    if traced[j] and value[j] != value[i] and same_surface(i, j, instance, normal, t_m, normal_cos,
                                                                           depth):
                        out[i] = True
                        break
                if out[i]:
                    break
    return out


@kernel("float32(float32[:, ::1], int64, float32[:, ::1], float32[::1], float32[::1])")
def _spread_on_image(rays, i, normal, sun, tangent):
    """How far (per radian of the sun's direction turned along ``tangent``, per metre of occluder distance, per metre
    of distance from the camera) the shadow of a point moves on the image at pixel ``i``: the shadow's shift on the
    surface, -(tangent - sun (n . tangent) / (n . sun)), less its component along the view ray."""
    n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
    n_dot_s = max(n0 * sun[0] + n1 * sun[1] + n2 * sun[2], np.float32(1e-3))
    f = (n0 * tangent[0] + n1 * tangent[1] + n2 * tangent[2]) / n_dot_s
    p0, p1, p2 = tangent[0] - sun[0] * f, tangent[1] - sun[1] * f, tangent[2] - sun[2] * f
    along = p0 * rays[i, 3] + p1 * rays[i, 4] + p2 * rays[i, 5]
    p0, p1, p2 = p0 - rays[i, 3] * along, p1 - rays[i, 4] * along, p2 - rays[i, 5] * along
    return np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)


@kernel("float32[::1](float32[::1], boolean[::1], boolean[::1], float32[::1], float32[:, ::1], float32[::1], "
        "float32[::1], float32[::1], float32, int32[::1], float32[:, ::1], float32[::1], int64, int64, float32, "
        "float32, int64)")
def _smooth_penumbrae(value, traced, mixed, occluder, rays, sun, e1, e2, spread, instance, normal, t_m, height, width,
                      normal_cos, depth, radius):
    """(H * W,) float32: ``value`` with each ``mixed`` pixel replaced by the weighted mean of ``value`` over the traced
    pixels of its surface within r = min(round(w / 2), ``radius``) of it, the window's outermost rows and columns at
    half weight (so each residue of the pixel position modulo 2 r weighs the same: the disc's cells, :func:`stratum`,
    count alike). w = d * ``spread`` * g / t is the penumbra's width on the image in pixels: d the greatest
    ``occluder`` distance on the pixel's surface within ``radius``, t its ``t_m``, ``spread`` the disc's angular
    diameter over the angle of a pixel, g the larger :func:`_spread_on_image` of the disc's axes ``e1``, ``e2``."""
    out = value.copy()
    for y in range(height):
        for x in range(width):
            i = y * width + x
            if not mixed[i]:
                continue
            d = np.float32(0)
            for yy in range(max(0, y - radius), min(height, y + radius + 1)):
                for xx in range(max(0, x - radius), min(width, x + radius + 1)):
                    j = yy * width + xx
                    if occluder[j] > d and same_surface(i, j, instance, normal, t_m, normal_cos, depth):
                        d = occluder[j]
            if not d > 0:
                continue
            g = max(_spread_on_image(rays, i, normal, sun, e1), _spread_on_image(rays, i, normal, sun, e2))
            half = np.float32(0.5) * d * spread * g / t_m[i]
            r = radius if half >= radius else np.int64(half + np.float32(0.5))
            if r == 0:
                continue
            total = np.float32(0)
            weight = np.float32(0)
            for yy in range(max(0, y - r), min(height, y + r + 1)):
                wy = np.float32(0.5) if abs(yy - y) == r else np.float32(1)
                for xx in range(max(0, x - r), min(width, x + r + 1)):
                    j = yy * width + xx
                    if traced[j] and same_surface(i, j, instance, normal, t_m, normal_cos, depth):
                        wxy = wy * (np.float32(0.5) if abs(xx - x) == r else np.float32(1))
                        total += wxy * value[j]
                        weight += wxy
            out[i] = total / weight
    return out
