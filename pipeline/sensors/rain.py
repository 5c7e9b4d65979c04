"""Rain streaks as a camera records them: the drops of a rain rate, each smeared over the exposure time.

A rain of R mm/h holds Marshall-Palmer drops (:mod:`pipeline.sensors.weather`); those of D >= STREAK_MIN_DIAMETER_MM
within STREAK_FAR_M of the camera are placed at random in its view (uniform in volume, a Poisson count from the
density), fall at their terminal speed plus the wind and move against the camera's own motion. Over the exposure time T
a drop at depth z draws a streak from its projection at the start to that at the end; its image has the diameter
d = fx D / z pixels. Spread over the streak's pixels, it covers each of them for a share of the exposure (Garg and Nayar
2007, "Vision and rain", IJCV 75): the drop's image area times T over the streak's area, alpha = (pi / 4) d^2 /
(max(L + d, 1) max(d, 1)) for a streak L pixels long (at least one pixel long and wide). Short exposures (a bright
day) freeze drops into dots, long ones (night) smear them into faint lines. The drops' coverage adds up (a Poisson
overlap: 1 - exp(-sum)), and a drop behind the surface its streak's middle sees is hidden.

A drop refracts light from a wide cone of directions (about 165 degrees) towards the camera, so its radiance hardly
depends on the background behind it (Garg and Nayar 2004): it is taken as the mean of the sky's radiance at the horizon
and the frame's mean radiance. At night the lamps light the drops besides (:func:`drop_radiance`): a drop scatters
their light towards the camera by its phase function, so streaks glow between the camera and an oncoming car's
headlamps and under street lamps, and hardly in the ego's own beams (light scattered back). Farther and smaller
drops are not drawn one by one: they dim the air as the rain's extinction
(:meth:`pipeline.sensors.conditions.Condition.fog`).
The lens is focused far away and its aperture is small (f/2 at a focal length of 2 mm), so even drops half a metre away
blur by about a pixel, which the streaks leave out.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pipeline.sensors.beams import PHASE_ASYMMETRY, henyey_greenstein
from pipeline.sensors.lights import spot_strength
from pipeline.sensors.weather import drops_per_m3, marshall_palmer_slope_per_mm, terminal_velocity_mps

if TYPE_CHECKING:
    from pipeline.core.geometry import Transform
    from pipeline.sensors.camera import Camera
    from pipeline.sensors.lights import SpotLights

STREAK_MIN_DIAMETER_MM = 0.5  # smaller drops are drawn only through the extinction
STREAK_MAX_DIAMETER_MM = 6.0  # larger drops break up as they fall
DIAMETER_STEP_MM = 0.05
STREAK_NEAR_M = 0.3  # nearer drops would sit on the windscreen or the housing
STREAK_FAR_M = 20.0
MIN_ALPHA = 2.0 / 255  # a streak covering less of its pixels changes none by more than two 8-bit levels: not drawn
MARGIN = 0.1  # drops are placed over the view widened by this share on each side, to streak in from outside


def _drops(rate_mm_h: float, camera: Camera, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) float64 start positions in the optical frame and (N,) diameters, mm, of the drops that can cover
    MIN_ALPHA of a pixel: a drop of diameter D images at most (pi / 4) (fx D / z)^2 of one, so only those nearer than
    fx D sqrt(pi / (4 MIN_ALPHA)) are drawn: per diameter bin a Poisson count of the drops in that part of the view."""
    w, h = camera.width, camera.height
    x0, x1 = (-camera.cx - MARGIN * w) / camera.fx, (w - camera.cx + MARGIN * w) / camera.fx
    y0, y1 = (-camera.cy - MARGIN * h) / camera.fy, (h - camera.cy + MARGIN * h) / camera.fy
    lam = marshall_palmer_slope_per_mm(rate_mm_h)
    lo = np.arange(STREAK_MIN_DIAMETER_MM, STREAK_MAX_DIAMETER_MM, DIAMETER_STEP_MM)
    per_m3 = drops_per_m3(rate_mm_h, 0.0) * (np.exp(-lam * lo) - np.exp(-lam * (lo + DIAMETER_STEP_MM)))
    far = np.clip(camera.fx * (lo + DIAMETER_STEP_MM) * 1e-3 * np.sqrt(np.pi / (4 * MIN_ALPHA)), STREAK_NEAR_M,
                  STREAK_FAR_M)
    counts = rng.poisson(per_m3 * (x1 - x0) * (y1 - y0) * (far ** 3 - STREAK_NEAR_M ** 3) / 3.0)
    n = int(counts.sum())
    u = rng.random((n, 4))
    diameter_mm = np.repeat(lo, counts) + u[:, 3] * DIAMETER_STEP_MM
    reach = np.repeat(far, counts)
    # Uniform in the frustum's volume: z with density ~ z^2, then uniform across the view at that depth.
    z = np.cbrt(STREAK_NEAR_M ** 3 + u[:, 0] * (reach ** 3 - STREAK_NEAR_M ** 3))
    return np.column_stack([(x0 + u[:, 1] * (x1 - x0)) * z, (y0 + u[:, 2] * (y1 - y0)) * z, z]), diameter_mm


