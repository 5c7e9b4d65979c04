"""Under a truck's box: a ladder frame, not a solid block (closed form along rays from behind)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.world.actor_shapes import box_truck, semi_trailer
from pipeline.world.loft import surface_point
from pipeline.world.materials import material_index


@pytest.mark.parametrize(("family", "x_rear", "z"), [(box_truck, -4.0, 0.8), (semi_trailer, -8.0, 1.12)])
def test_from_behind_the_road_shows_between_the_frame_rails(family, x_rear, z):
    """Rays along +x under the box's rear edge, above the underrun bar, between the rails: the first thing they meet
    lies metres ahead (the cab or the tractor), not at the box's rear end."""
    mesh = family()
    for y in (-0.2, 0.0, 0.2):
        hit = surface_point(mesh.vertices, mesh.triangles, np.array([x_rear - 5.0, y, z]), np.array([1.0, 0.0, 0.0]))
        assert hit is None or hit[0][0] > x_rear + 2.0, (y, hit)


@pytest.mark.parametrize(("family", "x_rear", "z"), [(box_truck, -4.0, 0.8), (semi_trailer, -8.0, 1.1)])
def test_the_frame_rails_meet_the_underrun_bar(family, x_rear, z):
    """Just outside the centre gap, at the rails (0.28-0.43 m either side), a ray from behind meets dark trim at the
    box's rear end."""
    mesh = family()
    trim = mesh.triangles[mesh.material == material_index("trim")]
    for y in (-0.35, 0.35):
        hit = surface_point(mesh.vertices, trim, np.array([x_rear - 5.0, y, z]), np.array([1.0, 0.0, 0.0]))
        assert hit is not None and hit[0][0] == pytest.approx(x_rear, abs=1e-9)
