"""A top-down occupancy raster of the world: which ground cells are paved, built on or taken.

Props (buildings, trees, lamps, barriers) are placed by querying it so they never stand on roads, and
each other. Cells are square, ``cell_m`` wide; cell (i, j) covers x in [x0 + j*cell, x0 + (j+1)*cell) and
y in [y0 + i*cell, ...). A cell is marked when its centre lies inside a rasterised triangle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.jit import kernel

_MAX_EDGE_CELLS = 8.0  # triangles are split until every edge spans at most this many cells
_SPAN = int(_MAX_EDGE_CELLS) + 2  # cells per axis that such a triangle's centres can lie in, from its lowest corner's


@dataclass
class Grid:
    """Raster frame: origin (x0, y0) in metres, cell size, shape (rows, cols)."""

    x0: float
    y0: float
    cell_m: float
    shape: tuple[int, int]

    @staticmethod
    def covering(bounds: tuple[float, float, float, float], cell_m: float = 0.5, max_cells: int = 16_000_000) -> Grid:
        """A grid over [xmin, ymin, xmax, ymax]; the cell grows when the area would exceed ``max_cells``."""
        xmin, ymin, xmax, ymax = bounds
        cell = max(cell_m, float(np.sqrt((xmax - xmin) * (ymax - ymin) / max_cells)))
        shape = (int(np.ceil((ymax - ymin) / cell)) + 1, int(np.ceil((xmax - xmin) / cell)) + 1)
        return Grid(xmin, ymin, cell, shape)

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Row and column (int64) of points (n, >=2), and a mask of those inside the grid."""
        col = np.floor((xy[:, 0] - self.x0) / self.cell_m).astype(np.int64)
        row = np.floor((xy[:, 1] - self.y0) / self.cell_m).astype(np.int64)
        ok = (row >= 0) & (row < self.shape[0]) & (col >= 0) & (col < self.shape[1])
        return row, col, ok

    def lookup(self, raster: np.ndarray, xy: np.ndarray, outside: bool = False) -> np.ndarray:
        """Raster values (n,) at points (n, >=2); ``outside`` for points off the grid."""
        row, col, ok = self.cells(xy)
        out = np.full(len(xy), outside, dtype=raster.dtype)
        out[ok] = raster[row[ok], col[ok]]
        return out

    def rasterise(self, tri_xy: np.ndarray, raster: np.ndarray | None = None) -> np.ndarray:
        """Mark cells whose centres lie in any triangle (T, 3, 2); returns the (rows, cols) bool raster (``raster``
        itself, marked in place, when given: C-contiguous bool of the grid's shape). Zero-area triangles mark
        nothing."""
        if raster is None:
            raster = np.zeros(self.shape, dtype=bool)
        elif raster.shape != self.shape or raster.dtype != bool or not raster.flags.c_contiguous:
            raise ValueError(f"raster must be C-contiguous bool of shape {self.shape}, got {raster.dtype} "
                             f"{raster.shape}")
        tri = _split_large(np.asarray(tri_xy, dtype=np.float64)[..., :2], _MAX_EDGE_CELLS * self.cell_m)
        _mark_triangles(np.ascontiguousarray(tri), float(self.x0), float(self.y0), float(self.cell_m), raster)
        return raster

    def mark_convex(self, poly_xy: np.ndarray, raster: np.ndarray) -> None:
        """Mark cells whose centres lie in one convex polygon (k, >=2), either orientation, in place."""
        poly = np.asarray(poly_xy, dtype=np.float64)[:, :2]
        (c0, r0), (c1, r1) = (np.floor((f(poly, axis=0) - (self.x0, self.y0)) / self.cell_m).astype(int)
                              for f in (np.min, np.max))
        c0, r0 = max(c0, 0), max(r0, 0)
        c1, r1 = min(c1, self.shape[1] - 1), min(r1, self.shape[0] - 1)
        if c0 > c1 or r0 > r1:
            return
        px, py = np.meshgrid(self.x0 + (np.arange(c0, c1 + 1) + 0.5) * self.cell_m,
                             self.y0 + (np.arange(r0, r1 + 1) + 0.5) * self.cell_m)
        a, b = poly, np.roll(poly, -1, axis=0)
        side = (b[:, None, None, 0] - a[:, None, None, 0]) * (py - a[:, None, None, 1]) - (
            b[:, None, None, 1] - a[:, None, None, 1]) * (px - a[:, None, None, 0])
        inside = (side >= -1e-9).all(axis=0) | (side <= 1e-9).all(axis=0)
        raster[r0 : r1 + 1, c0 : c1 + 1] |= inside

    def near(self, raster: np.ndarray, xy: np.ndarray, radius_m: float, outside: bool = False) -> np.ndarray:
        """(n,) bool: a marked cell lies within ``radius_m`` of the cell of each point (n, >=2) (Euclidean, between
        cell centres); ``outside`` for points off the grid. Cells off the grid count as unmarked.

        The same as looking the points up in ``raster`` dilated by the disk of cell offsets (i, j) with
        (i^2 + j^2) * cell^2 <= radius^2 (exactly the cells a Euclidean distance transform would mark), but it
        visits only the points' disks: the world's rasters have ~16M cells, and the props query a few thousand.
        """
        r = int(np.floor(max(radius_m, 0.0) / self.cell_m + 1e-9))
        i, j = np.mgrid[-r:r + 1, -r:r + 1].reshape(2, -1)
        disk = (i**2 + j**2) * self.cell_m**2 <= radius_m**2 + 1e-9
        i, j = i[disk], j[disk]
        row, col, ok = self.cells(xy)
        out = np.full(len(xy), outside, dtype=bool)
        rows, cols = row[ok, None] + i, col[ok, None] + j  # (m, offsets)
        inside = (rows >= 0) & (rows < self.shape[0]) & (cols >= 0) & (cols < self.shape[1])
        out[ok] = (raster[np.where(inside, rows, 0), np.where(inside, cols, 0)] & inside).any(axis=1)
        return out


