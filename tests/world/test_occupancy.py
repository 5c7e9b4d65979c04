"""Grid queries: the disk test equals the Euclidean distance transform it replaces (exact on cell centres), and
rasterisation marks exactly the cell centres inside the triangles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from pipeline.world.occupancy import Grid


@pytest.mark.parametrize(("cell_m", "radius_m"), [(0.5, 0.35), (0.5, 0.7), (0.5, 2.0), (0.25, 4.0), (0.4, 1.0)])
def test_near_matches_the_distance_transform(cell_m, radius_m):
    """At a point anywhere in every cell of the grid, against the distance from the cell's centre to the nearest
    marked centre (scipy's exact transform); off the grid, the ``outside`` value."""
    rng = np.random.default_rng(3)
    raster = rng.random((120, 90)) < 0.01
    raster[0, 5] = raster[-1, -1] = True  # marks on the border
    grid = Grid(-2.0, 1.0, cell_m, raster.shape)
    expected = ndimage.distance_transform_edt(~raster) * cell_m <= radius_m
    rows, cols = np.mgrid[0:120, 0:90].reshape(2, -1)
    xy = np.column_stack([grid.x0 + (cols + rng.uniform(0.01, 0.99, len(cols))) * cell_m,
                          grid.y0 + (rows + rng.uniform(0.01, 0.99, len(rows))) * cell_m])
    near = grid.near(raster, xy, radius_m)
    assert 0 < near.sum() < len(near)
    np.testing.assert_array_equal(near, expected.reshape(-1))
    off = np.array([[grid.x0 - 0.1, 3.0], [0.0, grid.y0 - 0.1], [grid.x0 + 90 * cell_m + 0.01, 3.0],
                    [0.0, grid.y0 + 120 * cell_m + 0.01]])
    assert not grid.near(raster, off, radius_m).any()
    assert grid.near(raster, off, radius_m, outside=True).all()


def _centres_in_triangle(grid: Grid, tri: np.ndarray) -> np.ndarray:
    """(rows, cols) bool: cells whose centre lies in the triangle (3, 2) or on its border (every cell's centre
    against the three edges)."""
    rows, cols = grid.shape
    px, py = np.meshgrid(grid.x0 + (np.arange(cols) + 0.5) * grid.cell_m,
                         grid.y0 + (np.arange(rows) + 0.5) * grid.cell_m)
    side = [(b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]) for a, b in ((tri[0], tri[1]), (tri[1], tri[2]),
                                                                                     (tri[2], tri[0]))]
    return ((side[0] >= 0) & (side[1] >= 0) & (side[2] >= 0)) | ((side[0] <= 0) & (side[1] <= 0) & (side[2] <= 0))


def test_rasterise_marks_exactly_the_cell_centres_inside():
    """Against a cell-by-cell test of every triangle over the whole grid: small and large triangles (split inside
    rasterise), either orientation, slivers, and triangles partly or wholly off the grid."""
    rng = np.random.default_rng(11)
    grid = Grid(-3.0, 2.0, 0.5, (70, 90))  # x in [-3, 42), y in [2, 37)
    centre = rng.uniform([-10.0, -5.0], [50.0, 45.0], (300, 1, 2))
    size = rng.choice([0.3, 2.0, 8.0, 30.0], (300, 1, 1))
    tris = centre + size * rng.uniform(-1.0, 1.0, (300, 3, 2))
    tris[:20, 2] = tris[:20, 0] + 1e-3 * (tris[:20, 1] - tris[:20, 0])  # slivers
    expected = np.zeros(grid.shape, bool)
    for tri in tris:
        expected |= _centres_in_triangle(grid, tri)
    assert expected.sum() > 1000 and not expected.all()
    np.testing.assert_array_equal(grid.rasterise(tris), expected)
    one = np.zeros(grid.shape, bool)
    grid.rasterise(tris[50:51], one)  # into a given raster, one triangle
    np.testing.assert_array_equal(one, _centres_in_triangle(grid, tris[50]))
    flat = np.array([[[1.0, 3.0], [9.0, 3.0], [5.0, 3.0]], [[2.0, 4.0], [2.0, 4.0], [2.0, 4.0]]])
    assert not grid.rasterise(flat).any()  # zero-area triangles (a segment, a point) mark nothing
    with pytest.raises(ValueError, match="C-contiguous bool"):
        grid.rasterise(tris[:1], np.zeros(grid.shape, np.uint8))
