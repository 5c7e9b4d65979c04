"""Where a ray towards the sun can meet the static world: a conservative test, drawn lazily tile by tile.

Along the sun's direction s (s_z > 0), a point p projects onto the plane z = 0 at p_xy - p_z * s_xy / s_z, and
so does every point of its ray towards the sun. The ray can meet a static triangle only where p's projection q lies
in the triangle's projection, and only if p lies no higher than the triangle does over q (the ray rises): where the
line along the sun through q pierces the triangle's plane, h(q), a linear function of q over the projection.

:class:`SunMap` keeps, per cell of a grid of SUN_CELL_M cells over the projections, a height no lower than any
triangle's over any point of the cell: the greatest over the triangles whose projection meets the cell (each
widened by SUN_EDGE_CELLS against rounding) of the least of the triangle's top and the greatest of its plane over the
(widened) cell. On flat ground the plane's bound is the ground's height, so a lit point lifted off the ground
(shading lifts shadow origins off their surface) is no candidate, though the ground beside a lane marking two
centimetres higher is. Faces that the sun grazes (a projection of almost no area: walls, kerbs) count with their
top. A shadow ray whose origin lies above its cell's height cannot meet the static world (~85% of the lit pixels
of a highway frame at noon).

The grid is cut into tiles of SUN_TILE_CELLS x SUN_TILE_CELLS cells, drawn the first time a point falls in one
(each with the triangles that meet it, listed once per sun), so a render draws only the part of the world its
cameras see.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import as_view_input, kernel
from pipeline.world.mesh import triangle_bounds

SUN_CELL_M = 0.25  # grid cell; only how many rays the test lets through depends on it
SUN_TILE_CELLS = 128  # cells per tile side (32 m)
SUN_Z_PAD_M = 1e-4  # a point this little above a cell's height still counts: far above float32 rounding
# Each triangle's projection is drawn widened by this much (in cells, 2 cm) on every side: several times the float32
# rounding of a point's projection within 20 km of the origin (an ulp there is 2 mm).
SUN_EDGE_CELLS = 0.08
# A projection whose area is below this fraction of its edges' squared lengths is a face the sun grazes: its plane
# is too steep over the projection to bound by, and it counts with its top.
_GRAZING = 1e-4


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


class SunTiles:
    """Which of the static world's triangles ((V, 3) float64 world ``vertices``, (T, 3) int64 ``triangles``) may
    draw into each tile along any of a set of sun directions (``slopes`` (S, 2), :func:`sun_slope` of each): per
    triangle, the tiles of its projections' box over the slopes' range, grown by one cell (more than the drawing's
    widening). One index serves the maps of all the directions of a sun's disc (:class:`SunMap`): a triangle listed
    for a tile it does not meet along one of them draws nothing there, so each map's tiles are those of its own
    index (a projection x - z sx is monotone in sx, and so is its rounding: the range's ends bound it). Its maps read
    the vertices and triangles it keeps (as float64 and int64, converted once)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, slopes: np.ndarray) -> None:
        self.vertices = vertices = np.asarray(vertices, np.float64)
        self.triangles = triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
        slopes = np.asarray(slopes, np.float64).reshape(-1, 2)
        self.slope_range = slopes.min(axis=0), slopes.max(axis=0)
        ends = [along_sun(*vertices.T, slope) for slope in self.slope_range]
        (ax, ay), (bx, by) = ends
        lo, _ = triangle_bounds(np.column_stack([np.fmin(ax, bx), np.fmin(ay, by)]) / SUN_CELL_M, triangles)
        _, hi = triangle_bounds(np.column_stack([np.fmax(ax, bx), np.fmax(ay, by)]) / SUN_CELL_M, triangles)
        t = SUN_TILE_CELLS
        owner, code = _tile_entries(np.floor((lo - 1.0) / t).astype(np.int64),
                                    np.floor((hi + 1.0) / t).astype(np.int64))
        order = np.argsort(code, kind="stable")  # by tile (i, j), each tile's triangles in their order
        self.entry_triangle = owner[order]
        codes = code[order]
        new = np.r_[True, codes[1:] != codes[:-1]] if len(codes) else np.zeros(0, bool)
        self.tile_codes = codes[new]  # the tiles (i, j) met, sorted, one int64 each: i * 2^32 + j
        self.tile_start = np.r_[np.flatnonzero(new), len(codes)]

    def entries(self, i: int, j: int) -> np.ndarray | None:
        """The triangles listed for tile (i, j), None where none is."""
        code = i * (1 << 32) + j
        k = int(np.searchsorted(self.tile_codes, code))
        if k >= len(self.tile_codes) or self.tile_codes[k] != code:
            return None
        return self.entry_triangle[self.tile_start[k]: self.tile_start[k + 1]]


