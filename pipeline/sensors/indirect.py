"""Light that bounces: sky occlusion (ambient occlusion) and one-bounce Fresnel reflections on paint and glass.

What makes a car read as a car in a photograph, beyond its shape, is how it sits in its light: the sky is shut out
under and around it (a dark contact shadow, dark wheel arches), and its paint and glass mirror the sky and the
street, strongly at grazing angles. Both are ray traced here in the same scene as everything else.

- **Sky occlusion.** The ambient (sky fill) term of :func:`pipeline.sensors.shading.shade` is scaled by the share of
  ``AO_SAMPLES`` cosine-weighted directions about the normal that leave without meeting anything within
  ``AO_RADIUS_M``, times ``AO_STRENGTH`` (the ground and nearby surfaces also bounce some light back, which this
  does not trace). Only the hits where it matters are traced, within INDIRECT_RANGE_M of the camera: on actors
  (against everything), and on the world within about a metre of an actor's footprint (against the actors only:
  their contact shadows; the world's occlusion of itself is left out everywhere), found by
  :meth:`FrameScene.near_actors` (a conservative grid test).
  The directions are a fixed spiral set rotated about the normal by an angle hashed from the ray's index, so a frame
  is the same on every run and the pattern shows as fine noise, not bands. On a camera's pixel-centre rays that
  noise is then filtered away (:func:`smooth_visibility`): each pixel takes the mean occlusion of the traced pixels
  within AO_FILTER_RADIUS_PX that lie on its surface (same instance, normals within about 18 degrees, depth within
  3 %), 8 rays each, so paint shows its sky occlusion as a smooth shade rather than grain. Since that mean holds a
  dozen or more pixels wherever a surface is wider than a pixel or two, only every other pixel traces (a
  checkerboard), and a pixel with no traced one on its surface within the window traces its own: half the rays
  (urban frames: ~1.9M -> ~0.95M), the same estimate of each surface's occlusion with a little more of its grain
  (docs/performance.md: 0.2 of an 8-bit level per channel on urban frames).
- **Reflections.** Materials with a Fresnel ``F0`` (:class:`pipeline.world.materials.Material.fresnel_f0`: clear-coat
  paint, glass, lamps, rims, glazed façades) reflect one bounce: the mirror ray is cast into the scene and what it
  meets is lit by the sky and the sun without shadows (or is the sky, also beyond MIRROR_RANGE_M: a documented
  simplification that bounds which actors a frame must hold, :mod:`pipeline.sensors.reach`); Schlick's Fresnel term
  F weights it, and the surface's own radiance by (1 - F). Hits within INDIRECT_RANGE_M of the camera only.
"""

from __future__ import annotations

import functools

import numpy as np

from pipeline.core.jit import as_input, kernel
from pipeline.sensors.sunlight import sky_and_sun
from pipeline.sensors.wet import WATER_F0
from pipeline.world.scene import FrameScene, Hits

AO_SAMPLES = 8
AO_RADIUS_M = 1.5
AO_STRENGTH = 0.85
AO_FILTER_RADIUS_PX = 2  # the occlusion is averaged over a (2r + 1)^2 pixel window of the same surface
AO_FILTER_NORMAL_COS = 0.95
AO_FILTER_DEPTH = 0.03  # relative depth difference within which two pixels lie on one surface
INDIRECT_RANGE_M = 60.0  # hits farther from the camera get neither (a car there is a few pixels tall)
MIRROR_RANGE_M = 60.0  # a mirror ray that meets nothing nearer sees the sky
# Every ray of this module meets nothing farther than this from the camera (actors beyond cannot change a pixel:
# pipeline.sensors.reach); 1 m for the rays' lift off their surfaces.
INDIRECT_REACH_M = INDIRECT_RANGE_M + max(MIRROR_RANGE_M, AO_RADIUS_M) + 1.0


def _hemisphere(samples: int) -> np.ndarray:
    """(S, 3) float32 cosine-weighted directions about +z: a spiral of equal-area rings (Fibonacci)."""
    k = np.arange(samples) + 0.5
    r = np.sqrt(k / samples)  # cosine weighting: uniform in the disc, lifted onto the hemisphere
    phi = k * np.pi * (3.0 - np.sqrt(5.0))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)]).astype(np.float32)


_PATTERN = _hemisphere(AO_SAMPLES)


