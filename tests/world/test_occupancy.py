"""Grid dilation equals the Euclidean distance transform it replaces (exact on cell centres)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from pipeline.world.occupancy import Grid


@pytest.mark.parametrize(("cell_m", "radius_m"), [(0.5, 0.35), (0.5, 0.7), (0.5, 2.0), (0.25, 4.0), (0.4, 1.0)])
def test_dilate_matches_the_distance_transform(cell_m, radius_m):
    rng = np.random.default_rng(3)
    raster = rng.random((120, 90)) < 0.01
    raster[0, 5] = raster[-1, -1] = True  # marks on the border
    grid = Grid(0.0, 0.0, cell_m, raster.shape)
    expected = ndimage.distance_transform_edt(~raster) * cell_m <= radius_m
    np.testing.assert_array_equal(grid.dilate(raster, radius_m), expected)
