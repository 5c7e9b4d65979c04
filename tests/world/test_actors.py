"""Procedural actor meshes: they fill their boxes exactly, are placed by an affine map, and validate input."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actor_shapes import FAMILIES, SUITS_LENGTH_M
from pipeline.world.actors import (
    ActorMeshes,
    Actors,
    Model,
    actor_variants,
    canonical_mesh,
    code_groups,
    family_extent,
    family_mesh,
    normalise_to_unit_box,
    place_actors,
    srgb8_to_linear,
    unit_to_world,
)
from pipeline.world.materials import MATERIAL_NAMES, material_index
from pipeline.world.mesh import Mesh
from pipeline.world.people import FAMILIES as PEOPLE

ALL_FAMILIES = [pytest.param(c, f, id=f.__name__) for c, families in FAMILIES.items() for f in families]


@pytest.mark.parametrize(("object_class", "family"), ALL_FAMILIES)
def test_every_family_spans_the_unit_box_exactly(object_class, family):
    mesh = family_mesh(family)
    np.testing.assert_array_equal(mesh.vertices.min(axis=0), [-0.5, -0.5, -0.5])
    np.testing.assert_array_equal(mesh.vertices.max(axis=0), [0.5, 0.5, 0.5])
    assert mesh.semantic == object_class.semantic
    # Outward winding: every part is a closed solid facing out (or a thin decal on one), so each closed part's signed
    # volume is positive, and so is the whole's (thin people and bicycles fill only a few % of their boxes).
    parts = _parts(mesh)
    assert all(volume > 0 for volume, closed in parts if closed)
    assert sum(volume for volume, _ in parts) > 0.02


def _parts(mesh: Mesh) -> list[tuple[float, bool]]:
    """(signed volume, closed) of each connected part (triangles sharing vertices); closed: every directed edge's
    reverse is an edge of the part (a watertight, consistently oriented surface)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    t = mesh.triangles
    graph = coo_matrix((np.ones(2 * len(t)), (np.r_[t[:, 0], t[:, 1]], np.r_[t[:, 1], t[:, 2]])),
                       shape=(len(mesh.vertices),) * 2)
    label = connected_components(graph, directed=False)[1][t[:, 0]]
    v = mesh.vertices[t]
    volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])) / 6.0
    out = []
    for k in np.unique(label):
        tk = t[label == k]
        edges = {(int(a), int(b)) for a, b in np.concatenate([tk[:, [0, 1]], tk[:, [1, 2]], tk[:, [2, 0]]])}
        out.append((float(volume[label == k].sum()), len(edges) == 3 * len(tk) and all((b, a) in edges
                                                                                      for a, b in edges)))
    return out


def _coplanar_overlaps(mesh: Mesh) -> list[tuple[int, int]]:
    """Pairs of triangles of different materials that lie in one plane and overlap with positive area (separating
    axis test on the in-plane edge normals)."""
    v = mesh.vertices[mesh.triangles]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    plane = np.round(np.column_stack([normal, np.einsum("ij,ij->i", normal, v[:, 0])]), 9)
    pairs = []
    for i in range(len(v)):
        for j in np.flatnonzero(np.all(plane[i + 1:] == plane[i], axis=1)) + i + 1:
            if mesh.material[i] == mesh.material[j]:
                continue
            edges = np.concatenate([np.roll(v[k], -1, axis=0) - v[k] for k in (i, j)])
            axes = np.cross(edges, normal[i])  # in-plane normals of all six edges
            pi, pj = v[i] @ axes.T, v[j] @ axes.T
            if np.all(np.minimum(pi.max(0), pj.max(0)) - np.maximum(pi.min(0), pj.min(0)) > 1e-9):
                pairs.append((i, j))
    return pairs


@pytest.mark.parametrize(("object_class", "family"), ALL_FAMILIES)
def test_no_two_materials_share_a_surface(object_class, family):
    # Where two coplanar triangles overlap, a ray hits both at the same t and Embree reports either, depending on
    # the BVH: the pixel's material would depend on which other actors are in the frame's scene.
    mesh = family_mesh(family)
    assert _coplanar_overlaps(mesh) == []


def test_the_coplanar_check_finds_an_overlap():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    shifted = square + [0.5, 0.5, 0.0]
    apart = square + [1.0, 0.0, 0.0]  # shares an edge only
    for other, expected in ((shifted, [(0, 2), (1, 3)]), (apart, [])):  # triangles across the diagonal only touch
        mesh = Mesh(np.concatenate([square, other]), np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]),
                    np.array([0, 0, 1, 1], np.int32), ObjectClass.CAR.semantic)
        assert sorted(_coplanar_overlaps(mesh)) == expected