def streak_coverage(rate_mm_h: float, wind_mps: tuple[float, float], exposure_s: float, camera: Camera,
                    cam_to_world: Transform, camera_velocity_mps: np.ndarray, depth_m: np.ndarray,
                    rng: np.random.Generator, lights: SpotLights | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(H, W) float32 share of each pixel's exposure that falling drops cover, in [0, 1); and, with ``lights`` (the
    frame's spot lights, at night), (H, W, 3) float32 the radiance the drops add by scattering them (None without).

    ``cam_to_world`` places the camera's optical frame (x right, y down, z forward); ``camera_velocity_mps`` (3,) is its
    world velocity; ``depth_m`` (H, W) the z-depth of what each pixel sees (0: nothing, the sky). Draws from ``rng``:
    the drop counts per diameter, then the drops' positions and diameters (the same with lights or without)."""
    h, w = camera.height, camera.width
    out = np.zeros(h * w, np.float64)
    lit = None if lights is None or not len(lights) else np.zeros((3, h * w), np.float64)
    start, diameter_mm = _drops(rate_mm_h, camera, rng)
    n, z = len(start), start[:, 2]
    if n == 0 or exposure_s <= 0:
        return out.reshape(h, w).astype(np.float32), _image(lit, h, w)
    fall = np.zeros((n, 3))
    fall[:, 0], fall[:, 1] = wind_mps
    fall[:, 2] = -terminal_velocity_mps(diameter_mm)
    relative = (fall - np.asarray(camera_velocity_mps, np.float64)) @ cam_to_world.rotation  # world -> optical
    end = start + relative * exposure_s
    end[:, 2] = np.maximum(end[:, 2], STREAK_NEAR_M)
    uv0, _ = camera.project(start)
    uv1, _ = camera.project(end)
    d_px = camera.fx * diameter_mm * 1e-3 / z
    length_px = np.hypot(*(uv1 - uv0).T)
    alpha = (np.pi / 4) * d_px ** 2 / (np.maximum(length_px + d_px, 1.0) * np.maximum(d_px, 1.0))
    # Hidden behind the surface its streak's middle (within the image) sees.
    mid = np.nan_to_num(0.5 * (uv0 + uv1), nan=-1.0)
    col = np.clip(np.floor(mid[:, 0]), 0, w - 1).astype(np.int64)
    row = np.clip(np.floor(mid[:, 1]), 0, h - 1).astype(np.int64)
    behind = depth_m.reshape(-1)[row * w + col]
    seen = (behind == 0) | (z < behind)
    keep = np.flatnonzero(seen & (alpha >= MIN_ALPHA) & np.isfinite(length_px))
    if not len(keep):
        return out.reshape(h, w).astype(np.float32), _image(lit, h, w)
    # Each streak is sampled once per pixel of its length, every sample carrying the streak's coverage.
    steps = np.maximum(np.ceil(length_px[keep]).astype(np.int64), 1)
    which = np.repeat(keep, steps)
    first = np.cumsum(steps) - steps
    t = (np.arange(len(which)) - np.repeat(first, steps) + 0.5) / np.repeat(steps, steps)
    p = uv0[which] + (uv1[which] - uv0[which]) * t[:, None] - 0.5  # pixel centres at integers
    _splat(out, p, alpha[which], h, w)
    if lit is not None:  # each drop at its streak's middle, lit by the lamps
        radiance = np.zeros((n, 3))
        radiance[keep] = drop_radiance(lights, cam_to_world.apply(0.5 * (start[keep] + end[keep])),
                                       cam_to_world.translation)
        for c in range(3):
            _splat(lit[c], p, alpha[which] * radiance[which, c], h, w)
    return (-np.expm1(-out)).reshape(h, w).astype(np.float32), _image(lit, h, w)


def _image(lit: np.ndarray | None, h: int, w: int) -> np.ndarray | None:
    return None if lit is None else np.ascontiguousarray(lit.T.reshape(h, w, 3), dtype=np.float32)


def drop_radiance(lights: SpotLights, points_m: np.ndarray, camera_m: np.ndarray) -> np.ndarray:
    """(K, 3) float64 radiance towards the camera at ``camera_m`` of raindrops at (K, 3) world ``points_m`` lit by
    ``lights``: per light, its irradiance there (:func:`pipeline.sensors.lights.spot_strength` x its rgb; no shadows)
    times the drop's phase function at the angle between the light's way and the way on to the camera.

    A drop of cross-section A scatters E A p(theta) per steradian (its scattering efficiency outside the narrow
    diffraction peak is 1) and shows the camera the same area A, so its radiance is E p(theta): a Henyey-Greenstein
    p with the asymmetry of the fog's droplets (:data:`pipeline.sensors.beams.PHASE_ASYMMETRY`, 0.85; large water
    spheres' geometric optics give about the same). Lit from behind the camera (the ego's own beams) a drop returns
    p(180 deg) = 0.0035 /sr of the light; between the camera and a lamp facing it, forward, up to 6.5 /sr."""
    x = np.asarray(points_m, np.float64)
    out = np.zeros((len(x), 3))
    to_camera = np.asarray(camera_m, np.float64) - x
    to_camera /= np.maximum(np.linalg.norm(to_camera, axis=1, keepdims=True), 1e-9)
    for k in range(len(lights)):
        v = (lights.position_m[k] - x).astype(np.float32)  # from each drop to the light
        axial = -(v @ lights.axis[k].astype(np.float32))
        ahead = np.flatnonzero(axial > 0)
        if not len(ahead):
            continue
        va = v[ahead]
        d2 = np.einsum("ij,ij->i", va, va)
        strength = spot_strength(lights, k, [va[:, 0], va[:, 1], va[:, 2]], d2, axial[ahead])
        cos_theta = -np.einsum("ij,ij->i", va.astype(np.float64), to_camera[ahead]) / np.sqrt(d2)
        p = henyey_greenstein(cos_theta.astype(np.float32), PHASE_ASYMMETRY)
        out[ahead] += (strength * p)[:, None].astype(np.float64) * lights.rgb[k].astype(np.float64)
    return out


def _splat(out: np.ndarray, p: np.ndarray, weight: np.ndarray, h: int, w: int) -> None:
    """Add (K,) ``weight`` at (K, 2) sub-pixel positions (x, y; pixel centres at integers) into the (H*W,) ``out``,
    bilinearly."""
    base = np.floor(p)
    frac = p - base
    bx, by = base[:, 0].astype(np.int64), base[:, 1].astype(np.int64)
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        x, y = bx + dx, by + dy
        share = (frac[:, 0] if dx else 1.0 - frac[:, 0]) * (frac[:, 1] if dy else 1.0 - frac[:, 1])
        ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        out += np.bincount(y[ok] * w + x[ok], weights=weight[ok] * share[ok], minlength=h * w)
