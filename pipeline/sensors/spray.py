"""Spray that vehicles throw up from a wet road: a cloud of droplets behind and beside each moving vehicle, which
dims what the camera and the LiDAR see through it and veils it in the light the droplets scatter.

A tyre rolling through the road's water ejects it as splash (large drops on ballistic paths, which fall back within a
metre or two) and spray (drops of ~0.1 mm and less, which the vehicle's wake carries along and lifts): the cloud
drivers know behind a lorry. Each vehicle of :data:`SPRAY_CLASSES` driving at least :data:`MIN_SPEED_MPS` gets one
cloud, in its own frame (a: backwards from the rear bumper, y: to its left, z: up from the road):

    beta(a, y, z) = beta0 exp(-a^2 / 2 sa^2 - y^2 / 2 sy^2 - z^2 / 2 sz^2),   -front <= a,  z >= 0,

densest at the rear at road level, thinning behind over ``sa``, across over ``sy`` and upwards over ``sz``; it
starts at the front wheels (``front``: the spray beside the vehicle, which its body hides from most views). The
peak extinction ``beta0`` grows with the speed and the water on the road (:func:`spray_clouds`; the values and their
sources are beside :data:`CAR` and :data:`HEAVY`, and in docs/realism.md). The drops are large against the wavelengths
of the camera and the LiDAR (extinction efficiency 2, as for rain: :mod:`pipeline.sensors.weather`), so one
extinction serves both.

A ray's optical depth through a cloud is the integral of beta along it, in closed form: along a ray p(t) = p0 + t e
the exponent is a quadratic in t, so tau = beta0 exp(-E) sqrt(pi / 4A) (erf(sqrt(A) (t1 - tv)) - erf(sqrt(A) (t0 -
tv))) over the part [t0, t1] of the ray within the cloud's bounds (``front``, and SPRAY_SIGMAS standard deviations
elsewhere) and before its hit (:func:`optical_depths`). The camera sees L = L0 T + L_air (1 - T), T = exp(-tau), with
the airlight of the condition's fog and rain (the droplets scatter the same overcast sky); the LiDAR's pulse loses
exp(-2 tau) both ways. Ground truth is unchanged: spray hides nothing from the labels (as fog).

The spray's own returns to the LiDAR are a soft target, as the fog's (:mod:`pipeline.sensors.backscatter`): along
each beam that meets a cloud, the pulse's echo from the spray and the air together (:func:`sweep_soft_returns`). At
the model's densities they stay below the threshold of the default LiDAR (at most half of it on the highway frames
docs/realism.md reports); three times as dense, a cloud just ahead of the sensor returns points.

Not modelled: the spray's light from lamps at night (the veil takes the sky's radiance), the ego's own spray,
splash, and the turbulence that makes a real cloud lumpy and changing from frame to frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D
from pipeline.core.jit import as_input, kernel
from pipeline.sensors.backscatter import cell_weights, waveform_peak, window_phases

if TYPE_CHECKING:
    from pipeline.core.geometry import Transform
    from pipeline.sensors.camera import Camera
    from pipeline.world.actors import Actors


@dataclass(frozen=True)
class SprayShape:
    """A class of vehicle's spray cloud at REFERENCE_SPEED_MPS on a road holding REFERENCE_WATER_MM of water.

    Attributes:
        peak_per_m: beta0, extinction at the rear bumper at road level, 1/m.
        length_m: sa, the Gaussian's standard deviation backwards from the rear bumper, m.
        spread_m: added to half the vehicle's width for sy, m.
        height_m: sz, m.
        front: the cloud starts this share of the vehicle's length ahead of its rear bumper (the front wheels).
    """

    peak_per_m: float
    length_m: float
    spread_m: float
    height_m: float
    front: float = 0.8


# No published extinction of a spray cloud was found (the laser transmissometer studies' tables: TRRL RR162, Dumas
# and Lemay 2009, VTI 171A, were out of reach); the peaks are estimated from the water a tyre lifts. A car's two
# tyre tracks (~0.4 m) through 1 mm of water at 25 m/s lift ~10 l/s; if ~2 % of it breaks into droplets fine enough
# to stay aloft (tyre spray's drops shrink as the Weber number's -1/2 power: Radovich, Plocher and Browand 2014,
# ~0.1-0.2 mm at motorway speeds; radius r ~ 50 um taken), spread over the wake's ~3 m2 moving past at the vehicle's
# speed, the liquid water content is ~3 g/m3 and beta = 3 Q LWC / (4 rho r) with Q = 2 is ~0.08 /m. Taken: 0.05 for
# cars, 0.12 for lorries and buses (more and larger tyres). Heights: cars' spray reaches ~1.5 m, lorries' their
# windscreens and beyond, 3-4 m (Sherard 1971: air currents set up by the wheels lift it). These are estimates to
# be replaced by measured clouds: docs/realism.md.
CAR = SprayShape(peak_per_m=0.05, length_m=8.0, spread_m=0.4, height_m=0.8)
HEAVY = SprayShape(peak_per_m=0.12, length_m=16.0, spread_m=1.0, height_m=1.8)
SPRAY_CLASSES = {ObjectClass.CAR: CAR, ObjectClass.VAN: CAR, ObjectClass.MOTORCYCLE: CAR,
                 ObjectClass.TRUCK: HEAVY, ObjectClass.BUS: HEAVY}
REFERENCE_SPEED_MPS = 25.0  # 90 km/h
REFERENCE_WATER_MM = 1.0
# Below 48 km/h spray is "scarcely measurable", above 64 km/h "a problem" (TRRL report VSE 513, 1979, lorries at
# 32-96 km/h over a controlled water depth): the peak grows from 45 km/h as a power of the speed above it (the
# exponent assumed: more water lifted, broken into finer drops).
MIN_SPEED_MPS = 12.5
SPEED_EXPONENT = 1.5
MAX_SPEED_MPS = 50.0  # the peak stops growing here
SPRAY_SIGMAS = 3.0  # clouds end this many standard deviations out (exp(-4.5): 1 % of the peak)


@dataclass(frozen=True)
class SprayClouds:
    """The spray clouds of one frame, K of them, struct of arrays (world frame).

    Attributes:
        origin: (K, 3) float64 the rear bumper's middle at road level.
        axes: (K, 3, 3) float64 rotation whose columns are the cloud's a (backwards), y (left) and z (up) axes.
        sigma: (K, 3) float64 sa, sy, sz, m.
        lo, hi: (K, 3) float64 the cloud's bounds in its own frame (a from -front, z from 0; elsewhere SPRAY_SIGMAS
            standard deviations).
        peak_per_m: (K,) float64 beta0.
        actor: (K,) int64 the vehicle's index among the frame's actors.
    """

    origin: np.ndarray
    axes: np.ndarray
    sigma: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    peak_per_m: np.ndarray
    actor: np.ndarray

    def __len__(self) -> int:
        return len(self.peak_per_m)

    def take(self, index: np.ndarray) -> SprayClouds:
        """The clouds at ``index`` (an integer or boolean array)."""
        return SprayClouds(self.origin[index], self.axes[index], self.sigma[index], self.lo[index], self.hi[index],
                           self.peak_per_m[index], self.actor[index])

    @property
    def boxes(self) -> Boxes3D:
        """Each cloud's bounds as a world box (its a axis, backwards from the vehicle, as the box's heading)."""
        centre = np.einsum("kij,kj->ki", self.axes, 0.5 * (self.lo + self.hi)) + self.origin
        return Boxes3D(centre, self.hi - self.lo, np.arctan2(self.axes[:, 1, 0], self.axes[:, 0, 0]))

    def world_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, 3) lo and hi of each cloud's axis-aligned world box (its bounds' eight corners)."""
        corners = self.boxes.corners()
        return corners.min(axis=1), corners.max(axis=1)


