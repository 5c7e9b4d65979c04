"""A top-down occupancy raster of the world: which ground cells are paved, built on or taken.

Props (buildings, trees, lamps, barriers) are placed by querying it so they never stand on roads, and
each other. Cells are square, ``cell_m`` wide; cell (i, j) covers x in [x0 + j*cell, x0 + (j+1)*cell) and
y in [y0 + i*cell, ...). A cell is marked when its centre lies inside a rasterised triangle.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

_MAX_EDGE_CELLS = 8.0  # triangles are split until every edge spans at most this many cells


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
        """Mark cells whose centres lie in any triangle (T, 3, 2); returns the (rows, cols) bool raster."""
        raster = np.zeros(self.shape, dtype=bool) if raster is None else raster
        tri = _split_large(np.asarray(tri_xy, dtype=np.float64)[..., :2], _MAX_EDGE_CELLS * self.cell_m)
        if not len(tri):
            return raster
        span = int(_MAX_EDGE_CELLS) + 2
        off = np.arange(span)
        lo = np.floor((tri.min(axis=1) - (self.x0, self.y0)) / self.cell_m).astype(np.int64)
        for chunk in range(0, len(tri), 20_000):
            t, base = tri[chunk : chunk + 20_000], lo[chunk : chunk + 20_000]
            # Candidate cells: a span x span window from each triangle's lowest corner. A cell centre's x depends
            # only on its column and y only on its row, so each edge function is a (T, span) term of the rows
            # minus a (T, span) term of the columns, broadcast: the same float operations per cell as evaluating
            # it cell by cell, at a fraction of the passes over (T, span, span) arrays.
            cols, rows = base[:, 0, None] + off, base[:, 1, None] + off  # (T, span) each
            px = self.x0 + (cols + 0.5) * self.cell_m
            py = self.y0 + (rows + 0.5) * self.cell_m
            orient = np.sign(_edge(t[:, 0], t[:, 1], t[:, 2]))[:, None, None]
            inside = np.ones((len(t), span, span), dtype=bool)  # [triangle, row, column]
            for a, b in ((0, 1), (1, 2), (2, 0)):
                dx, dy = (t[:, b, 0] - t[:, a, 0])[:, None], (t[:, b, 1] - t[:, a, 1])[:, None]
                edge = (dx * (py - t[:, a, 1, None]))[:, :, None] - (dy * (px - t[:, a, 0, None]))[:, None, :]
                inside &= orient * edge >= -1e-9
            inside &= ((rows >= 0) & (rows < self.shape[0]))[:, :, None]
            inside &= ((cols >= 0) & (cols < self.shape[1]))[:, None, :]
            k, i, j = np.nonzero(inside)
            raster[rows[k, i], cols[k, j]] = True
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

    def dilate(self, raster: np.ndarray, radius_m: float) -> np.ndarray:
        """Cells within ``radius_m`` of a marked cell (Euclidean, exact on the cell centres).

        A dilation by the disk of cell offsets (i, j) with (i^2 + j^2) * cell^2 <= radius^2 marks exactly
        the cells a Euclidean distance transform would, at a fraction of its cost on large rasters.
        """
        if radius_m <= 0:
            return raster.copy()
        r = int(np.floor(radius_m / self.cell_m + 1e-9))
        offsets = np.arange(-r, r + 1)
        disk = ((offsets[:, None] ** 2 + offsets[None, :] ** 2) * self.cell_m**2 <= radius_m**2 + 1e-9)
        return cv2.dilate(raster.astype(np.uint8), disk.astype(np.uint8), borderValue=0).astype(bool)


def _edge(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


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
