"""Ray casting against static geometry plus actors: closed-form hits, attributes, objects alone, shadows."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actors import Actors
from pipeline.world.materials import material_arrays, material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene


def ground(z: float = 0.0) -> Mesh:
    v = np.array([[-100, -100, z], [100, -100, z], [100, 100, z], [-100, 100, z]], dtype=np.float64)
    return Mesh(v, [[0, 1, 2], [0, 2, 3]], material_index("asphalt"), SemanticClass.ROAD)


def car_at(x: float, y: float, yaw: float = 0.0, track_id: int = 7) -> Actors:
    return Actors([track_id], [ObjectClass.CAR], Boxes3D([[x, y, 0.75]], [[4.5, 1.8, 1.5]], [yaw]), [[0.8, 0.1, 0.1]])


def test_static_ground_hit_and_miss():
    scene = FrameScene(StaticScene([ground()]), Actors.empty())
    origins = np.array([[0, 0, 2.0], [0, 0, 2.0], [0, 0, -3.0]])
    hits = scene.cast(origins, np.array([[3, 0, -4.0], [0, 0, 1], [0, 0, 1]]))
    assert hits.hit.tolist() == [True, False, True]
    np.testing.assert_allclose(hits.t_m[[0, 2]], [2.0 * 5 / 4, 3.0], rtol=1e-6)
    assert np.isinf(hits.t_m[1])
    assert hits.semantic.tolist() == [SemanticClass.ROAD, 0, SemanticClass.ROAD]
    assert hits.instance_id.tolist() == [0, 0, 0]
    np.testing.assert_allclose(hits.normal, [[0, 0, 1], [0, 0, 0], [0, 0, -1]], atol=1e-6)  # faces the origin
    np.testing.assert_allclose(hits.color[0], material_arrays()["albedo"][material_index("asphalt")])


@pytest.mark.parametrize("yaw", [0.0, 0.4, -2.0])
def test_actor_side_hit_is_exact_and_carries_paint_and_id(yaw):
    """A ray at the car's flank meets its placed mesh where an independent ray-triangle test (double precision)
    meets the canonical mesh, mapped by the placement: the side at mid-length, 0.6 m up (paint)."""
    from pipeline.world.actors import canonical_mesh
    from pipeline.world.loft import surface_point

    scene = FrameScene(StaticScene([ground()]), car_at(20.0, 3.0, yaw))
    left = np.array([-np.sin(yaw), np.cos(yaw), 0.0])  # the car's +y in the world
    origin = np.array([20.0, 3.0, 0.6]) + 10.0 * left
    hits = scene.cast(origin[None], -left[None])
    mesh = canonical_mesh(ObjectClass.CAR)
    point, normal = surface_point(mesh.vertices, mesh.triangles, np.array([0.0, 10.0, (0.6 - 0.75) / 1.5]),
                                  np.array([0.0, -1.0, 0.0]))
    assert hits.hit[0] and hits.instance_id[0] == 7 and hits.actor_index[0] == 0
    assert hits.t_m[0] == pytest.approx(10.0 - point[1] * 1.8, abs=1e-4)
    assert hits.semantic[0] == SemanticClass.CAR and hits.material[0] == material_index("paint")
    np.testing.assert_allclose(hits.color[0], [0.8, 0.1, 0.1])
    # The unit-frame normal maps by the inverse transpose of diag(4.5, 1.8, 1.5), then turns with the yaw.
    n = normal / np.array([4.5, 1.8, 1.5])
    n /= np.linalg.norm(n)
    world = np.array([n[0] * np.cos(yaw) - n[1] * np.sin(yaw), n[0] * np.sin(yaw) + n[1] * np.cos(yaw), n[2]])
    np.testing.assert_allclose(hits.normal[0], world, atol=1e-5)
    assert world @ left > 0.9  # it is the flank


def test_cast_alone_sees_through_occluders_and_matches_the_scene():
    actors = Actors([4, 9], [ObjectClass.CAR, ObjectClass.BUS],
                    Boxes3D([[20, 0, 0.75], [10, 0, 1.6]], [[4.5, 1.8, 1.5], [12, 2.55, 3.2]], [0.0, 0.3]),
                    [[0.1, 0.2, 0.3], [0.9, 0.9, 0.1]])
    scene = FrameScene(StaticScene([ground()]), actors)
    o = np.zeros((3, 3)) + [0.0, 0.0, 0.6]
    d = np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0.5, 0]])
    hits = scene.cast(o, d)
    assert hits.instance_id.tolist()[:2] == [9, 9]
    alone, t = scene.cast_alone(o, d, [0, 1, 0])
    assert alone.tolist() == [True, True, False]
    # The car's rear face (its plate), behind the bus: within a few cm of the box's rear.
    assert 20 - 2.25 <= t[0] <= 20 - 2.25 + 0.05
    assert t[1] == pytest.approx(hits.t_m[1], abs=1e-4)  # the bus alone = the bus in the scene
    with pytest.raises(ValueError, match="out of range"):
        scene.cast_alone(o, d, [0, 2, 0])


def test_actor_mask_skips_actor_cast_only_where_told():
    scene = FrameScene(StaticScene([ground()]), car_at(20.0, 0.0))
    o, d = np.array([[0, 0, 0.6], [0, 0, 0.6]]), np.array([[1.0, 0, 0], [1.0, 0, 0]])
    hits = scene.cast(o, d, actor_rays=np.array([True, False]))
    assert hits.instance_id.tolist() == [7, 0]


def test_shadow_rays():
    scene = FrameScene(StaticScene([ground()]), car_at(0.0, 0.0))
    blocked = scene.occluded(np.array([[0, 0, 10.0], [0, 0, 10.0], [0, 5.0, 0.01]]),
                             np.array([[0, 0, -1.0], [0, 0, 1.0], [0, 0, 1.0]]), t_max_m=20.0)
    assert blocked.tolist() == [True, False, False]
    assert scene.occluded(np.array([[0, 0, 10.0]]), np.array([[0, 0, -1.0]]), t_max_m=5.0).tolist() == [False]


def test_bad_rays_raise():
    scene = FrameScene(StaticScene([]), Actors.empty())
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        scene.cast(np.zeros((2, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="non-zero"):
        scene.cast(np.zeros((1, 3)), np.zeros((1, 3)))
    assert not scene.cast(np.zeros((1, 3)), np.ones((1, 3))).hit[0]


def test_static_materials_can_change_per_frame():
    empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3)), 0, SemanticClass.ROAD)
    static = StaticScene([empty, ground(-1.0), ground(0.0)])
    np.testing.assert_array_equal(static.mesh_offsets, [0, 0, 2, 4])
    scene = FrameScene(static, Actors.empty())
    ray = (np.array([[0, 0, 5.0]]), np.array([[0, 0, -1.0]]))
    assert scene.cast(*ray).material[0] == material_index("asphalt")
    static.set_triangle_materials(2, [0, 1], material_index("lamp"))
    assert scene.cast(*ray).material[0] == material_index("lamp")
    with pytest.raises(ValueError, match="out of range"):
        static.set_triangle_materials(1, [2], 0)


def test_rectangles_mask_is_the_union_of_clipped_rectangles():
    from pipeline.world.scene import rectangles_mask

    lo = np.array([[1, 2], [3, 0], [-4, 8], [5, 5], [6, 1]])
    hi = np.array([[4, 6], [9, 3], [2, 20], [5, 9], [2, 4]])  # the last two are empty
    expected = np.zeros((7, 10), bool)
    expected[1:4, 2:6] = expected[3:7, 0:3] = expected[0:2, 8:10] = True
    np.testing.assert_array_equal(rectangles_mask(7, 10, lo, hi), expected)
    assert not rectangles_mask(7, 10, np.zeros((0, 2)), np.zeros((0, 2))).any()


def test_make_rays_rotates_directions_and_repeats_the_origin():
    from pipeline.world.scene import make_rays

    c, s = np.cos(0.3), np.sin(0.3)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    dirs = np.array([[1.0, 0.0, 0.0], [0.0, 0.6, 0.8]], np.float32)
    rays = make_rays([1.0, -2.0, 3.5], dirs, rotation)
    assert rays.shape == (2, 6) and rays.dtype == np.float32
    np.testing.assert_array_equal(rays[:, :3], [[1.0, -2.0, 3.5]] * 2)
    np.testing.assert_allclose(rays[:, 3:], dirs @ rotation.T, atol=1e-7)
    assert make_rays([0.0, 0.0, 0.0], np.zeros((0, 3), np.float32), rotation).shape == (0, 6)


def test_make_rays_agrees_with_opencvs_transform():
    """make_rays computes OpenCV's transform with fused multiply-adds: within rounding of OpenCV's own result for
    every point. Not bytes: how many trailing points OpenCV leaves to its scalar loop (rounded otherwise) depends
    on the processor's SIMD width, and a test must pass on any x86-64 machine."""
    import cv2
    from scipy.spatial.transform import Rotation

    from pipeline.world.scene import make_rays

    rng = np.random.default_rng(5)
    dirs = rng.normal(size=(20000, 3)).astype(np.float32)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    rotation = Rotation.random(random_state=6).as_matrix()
    origin = np.array([1234.5, -678.25, 3.75])
    rays = make_rays(origin, dirs, rotation)
    opencv = cv2.transform(dirs.reshape(-1, 1, 3), rotation.astype(np.float32)).reshape(-1, 3)
    np.testing.assert_array_equal(rays[:, :3], np.broadcast_to(origin.astype(np.float32), (len(dirs), 3)))
    # unit vectors: two float32 roundings of three products differ by at most a few 6e-8 ulps
    np.testing.assert_allclose(rays[:, 3:], opencv, rtol=0, atol=2.5e-7)


