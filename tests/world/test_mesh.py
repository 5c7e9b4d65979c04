import numpy as np

from pipeline.world.mesh import triangle_bounds


def test_triangle_bounds_are_each_triangles_corner_extremes():
    points = np.array([[0.0, 5.0, -1.0], [2.0, -3.0, 4.0], [1.0, 1.0, 1.0], [-7.0, 0.5, 9.0]])
    triangles = np.array([[0, 1, 2], [3, 2, 0], [1, 1, 1]], np.int32)
    lo, hi = triangle_bounds(points, triangles)
    np.testing.assert_array_equal(lo, [[0.0, -3.0, -1.0], [-7.0, 0.5, -1.0], [2.0, -3.0, 4.0]])
    np.testing.assert_array_equal(hi, [[2.0, 5.0, 4.0], [1.0, 5.0, 9.0], [2.0, -3.0, 4.0]])
    rng = np.random.default_rng(0)  # any number of coordinates, against numpy's gather and reduction
    points, triangles = rng.normal(size=(50, 2)), rng.integers(0, 50, (200, 3))
    lo, hi = triangle_bounds(points, triangles)
    np.testing.assert_array_equal(lo, points[triangles].min(axis=1))
    np.testing.assert_array_equal(hi, points[triangles].max(axis=1))
    assert triangle_bounds(points, np.zeros((0, 3), np.int64))[0].shape == (0, 2)
