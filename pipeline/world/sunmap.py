"""Where a ray towards the sun can meet the static world: a conservative test, drawn lazily tile by tile.

Along the sun's direction s (s_z > 0), a point p projects onto the plane z = 0 at p_xy - p_z * s_xy / s_z, and
so does every point of its ray towards the sun. The ray can meet a static triangle only where p's projection lies
in the triangle's projection, and only if p lies no higher than the triangle's highest vertex (the ray rises).

:class:`SunMap` draws the projections of the static triangles on a grid of SUN_CELL_M cells, highest last, each
cell keeping the height of the highest triangle drawn over it. A cell that a triangle's projection meets either
has its centre inside the triangle (filled) or has the triangle's outline pass through it (drawn, Bresenham):
both are drawn, and the result is grown by one cell (a 3x3 maximum), so every cell a projection meets keeps at
least that triangle's height. A shadow ray whose origin lies above its cell's height cannot meet the static
world (~75% of the lit pixels of a highway frame at noon, ~45% of an urban one; fewer under a low sun).

The grid is cut into tiles of SUN_TILE_CELLS x SUN_TILE_CELLS cells, drawn the first time a point falls in one
(each with the triangles that meet it, listed once per sun), so a render draws only the part of the world its
cameras see.
"""

from __future__ import annotations

import cv2
import numpy as np

from pipeline.core.jit import as_view_input, kernel
from pipeline.world.mesh import triangle_bounds

SUN_CELL_M = 0.25  # grid cell; only how many rays the test lets through depends on it
SUN_TILE_CELLS = 128  # cells per tile side (32 m)
SUN_Z_PAD_M = 1e-4  # a point this little above a triangle's top still counts: far above float32 rounding
_FIXED_BITS = 4  # OpenCV's sub-pixel bits for polygon vertices


def sun_slope(sun: np.ndarray) -> np.ndarray:
    """(2,) float64 sun_xy / sun_z of an upward direction ``sun`` (3,): along the sun, a point p projects onto the
    plane z = 0 at p_xy - p_z * slope (:func:`along_sun`)."""
    sun = np.asarray(sun, np.float64)
    if not sun[2] > 0:
        raise ValueError(f"sun must point upwards (z > 0), got {sun.tolist()}")
    return sun[:2] / sun[2]