PEOPLE_FAMILIES = [p for p in ALL_FAMILIES if p.values[0] in (ObjectClass.PEDESTRIAN, ObjectClass.BICYCLE,
                                                               ObjectClass.MOTORCYCLE)]


@pytest.mark.parametrize(("object_class", "family"), PEOPLE_FAMILIES)
def test_people_and_two_wheelers_are_closed_solids(object_class, family):
    """Every part of a person, bicycle or motorcycle is a watertight, outward-facing solid (no decals), and each
    model stays light."""
    mesh = family_mesh(family)
    parts = _parts(mesh)
    assert all(closed and volume > 0 for volume, closed in parts)
    assert len(parts) >= 10 and len(mesh) < 4500


def test_the_parts_check_finds_a_hole_and_an_inward_part():
    from pipeline.world.solids import ellipsoid, merge

    v, t, m = ellipsoid((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), "skin")
    assert _parts(merge([(v, t, m)], ObjectClass.PEDESTRIAN)) == [(pytest.approx(4.0, rel=0.2), True)]
    inward = _parts(merge([(v, t[:, ::-1], m)], ObjectClass.PEDESTRIAN))
    assert inward[0][0] < 0 and inward[0][1]
    assert not _parts(merge([(v, t[1:], m[1:])], ObjectClass.PEDESTRIAN))[0][1]


def _first_materials(mesh: Mesh, origins: np.ndarray, direction) -> np.ndarray:
    """(N,) material of the first triangle each ray from ``origins`` (N, 3) along ``direction`` meets; -1 = miss."""
    from pipeline.world.scene import _cast, _embree

    rays = np.column_stack([origins, np.broadcast_to(direction, origins.shape)]).astype(np.float32)
    t, prim, _ = _cast(_embree(mesh.vertices, mesh.triangles), rays)
    return np.where(np.isfinite(t), mesh.material[np.minimum(prim, len(mesh) - 1)], -1)


PEDESTRIAN_FAMILIES = [p for p in ALL_FAMILIES if p.values[0] == ObjectClass.PEDESTRIAN]
SKIN = {material_index(n) for n in ("skin", "skin_medium", "skin_dark")}
HAIR = {material_index(n) for n in MATERIAL_NAMES if n.startswith("hair_")}
SHOES = {material_index(n) for n in ("trim", "rubber", "leather", "sneaker_white")}


@pytest.mark.parametrize(("object_class", "family"), PEDESTRIAN_FAMILIES)
@pytest.mark.parametrize("pose", [0, 3, 8, 9])
def test_pedestrians_have_a_face_on_top_and_shoes_below(object_class, family, pose):
    """Walking or standing, seen from the front at eye height (6 % of the stature below the top), a person shows
    skin; from behind, hair or a hat; from above, the head (skin, hair or hat) is what is highest; at the ankles, from
    the front, shoes or skin."""
    mesh = family_mesh(family, pose)
    hat = {material_index(family.outfit.hat)} if family.outfit.hat else set()
    eyes = np.array([[5.0, 0.0, 0.44]])
    assert _first_materials(mesh, eyes, [-1.0, 0.0, 0.0])[0] in SKIN
    assert _first_materials(mesh, eyes * [-1, 1, 1], [1.0, 0.0, 0.0])[0] in HAIR | hat
    top = mesh.vertices[np.argmax(mesh.vertices[:, 2])]
    assert _first_materials(mesh, (top + [0, 0, 1.0])[None], [0.0, 0.0, -1.0])[0] in SKIN | HAIR | hat
    feet = np.array([[5.0, y, -0.49] for y in np.linspace(-0.3, 0.3, 61)])
    seen = set(_first_materials(mesh, feet, [-1.0, 0.0, 0.0]).tolist()) - {-1}
    assert seen and seen <= SHOES | SKIN


@pytest.mark.parametrize("family", ["man_jeans", "man_summer", "woman_backpack"])
@pytest.mark.parametrize("pose", [0, 4])
def test_a_walker_mid_stride_shows_daylight_between_the_legs(family, pose):
    """At the double support of the walk cycle (the left heel striking, then the right), from the side just above the
    knees (30 % of the stature), rays meet the rear leg, then miss, then meet the front leg: the legs are apart
    (higher up, at mid-thigh, a real walker's thighs overlap seen from the side)."""
    fn = next(f for f in FAMILIES[ObjectClass.PEDESTRIAN] if f.__name__ == family)
    mesh = family_mesh(fn, pose)
    origins = np.array([[x, -5.0, -0.2] for x in np.linspace(-0.5, 0.5, 201)])
    hit = _first_materials(mesh, origins, [0.0, 1.0, 0.0]) >= 0
    runs = np.flatnonzero(np.diff(hit.astype(int)))  # where hit / miss changes along x
    assert hit.any() and len(runs) >= 3, hit.astype(int)
    first, last = np.flatnonzero(hit)[[0, -1]]
    assert not hit[first:last].all()