@kernel("float32[:, ::1](float32[:, ::1], float32[::1], float32[:, ::1], int64[::1], float32[:, ::1], int64)")
def occlusion_rays(rays, t_m, normal, rows, pattern, period):
    """(K * S, 6) float32 rays from the hits ``rows`` of the (N, 6) float32 camera ``rays`` (hit at ``t_m``, unit
    ``normal`` facing the viewer): for each, the S directions of ``pattern`` ((S, 3), about +z) turned onto its
    normal and rotated about it by an angle hashed from the row modulo ``period`` (rays that stack passes of
    ``period`` rays each hash as each pass alone would), from the hit lifted 2 mm + 0.1 mm per metre."""
    s = pattern.shape[0]
    out = np.empty((rows.size * s, 6), np.float32)
    for j in range(rows.size):
        i = rows[j]
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        # A tangent frame (b1, b2, n) without a singularity (Duff et al. 2017, "Building an orthonormal basis,
        # revisited").
        sign = np.float32(1) if n2 >= 0 else np.float32(-1)
        a = np.float32(-1) / (sign + n2)
        b = n0 * n1 * a
        b10, b11, b12 = np.float32(1) + sign * n0 * n0 * a, sign * b, -sign * n0
        b20, b21, b22 = b, sign + n1 * n1 * a, -n1
        # A rotation angle from the row: SplitMix64's finaliser, top 24 bits.
        z = np.uint64(i % period) * np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
        angle = np.float32(np.float64(z >> np.uint64(40)) * (2.0 * np.pi / 16777216.0))
        c, sn = np.float32(np.cos(angle)), np.float32(np.sin(angle))
        lift = np.float32(2e-3) + np.float32(1e-4) * t_m[i]
        p0 = rays[i, 0] + rays[i, 3] * t_m[i] + n0 * lift
        p1 = rays[i, 1] + rays[i, 4] * t_m[i] + n1 * lift
        p2 = rays[i, 2] + rays[i, 5] * t_m[i] + n2 * lift
        for k in range(s):
            x = pattern[k, 0] * c - pattern[k, 1] * sn
            y = pattern[k, 0] * sn + pattern[k, 1] * c
            zz = pattern[k, 2]
            r = j * s + k
            out[r, 0], out[r, 1], out[r, 2] = p0, p1, p2
            out[r, 3] = x * b10 + y * b20 + zz * n0
            out[r, 4] = x * b11 + y * b21 + zz * n1
            out[r, 5] = x * b12 + y * b22 + zz * n2
    return out


@kernel("boolean(int64, int64, int32[::1], float32[:, ::1], float32[::1], float32, float32)")
def same_surface(i, j, instance, normal, t_m, normal_cos, depth):
    """Pixels i and j lie on one surface: the same instance, depths within ``depth`` of i's (relatively), normals'
    cosine above ``normal_cos``."""
    if instance[j] != instance[i] or abs(t_m[j] - t_m[i]) > depth * t_m[i]:
        return False
    return normal[i, 0] * normal[j, 0] + normal[i, 1] * normal[j, 1] + normal[i, 2] * normal[j, 2] >= normal_cos


@kernel("float32[::1](float32[::1], boolean[::1], boolean[::1], int32[::1], float32[:, ::1], float32[::1], int64, "
        "int64, int64, float32, float32)")
def smooth_visibility(blocked, traced, wanted, instance, normal, t_m, height, width, radius, normal_cos, depth):
    """(H * W,) float32: for each ``wanted`` pixel of a row-major H x W grid, the mean of ``blocked`` over the traced
    pixels within ``radius`` (a square window) of the same ``instance`` whose normal's cosine with its own exceeds
    ``normal_cos`` and whose depth ``t_m`` is within ``depth`` of its own, relatively (itself included where traced);
    NaN where no such pixel is traced; 0 where not wanted."""
    out = np.zeros(height * width, np.float32)
    for y in range(height):
        for x in range(width):
            i = y * width + x
            if not wanted[i]:
                continue
            total = np.float32(0)
            count = 0
            # same_surface(i, j, ...) written out: called per neighbour, it cost more than the test itself.
            own, t_i, n0, n1, n2 = instance[i], t_m[i], normal[i, 0], normal[i, 1], normal[i, 2]
            reach = depth * t_i
            for yy in range(max(0, y - radius), min(height, y + radius + 1)):
                for xx in range(max(0, x - radius), min(width, x + radius + 1)):
                    j = yy * width + xx
                    if not traced[j] or instance[j] != own or abs(t_m[j] - t_i) > reach:
                        continue
                    if not n0 * normal[j, 0] + n1 * normal[j, 1] + n2 * normal[j, 2] >= normal_cos:
                        continue
                    total += blocked[j]
                    count += 1
            out[i] = total / np.float32(count) if count else np.float32(np.nan)
    return out