@kernel("void(float64[:, :, ::1], float64, float64, float64, bool_[:, ::1])")
def _mark_triangles(tri, x0, y0, cell_m, raster):
    """Mark, in the (rows, cols) bool ``raster`` of cells ``cell_m`` wide from (x0, y0), the cells whose centre lies
    in one of the (T, 3, 2) float64 triangles (or within 1e-9 of its edge functions), each spanning at most
    _MAX_EDGE_CELLS cells per axis (:func:`_split_large`): only the span x span cells from its lowest corner's are
    tested. Zero-area and non-finite triangles mark nothing."""
    rows, cols = raster.shape
    span = _SPAN
    for k in range(tri.shape[0]):
        ax, ay, bx, by, cx, cy = tri[k, 0, 0], tri[k, 0, 1], tri[k, 1, 0], tri[k, 1, 1], tri[k, 2, 0], tri[k, 2, 1]
        area2 = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        if area2 == 0 or not np.isfinite(area2):
            continue
        orient = 1.0 if area2 > 0 else -1.0
        c0 = np.int64(np.floor((min(ax, bx, cx) - x0) / cell_m))
        r0 = np.int64(np.floor((min(ay, by, cy) - y0) / cell_m))
        for i in range(span):
            r = r0 + i
            if r < 0 or r >= rows:
                continue
            py = y0 + (r + 0.5) * cell_m
            for j in range(span):
                c = c0 + j
                if c < 0 or c >= cols:
                    continue
                px = x0 + (c + 0.5) * cell_m
                if (orient * ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) >= -1e-9
                        and orient * ((cx - bx) * (py - by) - (cy - by) * (px - bx)) >= -1e-9
                        and orient * ((ax - cx) * (py - cy) - (ay - cy) * (px - cx)) >= -1e-9):
                    raster[r, c] = True


def _split_large(tri: np.ndarray, max_edge_m: float) -> np.ndarray:
    """Bisect triangles (T, 3, 2) across their longest edge until every edge is <= ``max_edge_m``.

    Longest-edge bisection keeps long thin triangles (lane strips) to about length/max_edge pieces.
    """
    done = []
    while len(tri):
        edges = np.linalg.norm(tri - np.roll(tri, -1, axis=1), axis=2)  # edge k runs from vertex k to k+1
        big = edges.max(axis=1) > max_edge_m
        done.append(tri[~big])
        t, k = tri[big], edges[big].argmax(axis=1)
        order = (k[:, None] + np.arange(3)[None, :]) % 3
        t = np.take_along_axis(t, order[:, :, None], axis=1)  # longest edge is now (0, 1)
        mid = (t[:, 0] + t[:, 1]) / 2
        tri = np.concatenate([np.stack([t[:, 0], mid, t[:, 2]], 1), np.stack([mid, t[:, 1], t[:, 2]], 1)])
    return np.concatenate(done) if done else tri