TWO_WHEELER_FAMILIES = [p for p in ALL_FAMILIES if p.values[0] in (ObjectClass.BICYCLE, ObjectClass.MOTORCYCLE)]


@pytest.mark.parametrize(("object_class", "family"), TWO_WHEELER_FAMILIES)
def test_two_wheelers_stand_on_two_tyres_and_carry_a_rider(object_class, family):
    """From the side just above the ground, rays meet tyres (rubber) near both ends and nothing between them; a
    ray from the front at the very top meets the rider's head (skin, hair or a helmet), above the bars."""
    mesh = family_mesh(family)
    xs = np.linspace(-0.5, 0.5, 201)
    low = _first_materials(mesh, np.array([[x, -5.0, -0.49] for x in xs]), [0.0, 1.0, 0.0])
    assert set(low.tolist()) == {-1, material_index("rubber")}
    assert (low[xs < -0.25] >= 0).any() and (low[xs > 0.25] >= 0).any() and (low[np.abs(xs) < 0.1] < 0).all()
    top = mesh.vertices[np.argmax(mesh.vertices[:, 2])]
    head = _first_materials(mesh, (top + [5.0, 0.0, -0.03])[None], [-1.0, 0.0, 0.0])[0]
    assert head in {material_index(n) for n in ("skin", "trim", "paint", "glass")} | SKIN | HAIR
    assert SKIN & set(mesh.material.tolist())


VEHICLE_FAMILIES = [p for p in ALL_FAMILIES if p.values[0] in (ObjectClass.CAR, ObjectClass.VAN, ObjectClass.TRUCK,
                                                                ObjectClass.BUS)]


@pytest.mark.parametrize(("object_class", "family"), VEHICLE_FAMILIES)
def test_vehicles_have_glass_wheels_lights_and_paint(object_class, family):
    materials = set(family_mesh(family).material.tolist())
    for name in ("paint", "glass", "rubber", "rim", "headlight", "taillight", "plate", "trim"):
        assert material_index(name) in materials, name


@pytest.mark.parametrize(("object_class", "family"), VEHICLE_FAMILIES)
def test_vehicle_views_show_their_parts(object_class, family):
    """Rays along the body's axes meet what a person expects: tail lamps from behind, headlamps from the front
    (at the lamps' height, off the centre line), a tyre from the side low between the arches' centres."""
    from pipeline.world.scene import _cast, _embree

    mesh = family_mesh(family)
    scene = _embree(mesh.vertices, mesh.triangles)
    lamp = {name: np.flatnonzero(mesh.material == material_index(name)) for name in ("headlight", "taillight")}

    def first_material(origin, direction, grid):
        rays = np.array([[*(origin + g), *direction] for g in grid], np.float32)
        t, prim, _ = _cast(scene, rays)
        return set(mesh.material[prim[np.isfinite(t)]].tolist())

    # A fan of rays at every height and lateral offset: some must meet each end's lamps.
    grid = [np.array([0.0, y, z]) for y in np.linspace(-0.45, 0.45, 19) for z in np.linspace(-0.45, 0.45, 37)]
    assert material_index("taillight") in first_material(np.array([-5.0, 0.0, 0.0]), [1.0, 0.0, 0.0], grid)
    assert material_index("headlight") in first_material(np.array([5.0, 0.0, 0.0]), [-1.0, 0.0, 0.0], grid)
    side = [np.array([x, 0.0, z]) for x in np.linspace(-0.45, 0.45, 46) for z in np.linspace(-0.5, -0.3, 5)]
    seen = first_material(np.array([0.0, -5.0, 0.0]), [0.0, 1.0, 0.0], side)
    assert {material_index("rubber"), material_index("rim")} <= seen
    assert len(lamp["headlight"]) and len(lamp["taillight"])


