"""Polyline offsets in closed form: every segment's offset line lies at the offset distance, mitred at turns."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.world.polygons import offset_polyline, polyline_normals


def test_right_angle_corner_is_mitred():
    line = np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 2.0], [10.0, 10.0, 3.0]])  # east, then north: a left turn
    np.testing.assert_allclose(polyline_normals(line), [[0.0, 1.0], [-1.0, 1.0], [-1.0, 0.0]], atol=1e-12)
    left = offset_polyline(line, 2.0)  # inside the turn: the corner moves diagonally by 2 * sqrt(2)
    np.testing.assert_allclose(left, [[0.0, 2.0, 1.0], [8.0, 2.0, 2.0], [8.0, 10.0, 3.0]], atol=1e-12)
    right = offset_polyline(line, -1.0)
    np.testing.assert_allclose(right, [[0.0, -1.0, 1.0], [11.0, -1.0, 2.0], [11.0, 10.0, 3.0]], atol=1e-12)


@pytest.mark.parametrize("turn_deg", [10.0, 60.0, 120.0])
def test_offset_segments_keep_their_distance(turn_deg):
    a = np.radians(turn_deg)
    line = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [5.0 + 5.0 * np.cos(a), 5.0 * np.sin(a), 0.0]])
    off = offset_polyline(line, 0.75)
    for k in range(2):  # each offset segment's end points lie 0.75 m left of the original segment's line
        d = (line[k + 1] - line[k])[:2] / np.linalg.norm((line[k + 1] - line[k])[:2])
        for p in (off[k], off[k + 1]):
            v = (p - line[k])[:2]
            assert d[0] * v[1] - d[1] * v[0] == pytest.approx(0.75)  # z of the cross product d x v


def test_sharp_turns_clamp_the_mitre():
    line = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 0.5, 0.0]])  # nearly back on itself
    assert np.linalg.norm(polyline_normals(line, max_miter=3.0)[1]) == pytest.approx(3.0)


def test_a_polyline_needs_two_points():
    with pytest.raises(ValueError, match="at least 2 points, got 1"):
        polyline_normals(np.zeros((1, 3)))
