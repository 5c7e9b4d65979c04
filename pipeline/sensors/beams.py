"""Beams in fog: the light that fog and rain scatter out of the frame's spot lights into the camera.

At night in fog the cones of street lamps and the beams of headlights show in the air itself, and the ego's own low
beams lay a bright veil over the view ahead (the reason to drive on low beams in fog). Each camera ray, from the
camera to its hit (to the lights' reach for a ray that hits nothing), gathers the light singly scattered towards the
camera (single scattering):

    L = pi * sum over lights of  integral of  beta * p(theta) * E(x) * exp(-beta * (s + d(x))) ds

with x the point at distance s along the ray, E(x) the light's irradiance there (the spot-light model of
:mod:`pipeline.sensors.lights`: cone, soft edge, beam pattern, inverse square, range window; the surfaces' own
:func:`pipeline.sensors.lights.cone_terms`), d(x) its distance to the light, beta the air's extinction
(:meth:`pipeline.sensors.conditions.Condition.extinction_per_m`; water droplets absorb almost nothing at visible
wavelengths, so they scatter all they remove), p the Henyey-Greenstein phase function with the asymmetry
PHASE_ASYMMETRY of fog droplets, and theta the angle between the light's path and the way on to the camera. The
factor pi turns radiance into the renderer's units (a white Lambertian surface under irradiance E reads E).
Scattering within FORWARD_LOBE_DEG of the light's own direction is left out: that is the lobe the haloes round
glowing sources already draw (:meth:`~pipeline.sensors.conditions.Condition.halos`), so a lamp that shines at the
camera is not counted twice. Not modelled: shadows inside the beams (an object in a beam does not darken the air
behind it), multiple scattering (beyond the haloes' lobes).

Cost: the integral along a ray changes slowly across the image but sharply with where the ray ends, so it is
tabulated, as a running sum over DISTANCE_BINS distances, on the rays of every COARSE_PX-th pixel; each pixel reads
the four tables around it at its own hit distance (bilinear across the image, linear between distances).
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import as_input, kernel
from pipeline.sensors.lights import MIN_DISTANCE_M, SpotLights, cone_terms, light_params

# Fog droplets (effective radii ~5-15 um) at visible wavelengths: Henyey-Greenstein asymmetry g ~ 0.85 (Mie theory for
# water clouds; Hansen and Travis 1974, "Light scattering in planetary atmospheres", Space Sci. Rev. 16, fig. 10).
PHASE_ASYMMETRY = 0.85
FORWARD_LOBE_DEG = 20.0  # the haloes' share: about 2.5 sigma of their widest lobe (conditions.HALO_LOBES)
COARSE_PX = 16
DISTANCE_BINS = 64
MAX_DISTANCE_M = 200.0  # tables end here: beyond, a light at the range of the night's conditions adds nothing
# Samples per ray and light: over the half circle a ray subtends at a light it passes close by, 0.7 degrees apart
# seen from the light (a low beam's cut-off is ~1 degree wide), as many over a shorter arc, at least MIN_ANGLE_SAMPLES.
ANGLE_SAMPLES = 256
MIN_ANGLE_SAMPLES = 16
# ... and no sample stands for more of the ray than the larger of these (far from a light an angular step is long).
MAX_STRETCH_M = 0.5
MAX_STRETCH_SHARE = 0.03  # of the sample's distance from the camera


def henyey_greenstein(cos_theta: np.ndarray, g: float) -> np.ndarray:
    """The Henyey-Greenstein phase function (per steradian; its integral over the sphere is 1) at ``cos_theta``, the
    cosine of the angle between the incoming light's direction of travel and the scattered light's."""
    g = np.float32(g)
    return (1 - g * g) / (np.float32(4 * np.pi) * (1 + g * g - 2 * g * cos_theta) ** np.float32(1.5))


def distance_edges(max_distance_m: float, bins: int = DISTANCE_BINS) -> np.ndarray:
    """(bins + 1,) float32 distances along a ray, quadratically spaced from 0 to ``max_distance_m`` (fine near the
    camera, where the ego's beams are, coarse far off)."""
    return (max_distance_m * (np.arange(bins + 1, dtype=np.float64) / bins) ** 2).astype(np.float32)


def light_rows(lights: SpotLights, origin: np.ndarray) -> np.ndarray:
    """(L, P) float32 the lights' values as :func:`pipeline.sensors.lights.cone_terms` reads them, their positions
    relative to ``origin``."""
    rows = np.stack([light_params(lights, k) for k in range(len(lights))]).astype(np.float32)
    rows[:, :3] = (lights.position_m - np.asarray(origin, np.float64)).astype(np.float32)
    return np.ascontiguousarray(rows)


@kernel("float32[:, :, ::1](float32[:, ::1], float32[:, ::1], float32[:, ::1], float32[::1], float64, float64, "
        "float64, int64)")
def _tables(directions, lights, rgb, edges, beta, g, cos_min, samples):
    """See :func:`inscatter_tables`: per ray and light, points uniform in the angle they subtend at the light
    (``samples`` over a half circle: they gather where the ray passes it, and the inverse square integrates
    exactly), each deposited in the distance bin it falls in; then the running sum over bins."""
    m, bins, n = directions.shape[0], edges.size - 1, lights.shape[0]
    out = np.zeros((m, bins + 1, 3), np.float32)
    end = np.float64(edges[bins])
    g2 = g * g
    for i in range(m):
        dx, dy, dz = np.float64(directions[i, 0]), np.float64(directions[i, 1]), np.float64(directions[i, 2])
        for k in range(n):
            px, py, pz = np.float64(lights[k, 0]), np.float64(lights[k, 1]), np.float64(lights[k, 2])
            reach = np.sqrt(np.float64(lights[k, 12]))  # the row holds range^2
            foot = px * dx + py * dy + pz * dz
            miss2 = max(px * px + py * py + pz * pz - foot * foot, 0.0)
            if miss2 >= reach * reach:
                continue
            half = np.sqrt(reach * reach - miss2)
            s0, s1 = max(foot - half, 0.0), min(foot + half, end)
            if s1 <= s0:
                continue
            gap = max(np.sqrt(miss2), MIN_DISTANCE_M)
            a0, a1 = np.arctan((s0 - foot) / gap), np.arctan((s1 - foot) / gap)
            count = max(MIN_ANGLE_SAMPLES, int(np.ceil(samples * (a1 - a0) / np.pi)))  # the same angular step
            step = (a1 - a0) / count
            j = 0
            for q in range(count):
                # Far from the light a step of angle is a long stretch of the ray: split it so that no sample
                # stands for more than MAX_STRETCH of the ray's length (a beam's edge crossed far off).
                lo, hi = a0 + q * step, a0 + (q + 1) * step
                length = gap * (np.tan(hi) - np.tan(lo))
                parts = max(1, int(np.ceil(length / max(MAX_STRETCH_M, MAX_STRETCH_SHARE * (foot + gap * np.tan(lo))))))
                sub = step / parts
                for r in range(parts):
                    s = foot + gap * np.tan(lo + (r + 0.5) * sub)
                    vx, vy, vz = px - dx * s, py - dy * s, pz - dz * s
                    d2 = vx * vx + vy * vy + vz * vz
                    axial = -(vx * lights[k, 3] + vy * lights[k, 4] + vz * lights[k, 5])
                    if axial <= 0.0 or d2 >= lights[k, 12]:
                        continue
                    cone, pattern = cone_terms(lights[k], np.float32(vx), np.float32(vy), np.float32(vz),
                                               np.float32(d2), np.float32(axial))
                    factor = np.float64(cone) * np.float64(pattern)
                    if factor <= 0.0:
                        continue
                    dist = np.sqrt(d2)
                    cos_theta = (vx * dx + vy * dy + vz * dz) / max(dist, 1e-9)
                    if cos_theta >= cos_min:
                        continue
                    base = 1.0 + g2 - 2.0 * g * cos_theta
                    phase = (1.0 - g2) / (4.0 * np.pi * base * np.sqrt(base))
                    w = np.pi * beta * phase * factor * (sub / gap) * np.exp(-beta * (s + dist))
                    while j < bins - 1 and edges[j + 1] <= s:
                        j += 1
                    # The sample stands for the stretch [s_lo, s_hi]: its share beyond either edge of its bin goes to
                    # the neighbouring bin, so the running sums at the edges do not step by a sample's weight.
                    s_lo, s_hi = foot + gap * np.tan(lo + r * sub), foot + gap * np.tan(lo + (r + 1) * sub)
                    span = max(s_hi - s_lo, 1e-12)
                    before = max(edges[j] - s_lo, 0.0) / span if j > 0 else 0.0
                    after = max(s_hi - edges[j + 1], 0.0) / span if j < bins - 1 else 0.0
                    for c in range(3):
                        value = w * rgb[k, c]
                        out[i, j + 1, c] += np.float32(value * (1.0 - before - after))
                        if before > 0.0:
                            out[i, j, c] += np.float32(value * before)
                        if after > 0.0:
                            out[i, j + 2, c] += np.float32(value * after)
        for j in range(1, bins + 1):
            for c in range(3):
                out[i, j, c] += out[i, j - 1, c]
    return out


def inscatter_tables(origin: np.ndarray, directions: np.ndarray, lights: SpotLights, extinction_per_m: float,
                     edges: np.ndarray, *, g: float = PHASE_ASYMMETRY, forward_lobe_deg: float = FORWARD_LOBE_DEG,
                     samples: int = ANGLE_SAMPLES) -> np.ndarray:
    """(M, B + 1, 3) float32 light scattered into M rays from ``origin`` (3,) along unit ``directions`` (M, 3),
    accumulated from the camera to each of the B + 1 distances ``edges`` (edges[0] = 0: zero), in the renderer's
    radiance units before the condition's exposure (see the module docstring). Each light is sampled along each ray
    within its range at points uniform in the angle they subtend at the light, ``samples`` to a half circle
    (equiangular sampling: dense where the ray passes the light, where the cone's edges and the phase change
    fastest, and exact for the inverse square, whose closest approach is clamped at MIN_DISTANCE_M as the surfaces'
    shading clamps it), no sample standing for more than MAX_STRETCH_M or MAX_STRETCH_SHARE of its distance."""
    if not len(lights) or extinction_per_m <= 0 or not len(directions):
        return np.zeros((len(directions), len(edges), 3), np.float32)
    rgb = np.ascontiguousarray(lights.rgb, np.float32)
    return _tables(as_input(directions, np.float32), light_rows(lights, origin), rgb, as_input(edges, np.float32),
                   float(extinction_per_m), float(g), float(np.cos(np.radians(forward_lobe_deg))), int(samples))


def coarse_grid(height: int, width: int, step: int = COARSE_PX) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the pixels whose rays are tabulated: every ``step``-th, and the last."""
    rows = np.unique(np.append(np.arange(0, height, step), height - 1))
    cols = np.unique(np.append(np.arange(0, width, step), width - 1))
    return rows, cols


def beams(origin: np.ndarray, pixel_directions: np.ndarray, distance_m: np.ndarray, shape: tuple[int, int],
          lights: SpotLights, extinction_per_m: float, *, step: int = COARSE_PX) -> np.ndarray:
    """(H*W, 3) float32 in-scattered radiance for every pixel (renderer units, before the exposure):
    ``pixel_directions`` (H*W, 3) unit world directions of the pixel rays from ``origin``, ``distance_m`` (H*W,)
    where each ends (inf: it hits nothing)."""
    h, w = shape
    if not len(lights) or extinction_per_m <= 0:
        return np.zeros((h * w, 3), np.float32)
    o = np.asarray(origin, np.float64)
    reach = max(float(np.linalg.norm(lights.position_m - o, axis=1).max() + lights.range_m.max()), 1.0)
    edges = distance_edges(min(reach, MAX_DISTANCE_M))
    rows, cols = coarse_grid(h, w, step)
    dirs = np.asarray(pixel_directions, np.float32).reshape(h, w, 3)[rows][:, cols].reshape(-1, 3)
    tables = inscatter_tables(o, dirs, lights, extinction_per_m, edges).reshape(len(rows), len(cols), -1, 3)
    # Each pixel: its distance's place between two edges, in the four tables around it.
    t = np.minimum(np.asarray(distance_m, np.float32), edges[-1])  # a ray to the sky reads the table's end
    j = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(edges) - 2)
    frac = ((t - edges[j]) / (edges[j + 1] - edges[j])).astype(np.float32)[:, None]
    y, x = np.divmod(np.arange(h * w), w)
    r0, r1, wy = _between(rows, y)
    c0, c1, wx = _between(cols, x)

    def at(r, c):
        low, high = tables[r, c, j], tables[r, c, j + 1]
        return low + frac * (high - low)

    top = at(r0, c0) * (1 - wx) + at(r0, c1) * wx
    bottom = at(r1, c0) * (1 - wx) + at(r1, c1) * wx
    return (top * (1 - wy) + bottom * wy).astype(np.float32)


def _between(grid: np.ndarray, at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each of ``at`` (pixel rows or columns), the grid entries on either side (indices) and the (K, 1) float32
    weight of the second; a single-entry grid gives that entry, weight 0."""
    second = np.clip(np.searchsorted(grid, at, side="left"), 0, len(grid) - 1)
    first = np.maximum(second - 1, 0)
    span = grid[second] - grid[first]
    weight = np.where(span > 0, (at - grid[first]) / np.maximum(span, 1), 0.0)
    return first, second, weight.astype(np.float32)[:, None]