class SunMap:
    """The static world's triangles ((V, 3) world ``vertices``, (T, 3) ``triangles``) seen along the upward unit
    direction ``sun`` (3,): :meth:`candidates` tells which shadow rays may meet them (see the module docstring).
    ``tiles``: a :class:`SunTiles` of the same triangles over directions ``sun`` is among (the sun's disc; default
    one of ``sun`` alone)."""

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, sun: np.ndarray,
                 tiles: SunTiles | None = None) -> None:
        self.slope = sun_slope(sun)
        if tiles is not None and not (np.all(tiles.slope_range[0] <= self.slope)
                                      and np.all(self.slope <= tiles.slope_range[1])):
            raise ValueError(f"sun {np.asarray(sun).tolist()} lies outside the directions its tile index was built for")
        self._index = SunTiles(vertices, triangles, self.slope) if tiles is None else tiles
        self._vertices, self._triangles = self._index.vertices, self._index.triangles
        self._slot: dict[tuple[int, int], int] = {}
        self._tiles = np.full((16, SUN_TILE_CELLS, SUN_TILE_CELLS), -np.inf, np.float32)  # drawn: slots 0 .. _drawn - 1
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
        entries = self._index.entries(i, j)
        if entries is None:
            self._slot[(i, j)] = -1
            return -1
        # The listed triangles' corners, projected (in cells): each corner its own row.
        corners = self._vertices[self._triangles[entries].reshape(-1)]
        flat = np.column_stack(along_sun(*corners.T, self.slope)) / SUN_CELL_M
        t = SUN_TILE_CELLS
        tile = _draw_tile(flat, np.ascontiguousarray(corners[:, 2]), np.arange(len(corners)).reshape(-1, 3),
                          i * t, j * t, t)
        slot = self._drawn
        if slot + 1 == len(self._tiles):  # one spare slot stays -inf (see candidates)
            self._tiles = np.concatenate([self._tiles, np.full_like(self._tiles, -np.inf)])
        self._tiles[slot] = tile
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


@kernel("float32[:, ::1](float64[:, ::1], float64[::1], int64[:, ::1], int64, int64, int64)")
def _draw_tile(flat, z, triangles, i0, j0, side):
    """(side, side) float32 heights of the cells (i0 + a, j0 + b) (cell (i, j) spans [i, i + 1) x [j, j + 1) of
    the projections ``flat`` (V, 2), in cells): per cell, the greatest over ``triangles`` (K, 3) (vertex heights
    ``z`` (V,)) whose projection, widened by SUN_EDGE_CELLS, meets the cell widened as much, of the least of the
    triangle's top and its plane's greatest height over the widened cell (see the module docstring); -inf where
    none does."""
    tile = np.full((side, side), -np.inf, np.float32)
    e = SUN_EDGE_CELLS
    px = np.empty(3)
    py = np.empty(3)
    for t in range(triangles.shape[0]):
        top = -np.inf
        for c in range(3):
            v = triangles[t, c]
            px[c], py[c] = flat[v, 0] - i0, flat[v, 1] - j0
            top = max(top, z[v])
        a, b, c0 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        e1x, e1y, e2x, e2y = px[1] - px[0], py[1] - py[0], px[2] - px[0], py[2] - py[0]
        det = e1x * e2y - e1y * e2x
        grazing = abs(det) <= _GRAZING * (e1x * e1x + e1y * e1y + e2x * e2x + e2y * e2y)
        gx = gy = 0.0
        if not grazing:  # h(q) = z_a + gx (qx - px0) + gy (qy - py0)
            dz1, dz2 = z[b] - z[a], z[c0] - z[a]
            gx = (dz1 * e2y - dz2 * e1y) / det
            gy = (e1x * dz2 - e2x * dz1) / det
        # Over a cell widened by e, the plane rises at most this far above its value at the cell's centre.
        rise = (0.5 + e) * (abs(gx) + abs(gy))
        lo_i = max(np.int64(np.floor(min(px[0], px[1], px[2]) - 2 * e)), 0)
        hi_i = min(np.int64(np.floor(max(px[0], px[1], px[2]) + 2 * e)), side - 1)
        for i in range(lo_i, hi_i + 1):
            # The y-range of the triangle within the band x in [i - 2e, i + 1 + 2e]: over its vertices inside the
            # band and its edges' crossings of the band's sides (both the cell's and the triangle's widening).
            x0, x1 = i - 2 * e, i + 1 + 2 * e
            y_lo, y_hi = np.inf, -np.inf
            for m in range(3):
                ax, ay, bx, by = px[m], py[m], px[(m + 1) % 3], py[(m + 1) % 3]
                if x0 <= ax <= x1:
                    y_lo, y_hi = min(y_lo, ay), max(y_hi, ay)
                if ax != bx:
                    for xs in (x0, x1):
                        f = (xs - ax) / (bx - ax)
                        if 0.0 <= f <= 1.0:
                            ys = ay + f * (by - ay)
                            y_lo, y_hi = min(y_lo, ys), max(y_hi, ys)
            if y_lo > y_hi:
                continue
            lo_j = max(np.int64(np.floor(y_lo - 2 * e)), 0)
            hi_j = min(np.int64(np.floor(y_hi + 2 * e)), side - 1)
            for j in range(lo_j, hi_j + 1):
                h = top
                if not grazing:
                    h = min(top, z[a] + gx * (i + 0.5 - px[0]) + gy * (j + 0.5 - py[0]) + rise)
                h32 = np.float32(h)
                if h32 < h:  # round up: the bound stays a bound
                    h32 = np.nextafter(h32, np.float32(np.inf))
                if h32 > tile[i, j]:
                    tile[i, j] = h32
    return tile


@kernel("Tuple((int64[::1], int64[::1]))(int64[:, ::1], int64[:, ::1])")
def _tile_entries(lo, hi):
    """Per triangle, the tiles (i, j) of its box ``lo`` .. ``hi`` (each (T, 2), tiles), row by row: the triangle
    (owner) and the tile's code i * 2^32 + j of every entry (ordered as (i, j) is, for |j| < 2^31)."""
    n = 0
    for k in range(lo.shape[0]):
        n += (hi[k, 0] - lo[k, 0] + 1) * (hi[k, 1] - lo[k, 1] + 1)
    owner = np.empty(n, np.int64)
    code = np.empty(n, np.int64)
    e = 0
    for k in range(lo.shape[0]):
        for i in range(lo[k, 0], hi[k, 0] + 1):
            for j in range(lo[k, 1], hi[k, 1] + 1):
                owner[e] = k
                code[e] = i * (np.int64(1) << 32) + j
                e += 1
    return owner, code