def sky_visibility(scene: FrameScene, rays: np.ndarray, hits: Hits,
                   image_shape: tuple[int, int] | None = None, given: np.ndarray | None = None,
                   period: int | None = None) -> np.ndarray:
    """(N,) float32 in [1 - AO_STRENGTH, 1]: how much of the sky fill reaches each hit (1 where not traced).
    With ``image_shape`` (H, W), the rays are a camera's pixel centres in row-major order (N = H * W) and the
    occlusion is smoothed over each surface (:func:`smooth_visibility`). ``given`` (N,) float32, optional: the
    visibility where it is already known (an anti-aliasing sample's, lent by its pixel centre's surface); only its
    NaN rows are traced. ``period``: the rays are passes of this many rays stacked (the anti-aliasing samples), each
    ray's directions hashed from its place in its pass (:func:`occlusion_rays`); default N."""
    n = len(rays)
    visibility = np.ones(n, np.float32)
    if given is not None:
        known = ~np.isnan(given)
        visibility[known] = given[known]
    if not len(scene.actors) or not n:
        return visibility
    hit = hits.hit & (hits.t_m < INDIRECT_RANGE_M)
    on_actor = hit & (hits.instance_id > 0)
    t = np.where(hit, hits.t_m, 0.0).astype(np.float32)
    static = np.flatnonzero(hit & ~on_actor if given is None else hit & ~on_actor & ~known)
    near = np.zeros(n, bool)
    if len(static):
        p = np.take(rays, static, axis=0)
        x, y, z = (p[:, k] + p[:, 3 + k] * t[static] for k in range(3))
        near[static] = scene.near_actors(x.astype(np.float32), y.astype(np.float32), z.astype(np.float32),
                                         AO_RADIUS_M)
    rows = np.flatnonzero((on_actor | near) if given is None else (on_actor | near) & ~known)
    if not len(rows):
        return visibility
    period = n if period is None else int(period)

    def traced_share(which: np.ndarray) -> np.ndarray:
        """The share of the AO_SAMPLES rays from each hit ``which`` that something blocks within AO_RADIUS_M."""
        ao_rays = occlusion_rays(as_input(rays, np.float32), t, as_input(hits.normal, np.float32), which, _PATTERN,
                                 period)
        # From the world, only actors occlude (their contact shadow): the world's own occlusion is traced nowhere, so
        # tracing it near actors only would draw the edges of that region.
        static_rays = np.repeat(on_actor[which], AO_SAMPLES)
        blocked = scene.occluded_rays(ao_rays, AO_RADIUS_M, static_rays=static_rays).reshape(len(which), AO_SAMPLES)
        return blocked.mean(axis=1, dtype=np.float32)

    if image_shape is None:
        visibility[rows] = 1.0 - np.float32(AO_STRENGTH) * traced_share(rows)
        return visibility
    h, w = image_shape
    if h * w != n:
        raise ValueError(f"image_shape {image_shape} does not hold the {n} rays")
    # Pixel centres: every other pixel traces (a checkerboard), and each takes the mean over the traced pixels of its
    # surface within AO_FILTER_RADIUS_PX; a skipped pixel with none (a surface a pixel wide) traces its own.
    smooth = functools.partial(smooth_visibility, instance=as_input(hits.instance_id, np.int32),
                               normal=as_input(hits.normal, np.float32), t_m=t, height=h, width=w,
                               radius=AO_FILTER_RADIUS_PX, normal_cos=np.float32(AO_FILTER_NORMAL_COS),
                               depth=np.float32(AO_FILTER_DEPTH))
    per_pixel, traced, wanted = np.zeros(n, np.float32), np.zeros(n, bool), np.zeros(n, bool)
    first = rows[(rows // w + rows % w) % 2 == 0]
    per_pixel[first], traced[first] = traced_share(first), True
    skipped = rows[~traced[rows]]
    wanted[skipped] = True
    alone = skipped[np.isnan(smooth(per_pixel, traced, wanted)[skipped])]
    if len(alone):
        per_pixel[alone], traced[alone] = traced_share(alone), True
    wanted[rows] = True
    visibility[rows] = 1.0 - np.float32(AO_STRENGTH) * smooth(per_pixel, traced, wanted)[rows]
    return visibility


@kernel("Tuple((float32[:, ::1], float32[::1]))(float32[:, ::1], float32[::1], float32[:, ::1], int64[::1], "
        "float32[::1], float32[::1], float32)")
def mirror_rays(rays, t_m, normal, rows, f0, film, film_f0):
    """The mirror rays of the hits ``rows`` ((K, 6) float32, from the hit lifted 2 mm + 0.1 mm per metre along the
    normal, which faces the viewer) and their Fresnel weights F = F0 + (1 - F0) (1 - cos)^5 (Schlick), ``f0`` (K,)
    float32 per row, cos the angle between the view ray and the normal; where a row has a water ``film`` w > 0
    ((K,) float32), F + w F_film (1 - F) with F_film Schlick's of ``film_f0`` (:mod:`pipeline.sensors.wet`)."""
    out = np.empty((rows.size, 6), np.float32)
    weight = np.empty(rows.size, np.float32)
    for j in range(rows.size):
        i = rows[j]
        d0, d1, d2 = rays[i, 3], rays[i, 4], rays[i, 5]
        n0, n1, n2 = normal[i, 0], normal[i, 1], normal[i, 2]
        cos = -(d0 * n0 + d1 * n1 + d2 * n2)
        cos = min(max(cos, np.float32(0)), np.float32(1))
        lift = np.float32(2e-3) + np.float32(1e-4) * t_m[i]
        for k in range(3):
            out[j, k] = rays[i, k] + rays[i, 3 + k] * t_m[i] + normal[i, k] * lift
        out[j, 3] = d0 + np.float32(2) * cos * n0
        out[j, 4] = d1 + np.float32(2) * cos * n1
        out[j, 5] = d2 + np.float32(2) * cos * n2
        g = np.float32(1) - cos
        g2 = g * g
        weight[j] = f0[j] + (np.float32(1) - f0[j]) * g2 * g2 * g
        if film[j] > 0:
            water = film_f0 + (np.float32(1) - film_f0) * g2 * g2 * g
            weight[j] += film[j] * water * (np.float32(1) - weight[j])
    return out, weight


def reflections(scene: FrameScene, rays: np.ndarray, hits: Hits, radiance: np.ndarray, fresnel_f0: np.ndarray,
                sun: np.ndarray, colours: tuple[np.ndarray, ...], specular: np.ndarray,
                shininess: np.ndarray, film: np.ndarray | None = None) -> None:
    """Blend one bounce of mirror reflection into ``radiance`` ((N, 3) float32, in place) on hits of materials with
    ``fresnel_f0`` (M,) > 0: radiance = (1 - F) radiance + F env, env lit by ``sun`` (3,) and ``colours`` (sun and
    ambient, (3,) float32 each, and the sky's (SKY_PARAMS,) float32 parameters: :mod:`pipeline.sensors.sky`) without
    shadows, with the ``specular``/``shininess`` tables. ``film`` (N,) float32, optional: a water film's weight per
    hit (:mod:`pipeline.sensors.wet`), which strengthens F (:func:`mirror_rays`)."""
    f0 = fresnel_f0[hits.material]
    rows = np.flatnonzero(hits.hit & (f0 > 0) & (hits.t_m < INDIRECT_RANGE_M))
    if not len(rows):
        return
    t = np.where(hits.hit, hits.t_m, 0.0).astype(np.float32)
    water = np.zeros(len(rows), np.float32) if film is None else as_input(film[rows], np.float32)
    mirror, weight = mirror_rays(as_input(rays, np.float32), t, as_input(hits.normal, np.float32), rows,
                                 as_input(f0[rows], np.float32), water, np.float32(WATER_F0))
    bounce = scene.cast_rays(mirror)
    normal = as_input(bounce.normal, np.float32)
    # n.l as sun_rays computes it (float32, in this order), without the shadow rays: reflections are unshadowed.
    n_dot_l = normal[:, 0] * sun[0] + normal[:, 1] * sun[1] + normal[:, 2] * sun[2]
    lit = np.flatnonzero(n_dot_l > 0)
    t_b = bounce.t_m
    env = sky_and_sun(mirror, bounce.hit & (t_b <= MIRROR_RANGE_M), normal, as_input(bounce.material, np.int32),
                      as_input(bounce.color, np.float32), n_dot_l, lit, np.ones(len(lit), np.float32), specular,
                      shininess, sun, *colours)
    w = weight[:, None]
    radiance[rows] = radiance[rows] * (1.0 - w) + env * w