NO_SPRAY = SprayClouds(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)),
                       np.zeros(0), np.zeros(0, np.int64))


def spray_factor(speed_mps: np.ndarray) -> np.ndarray:
    """(N,) float64: the peak extinction's share of the reference at each forward speed v: ((v - MIN_SPEED_MPS) /
    (REFERENCE_SPEED_MPS - MIN_SPEED_MPS)) ** SPEED_EXPONENT, 0 below MIN_SPEED_MPS, v at most MAX_SPEED_MPS."""
    v = np.minimum(np.asarray(speed_mps, np.float64), MAX_SPEED_MPS)
    ratio = np.maximum(v - MIN_SPEED_MPS, 0.0) / (REFERENCE_SPEED_MPS - MIN_SPEED_MPS)
    return ratio ** SPEED_EXPONENT


def spray_clouds(actors: Actors, velocity_mps: np.ndarray | None, water_mm: float, scale: float = 1.0,
                 active: np.ndarray | None = None) -> SprayClouds:
    """The spray of a frame's ``actors``: one cloud per vehicle of SPRAY_CLASSES (among the ``active`` ones, if
    given) whose (A, 3) world ``velocity_mps`` along its heading exceeds MIN_SPEED_MPS, on a road holding
    ``water_mm`` of water (:func:`pipeline.sensors.weather.road_water_mm`); peaks in proportion to it (the water the
    tyres lift) and times ``scale`` (the condition's ``rain.spray``). None or a dry road: no clouds."""
    if velocity_mps is None or water_mm <= 0 or scale <= 0 or not len(actors):
        return NO_SPRAY
    boxes = actors.boxes
    velocity = np.asarray(velocity_mps, np.float64).reshape(-1, 3)
    if len(velocity) != len(actors):
        raise ValueError(f"velocity_mps must be ({len(actors)}, 3), one row per actor; got {velocity.shape}")
    heading = np.column_stack([np.cos(boxes.yaw_rad), np.sin(boxes.yaw_rad), np.zeros(len(actors))])
    factor = spray_factor(np.einsum("ij,ij->i", velocity, heading))
    shape_of = [SPRAY_CLASSES.get(c) for c in actors.object_class]
    keep = factor > 0
    keep &= np.array([s is not None for s in shape_of], bool)
    if active is not None:
        keep &= np.asarray(active, bool)
    rows = np.flatnonzero(keep)
    if not len(rows):
        return NO_SPRAY
    shapes = [shape_of[i] for i in rows]
    length, width = boxes.size[rows, 0], boxes.size[rows, 1]
    back = -heading[rows]
    left = np.column_stack([-heading[rows, 1], heading[rows, 0], np.zeros(len(rows))])
    up = np.broadcast_to([0.0, 0.0, 1.0], (len(rows), 3))
    axes = np.stack([back, left, up], axis=2)
    origin = boxes.center[rows] + back * (0.5 * length)[:, None]
    origin[:, 2] = boxes.center[rows, 2] - 0.5 * boxes.size[rows, 2]
    sigma = np.column_stack([[s.length_m for s in shapes], 0.5 * width + [s.spread_m for s in shapes],
                             [s.height_m for s in shapes]])
    lo = np.column_stack([-np.array([s.front for s in shapes]) * length, -SPRAY_SIGMAS * sigma[:, 1],
                          np.zeros(len(rows))])
    hi = SPRAY_SIGMAS * sigma
    peak = np.array([s.peak_per_m for s in shapes]) * factor[rows] * (float(water_mm) / REFERENCE_WATER_MM * scale)
    return SprayClouds(origin, np.ascontiguousarray(axes), sigma, lo, np.ascontiguousarray(hi), peak,
                       rows.astype(np.int64))


