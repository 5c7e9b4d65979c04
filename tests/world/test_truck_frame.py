"""Under a truck's box: a ladder frame, not a solid block (closed form along rays from behind); a curtainsider's
straps; a tractor's roof fairing."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.world.actor_shapes import box_truck, curtain_trailer, semi_trailer
from pipeline.world.loft import surface_point
from pipeline.world.materials import material_index
from tests.world.mesh_rays import MeshRays


@pytest.mark.parametrize(("family", "x_rear", "z"), [(box_truck, -4.0, 0.8), (semi_trailer, -8.0, 1.12),
                                                   (curtain_trailer, -8.0, 1.12)])
def test_from_behind_the_road_shows_between_the_frame_rails(family, x_rear, z):
    """Rays along +x under the box's rear edge, above the underrun bar, between the rails: the first thing they meet
    lies metres ahead (the cab or the tractor), not at the box's rear end."""
    mesh = family()
    for y in (-0.2, 0.0, 0.2):
        hit = surface_point(mesh.vertices, mesh.triangles, np.array([x_rear - 5.0, y, z]), np.array([1.0, 0.0, 0.0]))
        assert hit is None or hit[0][0] > x_rear + 2.0, (y, hit)


@pytest.mark.parametrize(("family", "x_rear", "z"), [(box_truck, -4.0, 0.8), (semi_trailer, -8.0, 1.1),
                                                   (curtain_trailer, -8.0, 1.1)])
def test_the_frame_rails_meet_the_underrun_bar(family, x_rear, z):
    """Just outside the centre gap, at the rails (0.28-0.43 m either side), a ray from behind meets dark trim at the
    box's rear end."""
    mesh = family()
    trim = mesh.triangles[mesh.material == material_index("trim")]
    for y in (-0.35, 0.35):
        hit = surface_point(mesh.vertices, trim, np.array([x_rear - 5.0, y, z]), np.array([1.0, 0.0, 0.0]))
        assert hit is not None and hit[0][0] == pytest.approx(x_rear, abs=1e-9)



def test_a_curtainsiders_straps_cross_its_curtain_every_055_m():
    rays = MeshRays(curtain_trailer())
    xs = np.linspace(-7.6, -7.6 + 4 * 0.55, 81)  # four strap spacings from the first strap, along the right side
    at_mid = [rays.first((x, -5.0, 2.6), (0.0, 1.0, 0.0))[0] for x in xs]
    assert set(at_mid) == {"trim", "tarpaulin"}
    starts = [x for x, a, b in zip(xs[1:], at_mid, at_mid[1:], strict=False) if a == "tarpaulin" and b == "trim"]
    assert len(starts) == 4
    np.testing.assert_allclose(np.diff(starts), 0.55, atol=2 * (xs[1] - xs[0]))
    assert rays.first((-7.6, -5.0, 1.5), (0.0, 1.0, 0.0))[0] == "metal"  # the buckle over the bottom rail


@pytest.mark.parametrize("family", [semi_trailer, curtain_trailer])
def test_a_tractors_roof_fairing_fills_the_step_up_to_the_trailer(family):
    """From ahead, at heights between the cab's roof (3.2 m) and the trailer's top (4.0 m), rays meet the painted
    fairing over the cab, not the trailer's front 1.2 m further back."""
    rays = MeshRays(family())
    for z in (3.3, 3.6, 3.9):
        name, point = rays.first((20.0, 0.0, z), (-1.0, 0.0, 0.0))
        assert name == "paint" and point[0] > 5.7, (z, name, point)
