"""Lamps, grille and intake laid onto a body's end faces, and the body's plan shape, in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass
from pipeline.world.actor_shapes import FAMILIES, cuboid
from pipeline.world.loft import BodySpec, decal, plan_half_width, surface_point
from pipeline.world.materials import material_index
from tests.world.mesh_rays import MeshRays


def _cylinder_z(radius: float = 1.0, n: int = 361) -> tuple[np.ndarray, np.ndarray]:
    """The front half (+x) of an upright cylinder about the z axis from z = 0 to 1: x = sqrt(R^2 - y^2)."""
    ang = np.linspace(-np.pi / 2, np.pi / 2, n)
    ring = radius * np.column_stack([np.cos(ang), np.sin(ang)])  # (x, y)
    verts = np.concatenate([np.column_stack([ring, np.full(n, z)]) for z in (0.0, 1.0)])
    tris = np.array([t for i in range(n - 1) for t in ((i, i + 1, n + i + 1), (i, n + i + 1, n + i))])
    return verts, tris


def test_a_conforming_decal_on_a_flat_face_is_the_flat_decal_gridded():
    verts, tris, _ = cuboid((-2.0, -0.9, 0.3), (2.0, 0.9, 1.5), "paint")
    v, t, m = decal(verts, tris, 0.3, 0.8, 0.4, 0.2, "headlight", "front", lift_m=0.006, conform=(5, 3))
    np.testing.assert_allclose(v[:, 0], 2.006)  # on the front face, 6 mm off it
    np.testing.assert_allclose(np.unique(np.round(v[:, 1], 12)), [0.1, 0.2, 0.3, 0.4, 0.5])
    np.testing.assert_allclose(np.unique(np.round(v[:, 2], 12)), [0.7, 0.8, 0.9])
    assert len(t) == 2 * 4 * 2 and (m == material_index("headlight")).all()
    a, b, c = (v[t[:, k]] for k in range(3))
    assert (np.cross(b - a, c - a)[:, 0] > 0).all()  # facing out of the front, towards +x
    flat, _, _ = decal(verts, tris, 0.3, 0.8, 0.4, 0.2, "headlight", "front", lift_m=0.006)
    np.testing.assert_allclose(v.min(axis=0), flat.min(axis=0), atol=1e-12)
    np.testing.assert_allclose(v.max(axis=0), flat.max(axis=0), atol=1e-12)


def test_a_rear_decal_faces_backwards():
    verts, tris, _ = cuboid((-2.0, -0.9, 0.3), (2.0, 0.9, 1.5), "paint")
    v, t, _ = decal(verts, tris, -0.3, 0.8, 0.4, 0.2, "taillight", "rear", lift_m=0.006, conform=(4, 2))
    np.testing.assert_allclose(v[:, 0], -2.006)
    a, b, c = (v[t[:, k]] for k in range(3))
    assert (np.cross(b - a, c - a)[:, 0] < 0).all()


def test_a_conforming_decal_wraps_round_a_curved_corner():
    # On the cylinder x = sqrt(1 - y^2), each grid point lies at radius 1 + lift (lifted along the normal, which is
    # radial) at the angle its ray along -x meets: y = sin(a) before the lift.
    verts, tris = _cylinder_z()
    v, _, _ = decal(verts, tris, 0.5, 0.5, 0.8, 0.2, "headlight", "front", lift_m=0.01, conform=(9, 2))
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 1]), 1.01, atol=2e-4)  # facets of half a degree
    y = np.linspace(0.1, 0.9, 9)
    np.testing.assert_allclose(v[:9, 1], y * 1.01, atol=2e-3)
    # The outer end turns into the side: the quad's depth along x is what the circle gives, sqrt(1 - y^2).
    np.testing.assert_allclose(np.ptp(v[:9, 0]), 1.01 * (np.sqrt(1 - 0.1**2) - np.sqrt(1 - 0.9**2)), atol=2e-3)


def test_a_conforming_decal_past_the_face_is_none():
    verts, tris, _ = cuboid((-2.0, -0.9, 0.3), (2.0, 0.9, 1.5), "paint")
    assert decal(verts, tris, 0.8, 0.8, 0.4, 0.2, "headlight", "front", conform=(4, 2)) is None


def test_the_plan_is_straight_over_the_middle_and_narrows_to_the_ends():
    spec = BodySpec(4.0, 2.0, top=((0.0, 1.0), (1.0, 1.0)), sill_z_m=0.3, belt=((0.0, 0.8), (1.0, 0.8)),
                    plan_taper=0.2, plan_start=0.5, plan_power=2.0)
    u = np.array([0.25, 0.5, 0.75, 0.875, 1.0, 0.0, 0.125])
    # s = (|2u - 1| - 0.5) / 0.5: 0 in the middle half, 0.5 at u = 0.125 / 0.875, 1 at the ends.
    np.testing.assert_allclose(plan_half_width(u, spec), [1.0, 1.0, 1.0, 1.0 - 0.2 * 0.25, 0.8, 0.8, 0.95])


@pytest.mark.parametrize("family", FAMILIES[ObjectClass.CAR] + FAMILIES[ObjectClass.VAN], ids=lambda f: f.__name__)
def test_every_car_and_van_has_two_headlamps_a_grille_and_an_intake_in_front(family):
    mesh = family()
    x_front = mesh.vertices[:, 0].max()
    for name in ("headlight", "trim"):
        v = mesh.vertices[mesh.triangles[mesh.material == material_index(name)].reshape(-1)]
        front = v[v[:, 0] > x_front - 0.4]
        assert (front[:, 1] > 0.2).any() and (front[:, 1] < -0.2).any(), name  # on both sides of the centre
    lamps = mesh.vertices[mesh.triangles[mesh.material == material_index("headlight")].reshape(-1)]
    lamps = lamps[lamps[:, 0] > 0]
    assert np.ptp(lamps[:, 0]) > 0.05  # the clusters wrap back into the wings, not a flat card on the face


@pytest.mark.parametrize("family", FAMILIES[ObjectClass.CAR] + FAMILIES[ObjectClass.VAN], ids=lambda f: f.__name__)
def test_the_front_plate_is_seen_in_front_of_the_intake(family):
    """Rays along -x across the plate meet the plate before the intake (and the body) behind it."""
    mesh = family()
    plate = mesh.triangles[mesh.material == material_index("plate")]
    rest = mesh.triangles[mesh.material != material_index("plate")]
    pv = mesh.vertices[plate.reshape(-1)]
    for y in np.linspace(pv[:, 1].min(), pv[:, 1].max(), 7)[1:-1]:
        for z in np.linspace(pv[:, 2].min(), pv[:, 2].max(), 5)[1:-1]:
            origin, down = np.array([10.0, y, z]), np.array([-1.0, 0.0, 0.0])
            on_plate, behind = surface_point(mesh.vertices, plate, origin, down), surface_point(mesh.vertices, rest,
                                                                                               origin, down)
            assert on_plate is not None and behind is not None
            assert on_plate[0][0] > behind[0][0] + 0.003, (y, z)


def test_a_bus_shows_windows_lamps_louvres_and_displays_at_its_ends():
    from pipeline.world.actor_shapes import bus

    rays = MeshRays(bus())

    def seen(end: str, y: float, z: float) -> str:
        sign = 1.0 if end == "front" else -1.0
        return rays.first((sign * 20.0, y, z), (-sign, 0.0, 0.0))[0]

    half_w = 0.5 * 2.55
    # The windscreen and the rear window on the centre line, the route displays above them, LED lettering on the front
    # display standing out of it (not coplanar), the plates.
    assert [seen("front", 0.0, z) for z in (1.3, 2.0, 2.5)] == ["glass"] * 3
    assert [seen("rear", 0.0, z) for z in (2.1, 2.6)] == ["glass"] * 2
    assert seen("front", -0.45, 2.8) == "marker_lamp" and seen("front", -0.12, 2.8) == "trim"
    assert seen("rear", 0.0, 2.9) == "trim"
    assert seen("front", 0.0, 0.5) == "plate" and seen("rear", 0.0, 0.6) == "plate_rear"
    # The engine louvres: five dark slats on the painted rear, 0.15 m apart; tall tail lamps at both rear corners.
    zs = np.linspace(0.8, 1.5, 141)
    slats = np.array([seen("rear", 0.3, z) == "trim" for z in zs])
    assert np.count_nonzero(np.diff(slats.astype(int)) == 1) == 5 and not slats.all()
    for y in (-0.86 * half_w, 0.86 * half_w):
        assert [seen("rear", y, z) for z in (0.8, 1.05, 1.3)] == ["taillight"] * 3