def optical_depths(clouds: SprayClouds, rays: np.ndarray, ends_m: np.ndarray, rows: np.ndarray | None = None,
                   tiles: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(N,) float32: each ray's optical depth through the ``clouds`` up to its end (``rays`` (N, 6) float32 [origin
    | unit direction], world; ``ends_m`` (N,) the hit distance, inf where nothing is hit). ``rows``: only these rays
    (the others get 0). ``tiles``: which clouds each of the ``rows`` may meet, ((R,) int64 a tile per row, (T + 1,)
    int64 each tile's first entry in (M,) int64 cloud indices); by default every cloud (:func:`camera_optical_depths`
    gives a camera's)."""
    n = len(rays)
    if not len(clouds) or not n:
        return np.zeros(n, np.float32)
    rows = np.arange(n) if rows is None else np.asarray(rows, np.int64)
    if tiles is None:
        tiles = (np.zeros(len(rows), np.int64), np.array([0, len(clouds)], np.int64), np.arange(len(clouds)))
    boxes = clouds.boxes
    centre, radius = boxes.center, 0.5 * np.linalg.norm(boxes.size, axis=1)
    return _optical_depths(as_input(rays, np.float32), as_input(ends_m, np.float64), as_input(rows, np.int64),
                           *(as_input(a, np.int64) for a in tiles),
                           as_input(clouds.origin, np.float64), as_input(clouds.axes, np.float64),
                           as_input(clouds.sigma, np.float64), as_input(clouds.lo, np.float64),
                           as_input(clouds.hi, np.float64), as_input(clouds.peak_per_m, np.float64),
                           as_input(centre, np.float64), as_input(radius, np.float64))


def _packed(lists: list[list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Per-tile cloud lists packed for :func:`optical_depths`' ``tiles``: (T + 1,) int64 each tile's first entry and
    (M,) int64 the entries."""
    start = np.concatenate([[0], np.cumsum([len(x) for x in lists])]).astype(np.int64)
    return start, np.array([k for x in lists for k in x], np.int64)


TILE_CELLS = 16  # a camera's clouds are listed per tile of this many pixels square


def camera_optical_depths(clouds: SprayClouds, camera: Camera, cam_to_world: Transform, rays: np.ndarray,
                          ends_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pixels of ``camera`` whose centre ray (``rays``, ``ends_m`` as in :func:`optical_depths`, H*W of them)
    may pass a cloud, (R,) int64, and their optical depths, (R,) float32. Each cloud's bounds are projected to a
    rectangle (:meth:`pipeline.sensors.camera.Camera.boxes_pixel_rects`) and listed for the tiles it covers; a
    pixel tests only its tile's clouds."""
    index, rect_lo, rect_hi = camera.boxes_pixel_rects(cam_to_world, *clouds.world_bounds())
    (grid_h, grid_w), cells = camera.pixel_cells
    tiles_h, tiles_w = -(-grid_h // TILE_CELLS), -(-grid_w // TILE_CELLS)
    first = np.clip(rect_lo // TILE_CELLS, 0, [tiles_h - 1, tiles_w - 1])
    last = np.clip(rect_hi // TILE_CELLS, 0, [tiles_h - 1, tiles_w - 1])
    shown = np.flatnonzero(np.all((rect_hi >= 0) & (rect_lo < [grid_h, grid_w]), axis=1))
    lists: list[list[int]] = [[] for _ in range(tiles_h * tiles_w)]
    for k in shown[np.argsort(index[shown], kind="stable")]:  # each tile's clouds in the clouds' order
        for r in range(first[k, 0], last[k, 0] + 1):
            for c in range(first[k, 1], last[k, 1] + 1):
                lists[r * tiles_w + c].append(int(index[k]))
    start, members = _packed(lists)
    cell = np.arange(grid_h * grid_w, dtype=np.int64) if cells is None else cells
    tile = (cell // grid_w) // TILE_CELLS * tiles_w + (cell % grid_w) // TILE_CELLS
    rows = np.flatnonzero(np.diff(start)[tile] > 0)
    tau = optical_depths(clouds, rays, ends_m, rows, (tile[rows], start, members))
    return rows, tau[rows]


AZIMUTH_BINS = 720  # a sensor's clouds are listed per half degree of azimuth round its origin


def sweep_optical_depths(clouds: SprayClouds, rays: np.ndarray, ends_m: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """As :func:`optical_depths` for ``rows`` of rays that share one origin (a LiDAR's sweep): a ray tests only the
    clouds of its bin of azimuth (:func:`sweep_tiles`)."""
    rows = np.asarray(rows, np.int64)
    if not len(clouds) or not len(rows):
        return np.zeros(len(rays), np.float32)
    return optical_depths(clouds, rays, ends_m, rows, sweep_tiles(clouds, rays, rows))


def sweep_tiles(clouds: SprayClouds, rays: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which clouds each of ``rows`` (rays sharing one origin, a LiDAR's sweep; at least one) may meet, as
    :func:`optical_depths`' ``tiles``: each cloud is listed for the bins of azimuth its footprint spans seen from the
    origin (a convex footprint's extreme corners bound them; a footprint round the origin spans every bin)."""
    origin = np.asarray(rays[rows[0], :3], np.float64)
    rel = clouds.boxes.corners()[:, :4, :2] - origin[:2]  # the footprints' corners (the bottom four)
    mid = np.arctan2(rel[:, :, 1].mean(axis=1), rel[:, :, 0].mean(axis=1))
    offset = np.angle(np.exp(1j * (np.arctan2(rel[:, :, 1], rel[:, :, 0]) - mid[:, None])))
    low, high = mid + offset.min(axis=1), mid + offset.max(axis=1)
    own = np.einsum("kji,kj->ki", clouds.axes[:, :2, :2], origin[:2] - clouds.origin[:, :2])
    around = np.all((own >= clouds.lo[:, :2]) & (own <= clouds.hi[:, :2]), axis=1) | (high - low >= np.pi)
    scale = AZIMUTH_BINS / (2.0 * np.pi)
    lists: list[list[int]] = [[] for _ in range(AZIMUTH_BINS)]
    for k in range(len(clouds)):
        bins = range(AZIMUTH_BINS) if around[k] else (
            b % AZIMUTH_BINS for b in range(int(np.floor(low[k] * scale)) - 1, int(np.floor(high[k] * scale)) + 2))
        for b in bins:
            lists[b].append(k)
    start, members = _packed(lists)
    d = np.asarray(rays[rows, 3:5], np.float64)
    tile = np.floor(np.arctan2(d[:, 1], d[:, 0]) * scale).astype(np.int64) % AZIMUTH_BINS
    return tile, start, members


@kernel("float64(float64, float64)")
def _erf_difference(u0, u1):
    """erf(u1) - erf(u0) for u0 <= u1, without the cancellation of two values near 1 (or -1) far out in a tail."""
    if u0 >= 0.0:
        return math.erfc(u0) - math.erfc(u1)
    if u1 <= 0.0:
        return math.erfc(-u1) - math.erfc(-u0)
    return math.erf(u1) - math.erf(u0)


@kernel("UniTuple(float64, 5)(float64, float64, float64, float64, float64, float64, float64, int64, "
        "float64[:, ::1], float64[:, :, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[::1], "
        "float64[:, ::1], float64[::1])")
def _segment(o0, o1, o2, d0, d1, d2, end, k, origin, axes, sigma, lo, hi, peak, centre, radius):
    """The part [t0, t1] of the ray o + t d (t < ``end``) within cloud k's bounds, and the cloud's extinction along
    it, amplitude exp(-a (t - tv)^2): returns (t0, t1, tv, a, amplitude); t1 <= t0 where the ray misses the cloud
    (tested first against the cloud's bounding sphere)."""
    # The ray's closest approach to the cloud's bounding sphere.
    c0, c1, c2 = centre[k, 0] - o0, centre[k, 1] - o1, centre[k, 2] - o2
    along = c0 * d0 + c1 * d1 + c2 * d2
    if c0 * c0 + c1 * c1 + c2 * c2 - along * along > radius[k] * radius[k]:
        return 0.0, -1.0, 0.0, 0.0, 0.0
    if along + radius[k] <= 0.0 or along - radius[k] >= end:
        return 0.0, -1.0, 0.0, 0.0, 0.0
    # Origin and direction in the cloud's frame (axes' columns), and the part within its bounds.
    r0, r1, r2 = o0 - origin[k, 0], o1 - origin[k, 1], o2 - origin[k, 2]
    t0, t1 = 0.0, end
    a = 0.0
    b = 0.0
    c = 0.0
    for m in range(3):
        p = r0 * axes[k, 0, m] + r1 * axes[k, 1, m] + r2 * axes[k, 2, m]
        e = d0 * axes[k, 0, m] + d1 * axes[k, 1, m] + d2 * axes[k, 2, m]
        if e != 0.0:
            ta, tb = (lo[k, m] - p) / e, (hi[k, m] - p) / e
            if ta > tb:
                ta, tb = tb, ta
            t0, t1 = max(t0, ta), min(t1, tb)
        elif p < lo[k, m] or p > hi[k, m]:
            t1 = -1.0
        w = 0.5 / (sigma[k, m] * sigma[k, m])
        a += w * e * e
        b += 2.0 * w * p * e
        c += w * p * p
    if t1 <= t0:
        return t0, t1, 0.0, 0.0, 0.0
    # q(t) = a t^2 + b t + c = a (t - tv)^2 + lowest, with a > 0 (e is a unit vector).
    tv = -b / (2.0 * a)
    lowest = max(c - a * tv * tv, 0.0)
    return t0, t1, tv, a, peak[k] * math.exp(-lowest)


@kernel("float32[::1](float32[:, ::1], float64[::1], int64[::1], int64[::1], int64[::1], int64[::1], "
        "float64[:, ::1], float64[:, :, ::1], float64[:, ::1], float64[:, ::1], float64[:, ::1], float64[::1], "
        "float64[:, ::1], float64[::1])")
def _optical_depths(rays, ends, rows, row_tile, tile_start, tile_clouds, origin, axes, sigma, lo, hi, peak, centre,
                    radius):
    """:func:`optical_depths`' loop: per ray, per cloud of its tile that it meets (:func:`_segment`), the closed
    form."""
    out = np.zeros(rays.shape[0], np.float32)
    half_sqrt_pi = 0.5 * math.sqrt(math.pi)
    for j in range(rows.size):
        i = rows[j]
        o0, o1, o2 = np.float64(rays[i, 0]), np.float64(rays[i, 1]), np.float64(rays[i, 2])
        d0, d1, d2 = np.float64(rays[i, 3]), np.float64(rays[i, 4]), np.float64(rays[i, 5])
        total = 0.0
        tile = row_tile[j]
        for entry in range(tile_start[tile], tile_start[tile + 1]):
            t0, t1, tv, a, amplitude = _segment(o0, o1, o2, d0, d1, d2, ends[i], tile_clouds[entry], origin, axes,
                                                sigma, lo, hi, peak, centre, radius)
            if t1 <= t0:
                continue
            root = math.sqrt(a)
            total += amplitude * half_sqrt_pi / root * _erf_difference(root * (t0 - tv), root * (t1 - tv))
        out[i] = np.float32(total)
    return out


def sweep_soft_returns(clouds: SprayClouds, rays: np.ndarray, ends_m: np.ndarray, extinction_per_m: float,
                       backscatter_per_extinction: float, window_m: float, overlap_m: tuple[float, float],
                       far_m: float, air_peak: float, threshold: float,
                       step_m: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The droplets' strongest return (:mod:`pipeline.sensors.backscatter`'s soft target) along each ray of a sweep
    that meets a cloud before ``far_m`` and its end, where it can reach ``threshold``: the spray's extinction plus
    the air's (``extinction_per_m``, fog and rain), back-scattering ``backscatter_per_extinction`` of it, seen through
    both (the spray's optical depth accumulated along the ray), through the overlap ``overlap_m`` = (r1, r2), with the
    pulse's window ``window_m``, on cells of ``step_m`` up to the ray's end or ``far_m``. A ray is passed over where
    the air's peak alone (``air_peak``, an upper bound of the air's share) plus the spray's share summed over the
    whole ray without the pulse's weight or the loss on the way stays below the threshold. Returns the rays (R,)
    int64 and their peak power (R,) float64 and reported range (R,) float64 (the peak's window end less half the
    window)."""
    if not len(clouds) or not len(rays):
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    boxes = clouds.boxes
    centre, radius = boxes.center, 0.5 * np.linalg.norm(boxes.size, axis=1)
    near = np.linalg.norm(centre - np.asarray(rays[0, :3], np.float64), axis=1) - radius < far_m
    if not near.any():  # only the clouds within far_m of the sweep's origin can echo enough
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    clouds, centre, radius = clouds.take(near), centre[near], radius[near]
    rows = np.arange(len(rays), dtype=np.int64)
    ends = np.minimum(ends_m, far_m)
    cells = int(max(float(ends.max()), 0.0) / step_m) + 1
    weight = cell_weights(extinction_per_m, overlap_m, step_m, cells)  # per cell, before the spray's loss
    met, power, reported = _soft_peaks(
        as_input(rays, np.float32), as_input(ends, np.float64), rows,
        *(as_input(a, np.int64) for a in sweep_tiles(clouds, rays, rows)), as_input(clouds.origin, np.float64),
        as_input(clouds.axes, np.float64), as_input(clouds.sigma, np.float64), as_input(clouds.lo, np.float64),
        as_input(clouds.hi, np.float64), as_input(clouds.peak_per_m, np.float64), as_input(centre, np.float64),
        as_input(radius, np.float64), float(extinction_per_m), float(backscatter_per_extinction), float(window_m),
        float(step_m), weight, *window_phases(window_m, step_m, cells), float(air_peak), float(threshold))
    return np.flatnonzero(met), power[met], reported[met]


@kernel("void(int64, int64, int64, float64, float64, float64, float64, float64[::1], float64[::1], float64[::1], "
        "float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], "
        "float64[::1], float64[::1])")
def _peak_of(i, m, window, step, w, ratio, alpha, beta, weight, cos_cell, sin_cell, cos_edge, sin_edge, f, s0, sc,
             ss, power, reported):
    """:func:`_soft_peaks`' power and reported range of ray ``i`` from its ``m`` cells' spray extinction ``beta``:
    the echo densities ``f`` (scratch) of the spray and the air seen through the spray's optical depth to each cell,
    then :func:`pipeline.sensors.backscatter.waveform_peak` (``s0``, ``sc``, ``ss``: its scratch)."""
    tau = 0.0
    for s in range(m):
        half = 0.5 * beta[s] * step
        f[s] = ratio * (beta[s] + alpha) * weight[s] * math.exp(-2.0 * (tau + half))
        tau += 2.0 * half
    best, end = waveform_peak(f, m, window, cos_cell, sin_cell, cos_edge, sin_edge, s0, sc, ss)
    power[i] = best
    reported[i] = end * step - 0.5 * w


@kernel("Tuple((bool_[::1], float64[::1], float64[::1]))(float32[:, ::1], float64[::1], int64[::1], int64[::1], "
        "int64[::1], int64[::1], float64[:, ::1], float64[:, :, ::1], float64[:, ::1], float64[:, ::1], "
        "float64[:, ::1], float64[::1], float64[:, ::1], float64[::1], float64, float64, float64, float64, "
        "float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64, float64)")
def _soft_peaks(rays, ends, rows, row_tile, tile_start, tile_clouds, origin, axes, sigma, lo, hi, peak, centre,
                radius, alpha, ratio, w, step, weight, cos_cell, sin_cell, cos_edge, sin_edge, air_peak, threshold):
    """:func:`sweep_soft_returns`' loop. Per ray that meets a cloud: the spray's extinction beta(t_s) on the cells
    (centres t_s) before its end; the return density f_s = ratio (beta(t_s) + alpha) weight_s exp(-2 tau(t_s))
    (weight_s = xi / t^2 step exp(-2 alpha t) at the cell's centre, tau the spray's optical depth to it); the power at
    window end R, sum over t_s in [R - w, R) of f_s sin^2(pi (R - t_s) / w), from three running sums (sin^2 x = (1 -
    cos 2x) / 2; the cells' and the ends' cosines and sines given); its maximum over R on the cells' edges."""
    n_rays = rays.shape[0]
    cells = weight.size
    met = np.zeros(n_rays, np.bool_)
    power = np.zeros(n_rays)
    reported = np.zeros(n_rays)
    beta = np.zeros(cells)
    f = np.zeros(cells)
    s0 = np.zeros(cells + 1)
    sc = np.zeros(cells + 1)
    ss = np.zeros(cells + 1)
    window = int(w / step + 0.5)
    half_sqrt_pi = 0.5 * math.sqrt(math.pi)
    t_top = (np.argmax(weight) + 0.5) * step
    for j in range(rows.size):
        i = rows[j]
        o0, o1, o2 = np.float64(rays[i, 0]), np.float64(rays[i, 1]), np.float64(rays[i, 2])
        d0, d1, d2 = np.float64(rays[i, 3]), np.float64(rays[i, 4]), np.float64(rays[i, 5])
        end = ends[i]
        m = min(int(end / step), cells)  # whole cells before the end
        if m <= 0:
            continue
        # A first bound, in closed form: each cloud's optical depth along the ray (at most its peak over one pulse's
        # window) times the weight's largest cell value over its part (the weight rises to its top at t_top and falls
        # after), 10 % over for the cells' grain.
        bound = air_peak
        tile = row_tile[j]
        for entry in range(tile_start[tile], tile_start[tile + 1]):
            t0, t1, tv, a, amplitude = _segment(o0, o1, o2, d0, d1, d2, end, tile_clouds[entry], origin, axes,
                                                sigma, lo, hi, peak, centre, radius)
            if t1 <= t0:
                continue
            root = math.sqrt(a)
            tau = min(amplitude * half_sqrt_pi / root * _erf_difference(root * (t0 - tv), root * (t1 - tv)),
                      amplitude * w)  # one pulse's window holds at most w of it
            near = min(max(t_top, t0), t1)
            c = min(int(near / step), cells - 1)
            top = max(weight[c], weight[max(c - 1, 0)], weight[min(c + 1, cells - 1)]) / step
            bound += 1.1 * ratio * tau * top
        if bound < threshold:
            continue
        first_cell, last_cell = m, -1
        for entry in range(tile_start[tile], tile_start[tile + 1]):
            t0, t1, tv, a, amplitude = _segment(o0, o1, o2, d0, d1, d2, end, tile_clouds[entry], origin, axes,
                                                sigma, lo, hi, peak, centre, radius)
            if t1 <= t0:
                continue
            for s in range(max(int(t0 / step), 0), min(int(t1 / step) + 1, m)):
                t = (s + 0.5) * step
                if t0 <= t < t1:
                    beta[s] += amplitude * math.exp(-a * (t - tv) * (t - tv))
                    first_cell, last_cell = min(first_cell, s), max(last_cell, s)
        if last_cell < 0:
            continue
        met[i] = True
        _peak_of(i, m, window, step, w, ratio, alpha, beta, weight, cos_cell, sin_cell, cos_edge, sin_edge, f, s0,
                 sc, ss, power, reported)
        for s in range(first_cell, last_cell + 1):  # the cells this ray touched, cleared for the next
            beta[s] = 0.0
    return met, power, reported