def test_variants_pick_families_that_suit_the_length():
    """A car's variant picks among the car families whose length range holds its length; the same variant and
    length give the same model; a 16 m truck is a semi-trailer, an 8 m one a box truck."""
    meshes = ActorMeshes()
    n = 400
    rng = np.random.default_rng(1)
    lengths = rng.uniform(3.6, 5.5, n)
    boxes = Boxes3D(np.zeros((n, 3)), np.column_stack([lengths, np.full(n, 1.8), np.full(n, 1.5)]), np.zeros(n))
    actors = Actors(np.arange(1, n + 1), ["car"] * n, boxes, np.zeros((n, 3)),
                    variant=actor_variants(np.arange(1, n + 1), 7))
    codes = meshes.model_codes(actors)
    suits = {f.__name__: SUITS_LENGTH_M[f] for f in FAMILIES[ObjectClass.CAR]}
    for code, length in zip(codes, lengths, strict=True):
        assert meshes.model_class[code] == ObjectClass.CAR
        lo, hi = suits[meshes.model_names[code]]
        assert lo <= length < hi
    assert len(set(codes.tolist())) >= 5  # several families in a fleet of 400
    np.testing.assert_array_equal(meshes.model_codes(actors), codes)
    trucks = Actors([1, 2], ["truck", "truck"], Boxes3D(np.zeros((2, 3)), [[16.0, 2.5, 4.0], [8.0, 2.5, 3.5]],
                                                         np.zeros(2)), np.zeros((2, 3)), variant=[5, 5])
    # 16 m: the two articulated families suit it (variant 5 picks the second), 8 m: only the box truck.
    assert [meshes.model_names[c] for c in meshes.model_codes(trucks)] == ["curtain_trailer", "box_truck"]


def test_user_pedestrian_models_take_their_depth():
    """A user's pedestrian model of known proportions gets its own depth at SUMO's height (so it is not squashed to
    SUMO's 0.215 m); cars keep their length; a user's model of unknown proportions keeps SUMO's depth."""
    n = 4
    boxes = Boxes3D(np.zeros((n + 1, 3)), [[0.215, 0.478, 1.719]] * n + [[4.5, 1.8, 1.5]], np.zeros(n + 1))
    actors = Actors(np.arange(1, n + 2), ["pedestrian"] * n + ["car"], boxes, np.zeros((n + 1, 3)),
                    variant=actor_variants(np.arange(1, n + 2), 3))
    walker = FAMILIES[ObjectClass.PEDESTRIAN][0]
    known = ActorMeshes(overrides={ObjectClass.PEDESTRIAN: [Model("walker", family_mesh(walker, 2),
                                                                  tuple(family_extent(walker, 2)))]})
    length = known.body_lengths(actors)
    extent = family_extent(walker, 2)
    np.testing.assert_allclose(length[:n], extent[0] * 1.719 / extent[2], rtol=1e-12)
    assert length[-1] == 4.5
    user = ActorMeshes(overrides={ObjectClass.PEDESTRIAN: normalise_to_unit_box(family_mesh(walker))})
    np.testing.assert_array_equal(user.body_lengths(actors), boxes.size[:, 0])


def test_poses_pick_the_models_of_a_family():
    """A person's family comes from its variant alone; its pose picks that family's mesh (modulo its poses)."""
    meshes = ActorMeshes()
    n = 30
    boxes = Boxes3D(np.zeros((n, 3)), [[0.215, 0.478, 1.719]] * n, np.zeros(n))
    variant = actor_variants(np.arange(1, n + 1), 3)
    base = Actors(np.arange(1, n + 1), ["pedestrian"] * n, boxes, np.zeros((n, 3)), variant=variant)
    family = meshes.family_codes(base)
    poses = PEOPLE[0].poses  # walking, standing and running: 19 (the umbrella poses: umbrella_meshes)
    assert poses == 19
    for pose in (0, 5, 10, 11, 18, 19):
        posed = Actors(base.track_id, base.object_class, boxes, base.color_rgb, variant=variant, pose=np.full(n, pose))
        np.testing.assert_array_equal(meshes.family_codes(posed), family)
        codes = meshes.model_codes(posed)
        assert [meshes.model_pose[c] for c in codes] == [pose % poses] * n
        assert [meshes.model_names[c] for c in codes] == [meshes.families[f].__name__ for f in family]


def test_actor_variants_depend_on_seed_and_track_only():
    a = actor_variants(np.array([1, 2, 3, 1]), 5)
    assert a.dtype == np.uint32 and a[0] == a[3] and len(set(a[:3].tolist())) == 3
    assert not np.array_equal(a, actor_variants(np.array([1, 2, 3, 1]), 6))