def test_make_rays_rotates_closed_form():
    """A quarter turn about z maps a direction (x, y, z) to (-y, x, z) exactly (products with 0 and 1 round to
    themselves, on any processor); the origin is every ray's."""
    from pipeline.world.scene import make_rays

    rng = np.random.default_rng(3)
    dirs = rng.normal(size=(1001, 3)).astype(np.float32)
    rays = make_rays(np.array([1.0, 2.0, 3.0]), dirs, np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert rays.dtype == np.float32 and rays.shape == (1001, 6)
    np.testing.assert_array_equal(rays[:, :3], np.broadcast_to(np.float32([1.0, 2.0, 3.0]), (1001, 3)))
    np.testing.assert_array_equal(rays[:, 3:], np.column_stack([-dirs[:, 1], dirs[:, 0], dirs[:, 2]]))


def sun_towards(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def test_sun_actor_candidates_closed_form():
    # A car (x in [-2.25, 2.25], z in [0, 1.5]) under a sun 45 degrees up towards +x: its shadow reaches
    # x = -3.75 on the road. A ray from (-3, 0) rises through the car; from (-10, 0) it passes 7.8 m above it;
    # (2, 0, 5) lies on the line of a car's point along the sun, but above the car: its ray only rises.
    scene = FrameScene(StaticScene([ground()]), car_at(0.0, 0.0))
    sun = sun_towards(45.0, 0.0)
    points = np.array([[-3.0, 0.0, 0.01], [-10.0, 0.0, 0.01], [0.0, 5.0, 0.01], [2.0, 0.0, 5.0], [3.0, 0.0, 0.01]],
                      np.float32)
    cand = scene.sun_actor_candidates(*points.T, sun)
    assert cand.tolist() == [True, False, False, False, False]
    rays = np.column_stack([points, np.broadcast_to(sun, points.shape)]).astype(np.float32)
    assert scene.occluded_rays(rays, actor_rays=cand).tolist() == [True, False, False, False, False]
    with pytest.raises(ValueError, match="upwards"):
        scene.sun_actor_candidates(*points.T, -sun)
    empty = FrameScene(StaticScene([ground()]), Actors.empty())
    assert not empty.sun_actor_candidates(*points.T, sun).any()


@pytest.mark.parametrize("seed", range(4))
def test_sun_actor_candidates_keep_every_ray_an_actor_blocks(seed):
    """Random actors, points on and above the road and suns: the candidates contain every ray that the actors
    block (cast against all of them, in a scene of the actors alone), so the masked shadow test equals the
    unmasked one; and they leave most rays out (the mask does work)."""
    rng = np.random.default_rng(seed)
    n = 60
    classes = [list(ObjectClass)[i] for i in rng.integers(0, len(ObjectClass), n)]
    size = rng.uniform([0.5, 0.5, 1.2], [12.0, 2.6, 3.6], (n, 3))
    centre = np.column_stack([rng.uniform(-80, 80, (n, 2)), size[:, 2] / 2])
    actors = Actors(np.arange(1, n + 1), classes, Boxes3D(centre, size, rng.uniform(-np.pi, np.pi, n)),
                    rng.uniform(0, 1, (n, 3)))
    scene = FrameScene(StaticScene([ground()]), actors, threads=1)
    points = np.column_stack([rng.uniform(-90, 90, (20000, 2)), rng.choice([0.01, 0.5, 2.0, 4.0], 20000)])
    points = points.astype(np.float32)
    sun = sun_towards(rng.uniform(3.0, 89.0), rng.uniform(-180.0, 180.0))
    rays = np.column_stack([points, np.broadcast_to(sun, points.shape)]).astype(np.float32)
    cand = scene.sun_actor_candidates(*points.T, sun)
    by_actors = FrameScene(StaticScene([]), actors, threads=1).occluded_rays(rays)
    assert by_actors.any() and not (by_actors & ~cand).any()
    np.testing.assert_array_equal(scene.occluded_rays(rays, actor_rays=cand), scene.occluded_rays(rays))
    assert cand.mean() < 0.5


@pytest.mark.parametrize("seed", range(3))
def test_sun_disc_candidates_hold_each_directions_candidates(seed):
    """Rays along the 16 directions over a (here widened) sun's disc, all in one grid: every ray that the actors
    block is a candidate, so the masked shadow test equals the unmasked one; and they still leave most rays out."""
    from pipeline.sensors.shadows import sun_disc

    rng = np.random.default_rng(seed)
    n = 60
    size = rng.uniform([0.5, 0.5, 1.2], [12.0, 2.6, 3.6], (n, 3))
    centre = np.column_stack([rng.uniform(-80, 80, (n, 2)), size[:, 2] / 2])
    actors = Actors(np.arange(1, n + 1), [ObjectClass.CAR] * n, Boxes3D(centre, size, rng.uniform(-np.pi, np.pi, n)),
                    rng.uniform(0, 1, (n, 3)))
    scene = FrameScene(StaticScene([ground()]), actors, threads=1)
    points = np.column_stack([rng.uniform(-90, 90, (20000, 2)), rng.choice([0.01, 0.5, 2.0, 4.0], 20000)])
    points = points.astype(np.float32)
    disc = sun_disc(sun_towards(rng.uniform(5.0, 60.0), rng.uniform(-180.0, 180.0)), np.radians(3.0))
    which = rng.integers(0, len(disc), len(points))
    cand = scene.sun_disc_actor_candidates(*points.T, disc, which)
    rays = np.column_stack([points, disc[which]]).astype(np.float32)
    by_actors = FrameScene(StaticScene([]), actors, threads=1).occluded_rays(rays)
    assert by_actors.any() and not (by_actors & ~cand).any()
    np.testing.assert_array_equal(scene.occluded_rays(rays, actor_rays=cand), scene.occluded_rays(rays))
    assert cand.mean() < 0.5


@pytest.mark.parametrize("material", ["foliage", "building"])
def test_static_foliage_gets_smooth_normals(material):
    """A ray at an icosahedron of foliage gets the corners' normals interpolated at the hit (on a regular
    icosahedron the corner normals are the vertex directions, exactly), one of another material its face's normal."""
    from pipeline.world.primitives import ICO_FACES, ICO_VERTICES

    mesh = Mesh(ICO_VERTICES * 2.0, ICO_FACES, material_index(material), SemanticClass.VEGETATION)
    scene = FrameScene(StaticScene([mesh]), Actors.empty())
    rng = np.random.default_rng(0)
    target = rng.normal(size=(200, 3)) * 0.3
    origins = target + rng.normal(size=(200, 3)) * 0.1 + [[0.0, 0.0, 10.0]]
    hits = scene.cast(origins, target - origins)
    assert hits.hit.all()
    d = target - origins
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    point = origins + d * hits.t_m[:, None]
    v = (ICO_VERTICES * 2.0)[ICO_FACES]  # (20, 3, 3)
    # Which face: the one whose plane holds the point.
    face_n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    face = np.argmin(np.abs(np.einsum("fk,nk->nf", face_n, point) - np.einsum("fk,fk->f", face_n, v[:, 0])[None]), 1)
    if material == "building":
        np.testing.assert_allclose(hits.normal, face_n[face], atol=1e-5)
        return
    a, b, c = v[face, 0], v[face, 1], v[face, 2]
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    w = np.stack([np.linalg.norm(np.cross(q - p, point - p), axis=1) for p, q in ((b, c), (c, a), (a, b))], 1)
    w /= area[:, None]  # barycentric weights of a, b, c
    expected = np.einsum("nk,nkd->nd", w, v[face] / 2.0)
    expected /= np.linalg.norm(expected, axis=1, keepdims=True)
    np.testing.assert_allclose(hits.normal, expected, atol=1e-4)
    assert np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", hits.normal, face_n[face]), -1, 1))).max() > 10.0


def test_sun_footprints_are_each_runs_projected_bounds():
    """The compiled footprint pass against its definition: along_sun of every vertex, then min and max per run
    (numpy's reduceat), to the bit."""
    from pipeline.world.scene import _run_bounds_along_suns
    from pipeline.world.sunmap import along_sun

    rng = np.random.default_rng(3)
    vertices = rng.uniform(-800, 800, (5000, 3)) * [1, 1, 0.01]
    starts = np.concatenate([[0], np.sort(rng.choice(np.arange(1, 5000), 40, replace=False))])
    for slope in (np.array([0.3, -1.7]), np.zeros(2)):
        flat = np.column_stack(along_sun(*vertices.T, slope))
        lo, hi = _run_bounds_along_suns(vertices, starts, *slope, *slope)  # one sun: equal ends
        np.testing.assert_array_equal(lo, np.minimum.reduceat(flat, starts, axis=0))
        np.testing.assert_array_equal(hi, np.maximum.reduceat(flat, starts, axis=0))


def test_union_of_sun_footprints_over_a_disc_is_the_per_slope_passes_union():
    """One pass over a range of slopes (the sun's disc) against the union of one pass per slope, to the bit: vertices
    above, below and on z = 0, slopes of both signs."""
    from pipeline.world.scene import _run_bounds_along_suns

    rng = np.random.default_rng(5)
    vertices = rng.uniform(-800, 800, (6000, 3)) * [1, 1, 0.02]
    vertices[::7, 2] = 0.0
    starts = np.concatenate([[0], np.sort(rng.choice(np.arange(1, 6000), 50, replace=False))])
    slopes = np.column_stack([rng.uniform(-0.9, -0.85, 16), rng.uniform(0.31, 0.33, 16)])
    slopes[3] = [0.2, -0.1]  # a range across 0 in both axes
    per = [_run_bounds_along_suns(vertices, starts, *s, *s) for s in slopes]
    lo, hi = _run_bounds_along_suns(vertices, starts, *slopes.min(axis=0), *slopes.max(axis=0))
    np.testing.assert_array_equal(lo, np.minimum.reduce([p[0] for p in per]))
    np.testing.assert_array_equal(hi, np.maximum.reduce([p[1] for p in per]))


def test_frame_scene_hull_vertices_are_the_placed_meshes_on_the_hull():
    """FrameScene places only the hull vertices per frame: the same numbers, in the same order, as those of the
    whole placed meshes (geometry, placed on demand)."""
    rng = np.random.default_rng(8)
    n = 30
    actors = Actors(np.arange(1, n + 1), [list(ObjectClass)[i] for i in rng.integers(0, 7, n)],
                    Boxes3D(rng.uniform(-50, 50, (n, 3)), rng.uniform(0.5, 12, (n, 3)), rng.uniform(-3, 3, n)),
                    rng.uniform(0, 1, (n, 3)))
    scene = FrameScene(StaticScene([]), actors, active=rng.uniform(size=n) < 0.7)
    hull = scene.geometry.vertex_on_hull
    np.testing.assert_array_equal(scene.hull_vertices, scene.geometry.vertices[hull])
    np.testing.assert_array_equal(scene.hull_actor, scene.geometry.vertex_actor[hull])
