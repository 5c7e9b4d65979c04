"""Which sun shadow rays may meet the static world (pipeline.world.sunmap): a closed-form wall, and random worlds
of boxes, thin walls and floating strips against the shadow rays' real Embree occlusion test."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import SemanticClass
from pipeline.sensors.shadows import sun_disc
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import StaticScene
from pipeline.world.sunmap import SUN_CELL_M, SUN_TILE_CELLS, SunMap, SunTiles, sun_slope

CONCRETE = material_index("concrete")


def quad(corners) -> Mesh:
    return Mesh(np.asarray(corners, float), np.array([[0, 1, 2], [0, 2, 3]]), CONCRETE, SemanticClass.BUILDING)


def box(lo, hi) -> Mesh:
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], float)
    t = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return Mesh(v, t, CONCRETE, SemanticClass.BUILDING)


def sun_at(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], np.float32)


GROUND = quad([[-100, -100, 0], [100, -100, 0], [100, 100, 0], [-100, 100, 0]])
WALL = quad([[10, -5, 0], [10, 5, 0], [10, 5, 3], [10, -5, 3]])  # 3 m tall, in the plane x = 10


def sun_rays(points: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """(N, 6) float32 rays from the points towards the (unit) sun."""
    return np.hstack([points, np.tile(sun, (len(points), 1))]).astype(np.float32)


def candidates(meshes, points, sun):
    merged = Mesh.concatenate(meshes)
    p = np.asarray(points, np.float32)
    return SunMap(merged.vertices, merged.triangles, sun).candidates(p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy())


def test_a_wall_shadows_the_ground_behind_it_and_nothing_else():
    # The sun 45 degrees up towards +x: the wall's shadow covers 7 <= x <= 10 behind it (|y| <= 5).
    sun = sun_at(0.0, 45.0)
    points = [[8.0, 0.0, 1e-3], [7.2, 4.8, 1e-3],  # in the shadow
              [5.0, 0.0, 1e-3], [8.0, 8.0, 1e-3], [12.0, 0.0, 1e-3],  # before it, beside it, past the wall
              [8.0, 0.0, 3.5],  # above the wall's top
              [-50.0, 30.0, 1e-3]]  # open ground: only the ground itself (at z = 0) is below
    assert candidates([GROUND, WALL], points, sun).tolist() == [True, True, False, False, False, False, False]
    rays = sun_rays(np.asarray(points, np.float32), sun)
    assert StaticScene([GROUND, WALL]).occluded(rays, np.inf).tolist() == [True, True] + [False] * 5


def test_the_sun_must_be_up():
    with pytest.raises(ValueError, match="sun must point upwards"):
        SunMap(WALL.vertices, WALL.triangles, np.array([0.0, 0.0, -1.0]))


def random_world(rng: np.random.Generator) -> list[Mesh]:
    """Ground, boxes, thin vertical walls (kerbs) and floating strips (lane paint) at random poses, spanning
    several tiles on both sides of the origin."""
    meshes = [GROUND]
    for _ in range(40):
        lo = np.r_[rng.uniform(-60, 60, 2), rng.uniform(0.0, 2.0)]
        meshes.append(box(lo, lo + np.r_[rng.uniform(0.1, 8.0, 2), rng.uniform(0.05, 12.0)]))
    for _ in range(40):
        a, d = rng.uniform(-60, 60, 2), rng.normal(size=2)
        b = a + d / np.linalg.norm(d) * rng.uniform(0.5, 40.0)
        h = rng.choice([0.02, 0.15, 1.0])
        if rng.random() < 0.5:  # a vertical wall h tall
            meshes.append(quad([[*a, 0], [*b, 0], [*b, h], [*a, h]]))
        else:  # a horizontal strip 12 cm wide, h above the ground
            n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a) * 0.06
            meshes.append(quad([[*(a - n), h], [*(b - n), h], [*(b + n), h], [*(a + n), h]]))
    return meshes


@pytest.mark.parametrize("seed", range(4))
def test_every_blocked_shadow_ray_is_a_candidate(seed):
    rng = np.random.default_rng(seed)
    meshes = random_world(rng)
    sun = sun_at(rng.uniform(-180, 180), rng.uniform(10, 70))
    n = 40_000
    # Points on the ground just off it (as shading lifts them), and points anywhere up to 6 m.
    z = np.where(np.arange(n) < n // 2, 1e-3, rng.uniform(0.0, 6.0, n))
    points = np.column_stack([rng.uniform(-70, 70, (n, 2)), z]).astype(np.float32)
    found = candidates(meshes, points, sun)
    blocked = StaticScene(meshes).occluded(sun_rays(points, sun), np.inf)
    assert not np.any(blocked & ~found)
    assert np.count_nonzero(found) < 0.7 * n  # the test leaves most rays out
    tiles = np.unique(np.floor(points[:, :2] / (SUN_TILE_CELLS * SUN_CELL_M)), axis=0)
    assert len(tiles) >= 16 and tiles.min() < 0  # drawn tile by tile, on both sides of the origin


def test_the_masked_static_test_equals_the_full_one():
    rng = np.random.default_rng(7)
    meshes = random_world(rng)
    scene = StaticScene(meshes)
    sun = sun_at(30.0, 25.0)
    points = np.column_stack([rng.uniform(-70, 70, (20_000, 2)), np.full(20_000, 1e-3)]).astype(np.float32)
    rays = sun_rays(points, sun)
    mask = scene.sun_candidates(*(points[:, k].copy() for k in range(3)), sun)
    assert np.array_equal(scene.occluded(rays, np.inf, where=mask), scene.occluded(rays, np.inf))
    assert scene.occluded(rays, np.inf, where=mask).any()


def test_points_by_rows_and_in_place():
    """A subset by ``rows`` of the columns of an (N, 6) ray array, read in place, gives the candidates of those
    points alone; and no rows, none."""
    rng = np.random.default_rng(5)
    meshes = random_world(rng)
    sun = sun_at(-60.0, 35.0)
    points = np.column_stack([rng.uniform(-70, 70, (5000, 2)), rng.uniform(0.0, 3.0, 5000)]).astype(np.float32)
    rays = sun_rays(points, sun)
    merged = Mesh.concatenate(meshes)
    sun_map = SunMap(merged.vertices, merged.triangles, sun)
    rows = np.sort(rng.choice(len(points), 1200, replace=False))
    subset = sun_map.candidates(rays[:, 0], rays[:, 1], rays[:, 2], rows)
    alone = candidates(meshes, points[rows], sun)
    assert subset.any() and not subset.all()
    np.testing.assert_array_equal(subset, alone)
    assert sun_map.candidates(rays[:, 0], rays[:, 1], rays[:, 2], np.zeros(0, np.int64)).shape == (0,)


def sloped_world(rng: np.random.Generator) -> list[Mesh]:
    """The random world, with ramps (quads at slopes up to 40%) and triangles at any orientation added."""
    meshes = random_world(rng)
    for _ in range(30):
        a, d = rng.uniform(-60, 60, 2), rng.normal(size=2)
        u = d / np.linalg.norm(d)
        along, across = u * rng.uniform(2.0, 30.0), np.array([-u[1], u[0]]) * rng.uniform(0.5, 8.0)
        z0, slope = rng.uniform(0.0, 3.0), rng.uniform(-0.4, 0.4)
        rise = slope * np.linalg.norm(along)
        meshes.append(quad([[*a, z0], [*(a + along), z0 + rise], [*(a + along + across), z0 + rise],
                            [*(a + across), z0]]))
    for _ in range(30):
        v = np.r_[rng.uniform(-60, 60, 2), rng.uniform(0.0, 4.0)] + rng.normal(scale=3.0, size=(3, 3))
        meshes.append(Mesh(v, np.array([[0, 1, 2]]), CONCRETE, SemanticClass.BUILDING))
    return meshes


@pytest.mark.parametrize("seed", range(4))
def test_every_blocked_shadow_ray_from_a_surface_is_a_candidate(seed):
    """Shadow rays start just off a surface (shading lifts them along the normal): a cell's height must bound every
    triangle's over the whole cell, ramps and tilted triangles included, to within the lift."""
    rng = np.random.default_rng(100 + seed)
    meshes = sloped_world(rng)
    sun = sun_at(rng.uniform(-180, 180), rng.uniform(10, 70))
    merged = Mesh.concatenate(meshes)
    n = 60_000
    tri = rng.integers(0, len(merged.triangles), n)
    w = rng.dirichlet(np.ones(3), n)
    corners = merged.vertices[merged.triangles[tri]]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    normal *= np.sign(normal @ sun)[:, None]  # lifted towards the sun's side, as for a lit face
    lift = rng.choice([1e-4, 1e-3, 5e-3], n)[:, None]
    points = (np.einsum("nk,nkc->nc", w, corners) + lift * normal).astype(np.float32)
    found = candidates(meshes, points, sun)
    blocked = StaticScene(meshes).occluded(sun_rays(points, sun), np.inf)
    assert np.count_nonzero(blocked) > 0.05 * n
    assert not np.any(blocked & ~found)
    on_ground = tri < len(GROUND.triangles)  # flat open ground: only what else lies near the sun line counts
    assert np.count_nonzero(found[on_ground & ~blocked]) < 0.5 * np.count_nonzero(on_ground & ~blocked)