def test_placed_mesh_touches_all_six_faces_of_its_box():
    rng = np.random.default_rng(0)
    n = 14
    classes = [list(ObjectClass)[i % 7] for i in range(n)]
    boxes = Boxes3D(rng.uniform(-50, 50, (n, 3)), rng.uniform(0.4, 12.0, (n, 3)), rng.uniform(-np.pi, np.pi, n))
    actors = Actors(np.arange(10, 10 + n), classes, boxes, rng.uniform(0, 1, (n, 3)))
    geo = place_actors(actors)
    assert len(geo.triangles) == sum(len(canonical_mesh(c)) for c in classes)
    for k in range(n):
        v = geo.vertices[geo.vertex_actor == k].astype(np.float64) - boxes.center[k]
        c, s = np.cos(boxes.yaw_rad[k]), np.sin(boxes.yaw_rad[k])
        local = np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]])
        tol = 1e-5 * (1.0 + np.abs(boxes.center[k]).max())  # float32 vertices
        np.testing.assert_allclose(local.min(axis=0), -0.5 * boxes.size[k], atol=tol)
        np.testing.assert_allclose(local.max(axis=0), 0.5 * boxes.size[k], atol=tol)
        tri_owner = geo.vertex_actor[geo.triangles[geo.triangle_actor == k]]
        assert np.all(tri_owner == k)
        own = geo.triangle_semantic[geo.triangle_actor == k]
        assert np.all((own == classes[k].semantic) | (own == SemanticClass.RIDER))  # a two-wheeler's rider: RIDER
        assert (own == SemanticClass.RIDER).any() == (classes[k] in (ObjectClass.BICYCLE, ObjectClass.MOTORCYCLE))


def test_unit_to_world_maps_unit_corners_to_box_corners():
    boxes = Boxes3D([[3.0, -2.0, 0.8]], [[4.5, 1.8, 1.6]], [0.7])
    signs = np.array(
        [[1, 1, -1], [-1, 1, -1], [-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1], [-1, -1, 1], [1, -1, 1]]
    )
    a = unit_to_world(boxes)[0]
    np.testing.assert_allclose(0.5 * signs @ a[:, :3].T + a[:, 3], boxes.corners()[0], atol=1e-12)


def test_actor_validation():
    boxes = Boxes3D(np.zeros((2, 3)), np.ones((2, 3)), np.zeros(2))
    with pytest.raises(ValueError, match="unique"):
        Actors([3, 3], ["car", "car"], boxes, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="positive"):
        Actors([0, 1], ["car", "car"], boxes, np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        Actors([1, 2], ["car", "car"], boxes, np.full((2, 3), 255.0))
    with pytest.raises(ValueError, match="differ"):
        Actors([1], ["car", "car"], boxes, np.zeros((2, 3)))
    with pytest.raises(ValueError):
        Actors([1, 2], ["car", "spaceship"], boxes, np.zeros((2, 3)))
    assert len(Actors.empty()) == 0 and len(place_actors(Actors.empty()).triangles) == 0


def test_mesh_overrides_must_fill_the_unit_box():
    tri = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 1]], [[0, 1, 2]], 0, ObjectClass.CAR.semantic)
    with pytest.raises(ValueError, match="exactly"):
        ActorMeshes({ObjectClass.CAR: tri})
    unit = normalise_to_unit_box(tri)
    assert ActorMeshes({ObjectClass.CAR: unit})[ObjectClass.CAR] is unit


def test_srgb8_to_linear():
    np.testing.assert_allclose(srgb8_to_linear([[0, 255, 188]]), [[0.0, 1.0, 0.5029]], atol=1e-3)


@pytest.mark.parametrize("codes", [[], [-1, -1], [3], [2, 0, 2, -1, 5, 0, 0, 7, 2], list(range(9, -3, -1))])
def test_code_groups_are_the_per_code_comparisons(codes):
    """One stable sort gives, code by code ascending, the positions a comparison per code gives (negatives left out),
    as int64 like ``np.flatnonzero``: the order in which the placed actors' vertices are stacked."""
    codes = np.array(codes, np.int32)
    got = list(code_groups(codes))
    want = [(c, np.flatnonzero(codes == c)) for c in sorted(set(codes.tolist())) if c >= 0]
    assert [c for c, _ in got] == [c for c, _ in want]
    for (_, sel), (_, ref) in zip(got, want, strict=True):
        assert sel.dtype == ref.dtype and np.array_equal(sel, ref)


def test_code_groups_on_many_random_codes():
    codes = np.random.default_rng(4).integers(-1, 600, 5000)
    got = dict(code_groups(codes))
    assert sorted(got) == sorted(set(codes[codes >= 0].tolist()))
    for c, sel in got.items():
        assert np.array_equal(sel, np.flatnonzero(codes == c))
