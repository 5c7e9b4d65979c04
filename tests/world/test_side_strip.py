"""Strips laid along a body's side (door shut lines, handles, rubbing strips) in closed form on known surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass
from pipeline.world.actor_shapes import cuboid, van
from pipeline.world.loft import side_strip
from pipeline.world.materials import material_index


def test_a_strip_on_a_flat_side_lies_lifted_off_it_with_its_width():
    verts, tris, _ = cuboid((-2.0, -0.9, 0.3), (2.0, 0.9, 1.5), "paint")
    points = np.array([[0.5, 0.4], [0.5, 0.9], [0.5, 1.4]])  # a vertical line at x = 0.5
    v, t, m = side_strip(verts, tris, points, 0.02, "trim", lift_m=0.004)
    np.testing.assert_allclose(v[:, 1], 0.904)  # on the +y face, 4 mm off it
    np.testing.assert_allclose(np.sort(np.unique(np.round(v[:, 0], 9))), [0.49, 0.51])  # 2 cm wide across the line
    np.testing.assert_allclose(np.unique(v[:, 2]), [0.4, 0.9, 1.4])
    assert (m == material_index("trim")).all() and len(t) == 4
    a, b, c = (v[t[:, k]] for k in range(3))
    assert (np.cross(b - a, c - a)[:, 1] > 0).all()  # facing out of the side, towards +y


def test_a_strip_follows_a_curved_side():
    # A cylinder about the x axis (radius 1): a horizontal strip at height z lies at y = sqrt(1 - z^2) + lift.
    ang = np.linspace(-np.pi / 2, np.pi / 2, 181)
    ring = np.column_stack([np.cos(ang), np.sin(ang)])  # (y, z) of the right half, facing +y
    verts = np.concatenate([np.column_stack([np.full(len(ring), x), ring]) for x in (-1.0, 1.0)])
    n = len(ring)
    tris = np.array([t for i in range(n - 1) for t in ((i, i + 1, n + i + 1), (i, n + i + 1, n + i))])
    z = 0.6
    v, _, _ = side_strip(verts, tris, np.array([[-0.5, z], [0.0, z], [0.5, z]]), 0.1, "trim", lift_m=0.01)
    centre = 0.5 * (v[:3] + v[3:])
    np.testing.assert_allclose(np.hypot(centre[:, 1], centre[:, 2]), 1.01, atol=1e-4)  # lifted along the normal
    # The edges lie in the tangent plane (of the 1-degree facet met): sqrt((R + lift)^2 + (w / 2)^2) from the axis,
    # within what the facet normal's tilt (half a degree at most) moves them.
    np.testing.assert_allclose(np.hypot(v[:, 1], v[:, 2]), np.hypot(1.01, 0.05), atol=0.05 * np.radians(0.5))
    across = v[3:] - v[:3]  # the two edges of the strip, across it: 0.1 m along the surface's tangent
    np.testing.assert_allclose(np.linalg.norm(across, axis=1), 0.1, rtol=1e-6)
    np.testing.assert_allclose(across[:, 0], 0.0, atol=1e-12)


def test_a_strip_that_misses_the_body_is_none():
    verts, tris, _ = cuboid((-2.0, -0.9, 0.3), (2.0, 0.9, 1.5), "paint")
    assert side_strip(verts, tris, np.array([[0.0, 0.1], [0.0, 0.5]]), 0.02, "trim") is None


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_a_van_shows_its_sliding_door_rail_and_rubbing_strip_on_both_sides(side):
    mesh = van()
    trim = mesh.vertices[mesh.triangles[mesh.material == material_index("trim")].reshape(-1)]
    # Trim near the side at the rubbing strip's height (0.57-0.67 m) between the arches, on this side.
    on_side = trim[(side * trim[:, 1] > 0.8) & (np.abs(trim[:, 2] - 0.62) <= 0.051)]
    assert np.ptp(on_side[:, 0]) > 2.0
    assert mesh.semantic == ObjectClass.VAN.semantic