def _listed(index: SunTiles) -> set[tuple[int, int]]:
    """The (tile code, triangle) pairs an index lists."""
    codes = np.repeat(index.tile_codes, np.diff(index.tile_start))
    return set(zip(codes.tolist(), index.entry_triangle.tolist(), strict=True))


@pytest.mark.parametrize("seed", range(3))
def test_the_maps_of_a_disc_share_one_index_and_draw_the_same_tiles(seed):
    """One index of triangles per tile over the slopes of a whole disc of directions (a superset of each one's own
    list) draws, for every direction, the tiles that direction's own index draws: the same heights, so the same
    candidates. The disc is 5 degrees wide (the sun's is 0.27) so that the lists differ."""
    rng = np.random.default_rng(200 + seed)
    merged = Mesh.concatenate(sloped_world(rng))
    disc = sun_disc(sun_at(rng.uniform(-180, 180), rng.uniform(15, 60)), np.radians(5.0))
    shared = SunTiles(merged.vertices, merged.triangles, np.array([sun_slope(d) for d in disc]))
    points = np.column_stack([rng.uniform(-70, 70, (20_000, 2)), rng.uniform(0.0, 4.0, 20_000)]).astype(np.float32)
    x, y, z = (points[:, k].copy() for k in range(3))
    listed_more = 0
    for direction in disc[::3]:
        own = SunMap(merged.vertices, merged.triangles, direction)
        with_shared = SunMap(merged.vertices, merged.triangles, direction, shared)
        np.testing.assert_array_equal(with_shared.candidates(x, y, z), own.candidates(x, y, z))
        assert with_shared._drawn == own._drawn > 16
        np.testing.assert_array_equal(with_shared._tiles[: own._drawn], own._tiles[: own._drawn])
        listed_more += len(shared.entry_triangle) > len(own._index.entry_triangle)
        own_pairs = _listed(own._index)
        shared_pairs = _listed(shared)
        assert own_pairs <= shared_pairs
    assert listed_more >= 4


def test_a_direction_outside_the_index_is_refused():
    disc = sun_disc(sun_at(40.0, 30.0), np.radians(0.27))
    index = SunTiles(WALL.vertices, WALL.triangles, np.array([sun_slope(d) for d in disc]))
    SunMap(WALL.vertices, WALL.triangles, disc[3], index)
    with pytest.raises(ValueError, match="outside the directions its tile index was built for"):
        SunMap(WALL.vertices, WALL.triangles, sun_at(40.0, 35.0), index)


def test_the_scene_answers_alike_with_and_without_the_disc():
    rng = np.random.default_rng(11)
    meshes = sloped_world(rng)
    disc = sun_disc(sun_at(40.0, 30.0), np.radians(2.0))
    points = np.column_stack([rng.uniform(-70, 70, (8000, 2)), rng.uniform(0.0, 3.0, 8000)]).astype(np.float32)
    alone, grouped = StaticScene(meshes), StaticScene(meshes)
    for direction in disc[:5]:
        cols = [points[:, k].copy() for k in range(3)]
        np.testing.assert_array_equal(grouped.sun_candidates(*cols, direction, disc=disc),
                                      alone.sun_candidates(*cols, direction))