def along_sun(x: np.ndarray, y: np.ndarray, z: np.ndarray, slope: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The projections (px, py) of the points (x, y, z) (each (M,)) along the sun onto z = 0, in their dtype."""
    sx, sy = np.asarray(slope, x.dtype)
    return x - z * sx, y - z * sy


class SunMap:
    """The static world's triangles ((V, 3) world ``vertices``, (T, 3) ``triangles``) seen along the upward unit
    direction ``sun`` (3,): :meth:`candidates` tells which shadow rays may meet them (see the module docstring)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, sun: np.ndarray) -> None:
        self.slope = sun_slope(sun)
        vertices = np.asarray(vertices, np.float64)
        triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
        # Projections, in cells.
        self._flat = np.column_stack(along_sun(*vertices.T, self.slope)) / SUN_CELL_M
        flat_lo, flat_hi = triangle_bounds(self._flat, triangles)
        self._triangles = triangles
        self._top = triangle_bounds(vertices[:, 2:], triangles)[1][:, 0]
        # Tiles each triangle meets (its cells' box grown by one cell, as the drawing is), listed per tile with the
        # lowest triangle first.
        t = SUN_TILE_CELLS
        lo = np.floor((flat_lo - 1.0) / t).astype(np.int64)
        hi = np.floor((flat_hi + 1.0) / t).astype(np.int64)
        span = hi - lo + 1
        count = span[:, 0] * span[:, 1]
        owner = np.repeat(np.arange(len(triangles)), count)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)  # position within each triangle's box
        tile_i = lo[owner, 0] + k // span[owner, 1]
        tile_j = lo[owner, 1] + k % span[owner, 1]
        order = np.lexsort((self._top[owner], tile_j, tile_i))
        self._entry_triangle = owner[order]
        keys = np.column_stack([tile_i[order], tile_j[order]])
        new = np.r_[True, np.any(keys[1:] != keys[:-1], axis=1)] if len(keys) else np.zeros(0, bool)
        self._tile_codes = keys[new, 0] * (1 << 32) + keys[new, 1]  # the tiles (i, j) met, sorted, one int64 each
        self._tile_start = np.r_[np.flatnonzero(new), len(keys)]
        self._slot: dict[tuple[int, int], int] = {}
        self._tiles = np.full((16, t, t), -np.inf, np.float32)  # tiles drawn so far in slots 0 .. _drawn - 1
        self._drawn = 0

    def candidates(self, x: np.ndarray, y: np.ndarray, z: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """(M,) bool: which rays towards the sun from the points (x, y, z) may meet a static triangle; the others
        cannot. ``x``, ``y``, ``z`` (each (N,) float32, world metres; strided views are read in place); ``rows``
        (M,) int64, optional: test only these points (default all, M = N)."""
        x, y, z = (as_view_input(c, np.float32) for c in (x, y, z))
        rows = np.arange(len(x), dtype=np.int64) if rows is None else np.ascontiguousarray(rows, np.int64)
        if not len(rows):
            return np.zeros(0, bool)
        sx, sy = np.asarray(self.slope, np.float32)
        cx, cy, bounds = _cells(x, y, z, rows, sx, sy, np.float32(1.0 / SUN_CELL_M))
        shift = SUN_TILE_CELLS.bit_length() - 1
        # The tiles the cells lie in: (i0 .. i1) x (j0 .. j1), numbered row-major; draw those met, once each.
        i0, i1, j0, j1 = (int(b) >> shift for b in bounds)
        cols = j1 - j0 + 1
        needed = _tiles_met(cx, cy, shift, i0, j0, cols, (i1 - i0 + 1) * cols)
        slots = np.full(len(needed), -1, np.int32)
        for k in np.flatnonzero(needed).tolist():
            slots[k] = self._tile(i0 + k // cols, j0 + k % cols)
        drawn = self._tiles[: self._drawn + 1].reshape(-1)  # the last slot holds -inf: a tile no triangle meets
        return _below_tops(cx, cy, z, rows, slots, shift, i0, j0, cols, drawn, self._drawn,
                           np.float32(SUN_Z_PAD_M))

    def _tile(self, i: int, j: int) -> int:
        """The slot of tile (i, j) in ``_tiles``, drawn now if it is not yet; -1 where no triangle meets it."""
        if (i, j) in self._slot:
            return self._slot[(i, j)]
        k = int(np.searchsorted(self._tile_codes, i * (1 << 32) + j))
        if k >= len(self._tile_codes) or self._tile_codes[k] != i * (1 << 32) + j:
            self._slot[(i, j)] = -1
            return -1
        t = SUN_TILE_CELLS
        # Image rows follow the first cell index, columns the second; one cell of apron on each side for the 3x3
        # maximum. A pixel's centre sits at its integer coordinates: cell c spans [c - 0.5, c + 0.5).
        image = np.full((t + 2, t + 2), -np.inf, np.float32)
        origin = np.array([i * t - 1, j * t - 1], np.float64)
        entries = self._entry_triangle[self._tile_start[k]: self._tile_start[k + 1]]
        corners = (self._flat[self._triangles[entries]] - origin - 0.5)[:, :, ::-1]  # (x, y) = (column, row)
        fixed = np.round(corners * (1 << _FIXED_BITS)).astype(np.int32)
        for points, top in zip(fixed, self._top[entries].astype(np.float32).tolist(), strict=True):
            cv2.fillConvexPoly(image, points, top, cv2.LINE_8, _FIXED_BITS)
            cv2.polylines(image, [points], True, top, 1, cv2.LINE_8, _FIXED_BITS)
        grown = cv2.dilate(image, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
        slot = self._drawn
        if slot + 1 == len(self._tiles):  # one spare slot stays -inf (see candidates)
            self._tiles = np.concatenate([self._tiles, np.full_like(self._tiles, -np.inf)])
        self._tiles[slot] = grown[1:-1, 1:-1]
        self._drawn += 1
        self._slot[(i, j)] = slot
        return slot


@kernel("Tuple((int32[::1], int32[::1], int64[::1]))(float32[:], float32[:], float32[:], int64[::1], float32, float32, "
        "float32)")
def _cells(x, y, z, rows, sx, sy, scale):
    """The cells (cx, cy) (each (M,) int32) of the points ``rows`` projected along the sun (slope (sx, sy); cells
    ``1 / scale`` wide), and their bounds [min cx, max cx, min cy, max cy] (int64)."""
    n = rows.size
    cx = np.empty(n, np.int32)
    cy = np.empty(n, np.int32)
    lo_x = lo_y = np.iinfo(np.int32).max
    hi_x = hi_y = np.iinfo(np.int32).min
    for k in range(n):
        i = rows[k]
        a = np.int32(np.floor((x[i] - z[i] * sx) * scale))
        b = np.int32(np.floor((y[i] - z[i] * sy) * scale))
        cx[k] = a
        cy[k] = b
        lo_x, hi_x = min(lo_x, a), max(hi_x, a)
        lo_y, hi_y = min(lo_y, b), max(hi_y, b)
    return cx, cy, np.array([lo_x, hi_x, lo_y, hi_y], np.int64)


@kernel("int64(int32, int32, int64, int64, int64, int64)")
def _tile_number(cx, cy, shift, i0, j0, cols):
    """The tile of cell (cx, cy) (cells >> shift), numbered row-major from tile (i0, j0), ``cols`` per row."""
    return ((cx >> shift) - i0) * cols + ((cy >> shift) - j0)


@kernel("bool_[::1](int32[::1], int32[::1], int64, int64, int64, int64, int64)")
def _tiles_met(cx, cy, shift, i0, j0, cols, count):
    """(count,) bool: the tiles (numbered by :func:`_tile_number`) that the cells (cx, cy) lie in."""
    met = np.zeros(count, np.bool_)
    for k in range(cx.size):
        met[_tile_number(cx[k], cy[k], shift, i0, j0, cols)] = True
    return met


@kernel("bool_[::1](int32[::1], int32[::1], float32[:], int64[::1], int32[::1], int64, int64, int64, int64, "
        "float32[::1], int64, float32)")
def _below_tops(cx, cy, z, rows, slots, shift, i0, j0, cols, tiles, empty, pad):
    """(M,) bool: the point ``rows[k]`` (height z) lies no higher than ``pad`` above its cell's height, read from
    the drawn tiles (``tiles``: slots of (2^shift)^2 cells, flat; a tile's slot from ``slots`` as numbered by
    :func:`_tile_number`; ``empty``: the slot of a tile no triangle meets)."""
    side = np.int64(1) << shift
    out = np.empty(cx.size, np.bool_)
    for k in range(cx.size):
        slot = np.int64(slots[_tile_number(cx[k], cy[k], shift, i0, j0, cols)])
        if slot < 0:
            slot = empty
        cell = ((cx[k] & (side - 1)) << shift) | (cy[k] & (side - 1))
        out[k] = z[rows[k]] <= tiles[slot * side * side + cell] + pad
    return out
