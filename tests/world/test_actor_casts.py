"""Actors as their class's canonical mesh under an affine map: candidate pairs against a brute-force slab test,
the nearest hit and its world normal in closed form, and shadow segments through actors."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actor_casts import (
    BOX_MARGIN,
    _unit_box_entry,
    actor_grid,
    actor_pairs,
    cell_lists,
    grid_actor_pairs,
    nearest_actor_hits,
    origin_actor_pairs,
    origin_bins,
    origin_lists,
    shared_origin,
)
from pipeline.world.actors import Actors, unit_to_world
from pipeline.world.scene import FrameScene, StaticScene


def _boxes(rng: np.random.Generator, n: int) -> Boxes3D:
    return Boxes3D(rng.uniform(-20, 20, (n, 3)), rng.uniform(0.5, 12.0, (n, 3)), rng.uniform(-np.pi, np.pi, n))


def _slab_pairs(rays: np.ndarray, affine: np.ndarray) -> set[tuple[int, int]]:
    """Every (ray, actor) whose ray, mapped into the actor's unit frame, meets [-0.5 - m, 0.5 + m]^3 at t >= 0."""
    pairs = set()
    half = 0.5 + BOX_MARGIN
    for a, m in enumerate(affine):
        inv = np.linalg.inv(m[:, :3])
        o = (rays[:, :3].astype(np.float64) - m[:, 3]) @ inv.T
        d = rays[:, 3:].astype(np.float64) @ inv.T
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = (-half - o) / d, (half - o) / d
        t_in = np.where(d == 0, np.where(np.abs(o) <= half, -np.inf, np.inf), np.minimum(t0, t1)).max(axis=1)
        t_out = np.where(d == 0, np.where(np.abs(o) <= half, np.inf, -np.inf), np.maximum(t0, t1)).min(axis=1)
        pairs |= {(int(i), a) for i in np.flatnonzero((t_in <= t_out) & (t_out >= 0))}
    return pairs


@pytest.mark.parametrize("length", [1.0, 0.05, 30.0])  # unit directions, and segments (shadow rays to a lamp)
def test_pairs_are_every_ray_that_meets_a_box(length):
    rng = np.random.default_rng(int(length * 100))
    boxes = _boxes(rng, 25)
    affine = unit_to_world(boxes)
    d = rng.normal(size=(4000, 3))
    d *= length / np.linalg.norm(d, axis=1, keepdims=True)
    origins = np.concatenate([rng.uniform(-30, 30, (3000, 3)), np.repeat(boxes.center[:5], 200, axis=0)])  # some
    rays = np.concatenate([origins, d], axis=1).astype(np.float32)  # inside a box; rays sharing an origin
    radius = 0.5 * np.linalg.norm(boxes.size, axis=1) * (1 + 2 * BOX_MARGIN) + 1e-6
    rows = np.arange(0, 4000, 2)  # every other ray
    pair_row, pair_actor, local = actor_pairs(rays, rows, np.arange(25), np.ascontiguousarray(
        np.linalg.inv(affine[:, :, :3])), np.ascontiguousarray(affine[:, :, 3]), radius)
    meets = _slab_pairs(rays, affine)
    expected = {(j, a) for j, i in enumerate(rows) for a in range(25) if (int(i), a) in meets}
    assert set(zip(pair_row.tolist(), pair_actor.tolist(), strict=True)) == expected
    assert len(expected) > 100
    assert np.all(np.diff(pair_row) >= 0)  # ordered by row
    for p in range(0, len(pair_row), 37):  # the unit-frame ray maps back to the world ray
        m = affine[pair_actor[p]]
        np.testing.assert_allclose(m[:, :3] @ local[p, :3] + m[:, 3], rays[rows[pair_row[p]], :3], atol=1e-3)
        np.testing.assert_allclose(m[:, :3] @ local[p, 3:], rays[rows[pair_row[p]], 3:], rtol=1e-5, atol=1e-6)


def test_nearest_hit_wins_and_normals_map_by_the_inverse_transpose():
    # Actor 0: a 4 x 2 x 1 box turned 90 deg: its unit-frame +x face (normal (1, 0, 0)) faces world +y.
    affine = unit_to_world(Boxes3D([[0.0, 0.0, 0.0], [0.0, 10.0, 0.0]], [[4.0, 2.0, 1.0], [1.0, 1.0, 1.0]],
                                   [np.pi / 2, 0.0]))
    inv = np.ascontiguousarray(np.linalg.inv(affine[:, :, :3]))
    # Rows 0 and 1 have two pairs each; row 2 one pair that missed.
    t, prim, normal, actor = nearest_actor_hits(
        3, np.array([0, 0, 1, 1, 2]), np.array([1, 0, 0, 1, 1]), np.float32([9.0, 7.5, 2.0, 3.0, np.inf]),
        np.uint32([11, 12, 13, 14, 15]),
        np.float32([[0, 0, 1], [1, 0, 0], [0.6, 0.8, 0], [0, 1, 0], [0, 0, 0]]), inv)
    assert t.tolist() == [7.5, 2.0, np.inf] and prim.tolist()[:2] == [12, 13] and actor.tolist()[:2] == [0, 0]
    np.testing.assert_allclose(normal[0], [0, 1, 0], atol=1e-7)
    # (0.6, 0.8, 0) in the unit frame: A^-T scales by 1/size (1/4, 1/2), then turns 90 deg: (-0.4, 0.15) normalised.
    np.testing.assert_allclose(normal[1], np.array([-0.4, 0.15, 0.0]) / np.hypot(0.4, 0.15), atol=1e-6)
    assert not normal[2].any()


def test_shadow_segments_through_and_beside_an_actor():
    car = Actors([5], [ObjectClass.CAR], Boxes3D([[10.0, 0.0, 0.75]], [[4.5, 1.8, 1.5]], [0.3]), [[0.5, 0.5, 0.5]])
    scene = FrameScene(StaticScene([]), car, threads=1)
    origins = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 0.5], [0.0, 5.0, 0.5]])
    lamps = np.array([[20.0, 0.0, 0.5], [5.0, 0.0, 0.5], [20.0, 5.0, 0.5]])  # through; short of it; beside it
    rays = np.concatenate([origins, lamps - origins], axis=1).astype(np.float32)  # segments: t in [0, 1]
    assert scene.occluded_rays(rays, 1.0).tolist() == [True, False, False]
    assert scene.occluded_rays(rays, 1.0, actor_rays=np.array([True, True, True])).tolist() == [True, False, False]


def _box_entry(rays: np.ndarray, affine: np.ndarray, rows: np.ndarray, actor: np.ndarray) -> np.ndarray:
    """(P,) float64 t >= 0 at which each ray rows[p] enters actor[p]'s grown unit box (brute force, float64)."""
    half = 0.5 + BOX_MARGIN
    m = affine[actor]
    inv = np.linalg.inv(m[:, :, :3])
    o = np.einsum("pij,pj->pi", inv, rays[rows, :3].astype(np.float64) - m[:, :, 3])
    d = np.einsum("pij,pj->pi", inv, rays[rows, 3:].astype(np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (-half - o) / d, (half - o) / d
    return np.maximum(np.where(d == 0, -np.inf, np.minimum(t0, t1)).max(axis=1), 0.0)


@pytest.mark.parametrize("spread_m", [40.0, 600.0])  # one cell's worth of actors; a grid of many cells
@pytest.mark.parametrize("near_m", [0.0, 100.0])  # each ray walks its cells; limited ones take their origin's reach
def test_grid_pairs_are_actor_pairs(spread_m, near_m):
    """grid_actor_pairs against actor_pairs: without a limit, the same arrays (pairs, order, unit-frame rays); with
    a limit per ray, exactly the pairs whose box the ray enters by the limit, and none entered beyond its margin,
    whether the rays walk the grid's cells or (``near_m``) take the actors within their reach of the origin."""
    rng = np.random.default_rng(int(spread_m))
    n = 300
    centre = np.column_stack([rng.uniform(-spread_m, spread_m, (n, 2)), rng.uniform(0.0, 2.0, n)])
    boxes = Boxes3D(centre, rng.uniform(0.5, 12.0, (n, 3)), rng.uniform(-np.pi, np.pi, n))
    affine = unit_to_world(boxes)
    inv, c = np.ascontiguousarray(np.linalg.inv(affine[:, :, :3])), np.ascontiguousarray(affine[:, :, 3])
    radius = 0.5 * np.linalg.norm(boxes.size, axis=1) * (1 + 2 * BOX_MARGIN) + 1e-6
    d = rng.normal(size=(6000, 3))
    d[:2000, 2] *= 0.05  # near-horizontal rays cross many cells
    d[2000:2100, :2] = 0.0  # vertical ones a single cell
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    origins = np.concatenate([rng.uniform(-spread_m, spread_m, (3000, 3)) * [1, 1, 0.01],
                              np.repeat(centre[:6], 500, axis=0)])  # some inside actors, sharing origins
    rays = np.concatenate([origins, d], axis=1).astype(np.float32)
    rows, actors = np.arange(0, 6000, 2), np.sort(rng.choice(n, 250, replace=False))
    grid = actor_grid(c, radius, actors)
    full = actor_pairs(rays, rows, actors, inv, c, radius)
    unlimited = grid_actor_pairs(rays, rows, actors, inv, c, radius, np.full(len(rows), np.inf), *grid, near_m)
    assert len(full[0]) > 500
    for a, b in zip(full, unlimited, strict=True):
        np.testing.assert_array_equal(a, b)
    limit = rng.uniform(0.0, 30.0, len(rows))
    pair_row, pair_actor, _ = grid_actor_pairs(rays, rows, actors, inv, c, radius, limit, *grid, near_m)
    entry = _box_entry(rays, affine, rows[full[0]], full[1])
    within = entry <= limit[full[0]]
    beyond = entry > limit[full[0]] * 1.001 + 0.01
    kept = np.isin(np.arange(len(full[0])), np.flatnonzero(~beyond)) & ~within
    assert within.sum() > 100 and beyond.sum() > 100
    got = set(zip(pair_row.tolist(), pair_actor.tolist(), strict=True))
    assert {(int(r), int(a)) for r, a in zip(full[0][within], full[1][within], strict=True)} <= got
    assert got <= {(int(r), int(a)) for r, a in zip(full[0][within | kept], full[1][within | kept], strict=True)}
    assert np.all(np.diff(pair_row) >= 0)


@pytest.mark.parametrize("step_deg", [0.5, 1.0, 4.0])
def test_rays_from_one_origin_take_the_pairs_of_the_grid_from_their_direction_bin(step_deg):
    """origin_actor_pairs (the actors listed for a ray's direction bin) against grid_actor_pairs (the actors of the
    grid cells it crosses): the same arrays, with and without a limit per ray, for rays from one origin in every
    direction (straight up and down, along the azimuth's seam at +-180 deg), of unit and other lengths, among
    actors all around, above the origin, at the seam, and about the origin itself."""
    rng = np.random.default_rng(int(step_deg * 10))
    n = 300
    centre = np.column_stack([rng.uniform(-150.0, 150.0, (n, 2)), rng.uniform(0.0, 3.0, n)])
    centre[:4] = [[0.5, 0.2, 1.0], [0.0, 0.0, 9.0], [0.0, 0.0, -8.0], [-30.0, 0.0, 1.0]]  # about, above, below, seam
    size = rng.uniform(0.5, 12.0, (n, 3))
    size[:4] = [[4.5, 1.8, 1.5], [2.0, 2.0, 1.0], [2.0, 2.0, 1.0], [4.5, 1.8, 1.5]]
    boxes = Boxes3D(centre, size, rng.uniform(-np.pi, np.pi, n))
    affine = unit_to_world(boxes)
    inv, c = np.ascontiguousarray(np.linalg.inv(affine[:, :, :3])), np.ascontiguousarray(affine[:, :, 3])
    radius = 0.5 * np.linalg.norm(boxes.size, axis=1) * (1 + 2 * BOX_MARGIN) + 1e-6
    d = rng.normal(size=(20000, 3))
    d[:5000, 2] *= 0.05  # near the horizon, as a camera's and a LiDAR's
    d[5000:5100, :2] = 0.0  # straight up or down
    d[5100:5600, 1] *= 1e-4  # along the seam, on both sides
    d[5100:5600, 0] = -np.abs(d[5100:5600, 0])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[10000:] *= rng.uniform(0.2, 5.0, (10000, 1))  # segments
    rays = np.column_stack([np.tile([0.2, -0.1, 1.3], (len(d), 1)), d]).astype(np.float32)
    rows, actors = np.arange(0, len(d), 2), np.sort(rng.choice(n, 250, replace=False))
    actors[:4] = np.arange(4)
    actors = np.sort(np.unique(actors))
    grid = actor_grid(c, radius, actors)
    step = float(np.deg2rad(step_deg))
    lists = origin_lists(0.2, -0.1, 1.3, actors, c, radius, step, *origin_bins(step))
    for limit in (np.full(len(rows), np.inf), rng.uniform(0.0, 60.0, len(rows))):
        walked = grid_actor_pairs(rays, rows, actors, inv, c, radius, limit, *grid, 0.0)
        binned = origin_actor_pairs(rays, rows, actors, inv, c, radius, limit, step, *origin_bins(step), *lists,
                                    np.full(3, np.nan))
        assert len(walked[0]) > 2000 and {0, 1, 2, 3} <= set(walked[1].tolist())
        for a, b in zip(walked, binned, strict=True):
            np.testing.assert_array_equal(a, b)
    start, item = lists
    assert np.count_nonzero(item == 0) == len(start) - 1  # the actor about the origin: every bin
    _, n_az = origin_bins(step)
    above, cone = np.count_nonzero(item == 1), np.arcsin(radius[1] / np.linalg.norm(c[1] - [0.2, -0.1, 1.3]))
    assert above % n_az == 0 and above // n_az <= 2 * cone / step + 3  # the one above: every azimuth, its rows
    assert shared_origin(rays, rows) and not shared_origin(rays, np.zeros(0, np.int64))
    moved = rays.copy()
    moved[rows[-1], 2] += np.float32(1e-3)
    assert not shared_origin(moved, rows)


def _cars_scene(rng: np.random.Generator, n: int, half_x_m: float, half_y_m: float) -> tuple[Boxes3D, FrameScene]:
    """``n`` cars at random places within +-half_x_m, +-half_y_m and headings on the ground, and a frame scene of them
    alone (one thread)."""
    centre = np.column_stack([rng.uniform(-half_x_m, half_x_m, n), rng.uniform(-half_y_m, half_y_m, n),
                              np.full(n, 0.75)])
    boxes = Boxes3D(centre, np.tile([[4.5, 1.8, 1.5]], (n, 1)), rng.uniform(-np.pi, np.pi, n))
    cars = Actors(np.arange(1, n + 1), [ObjectClass.CAR] * n, boxes, np.full((n, 3), 0.5))
    return boxes, FrameScene(StaticScene([]), cars, threads=1)


def test_a_frame_scene_gives_rays_from_one_origin_the_grid_pairs():
    """FrameScene._pairs takes the direction bins for many rays from one origin (a camera's): the same pairs."""
    rng = np.random.default_rng(5)
    _, scene = _cars_scene(rng, 40, 60.0, 8.0)
    d = rng.normal(size=(5000, 3)) * [1.0, 1.0, 0.1]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rays = np.column_stack([np.tile([0.0, 0.0, 1.2], (len(d), 1)), d]).astype(np.float32)
    sub, limit = np.arange(len(d)), rng.uniform(0.0, 80.0, len(d))
    got = scene._pairs(rays, sub, limit)
    assert len(scene._origin_lists) == 1
    expected = grid_actor_pairs(rays, sub, scene._placed, scene._inv_linear, scene._center, scene._radius, limit,
                                *actor_grid(scene._center, scene._radius, scene._placed), 0.0)
    assert len(expected[0]) > 200
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("lamp", [(3.0, 1.0, 6.5), (0.0, 0.0, 1.0)])  # a street lamp; a headlamp among the cars
def test_segments_towards_a_lamp_take_the_pairs_of_bins_about_it(lamp):
    """Shadow segments towards one lamp (from points on and about cars, 2 mm off the surface, stopping 5 cm short of
    the lamp) find their actors in the direction bins about the lamp (``toward``): every pair the grid's walk finds,
    none it could not (each entered by the limit and its margin), and the same occlusion by real Embree tests."""
    rng = np.random.default_rng(11)
    n = 60
    boxes, scene = _cars_scene(rng, n, 30.0, 10.0)
    points = np.concatenate([boxes.center[rng.integers(0, n, 3000)] + rng.normal(0, [2.0, 1.0, 0.8], (3000, 3)),
                             rng.uniform([-35, -12, 0], [35, 12, 2], (3000, 3))])
    normal = rng.normal(size=points.shape)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    lamp = np.array(lamp)
    v = lamp - points
    start = points + normal * 2e-3
    seg = v * (1.0 - 0.05 / np.linalg.norm(v, axis=1))[:, None]
    rays = np.concatenate([start, seg], axis=1).astype(np.float32)
    sub, limit = np.arange(len(rays)), np.ones(len(rays))
    walked = scene._pairs(rays, sub, limit, near=True)
    binned = scene._pairs(rays, sub, limit, near=True, toward=(lamp, 0.1))
    assert any(key[0] == "toward" for key in scene._origin_lists)
    walked_set = set(zip(walked[0].tolist(), walked[1].tolist(), strict=True))
    binned_set = set(zip(binned[0].tolist(), binned[1].tolist(), strict=True))
    assert len(walked_set) > 500 and walked_set <= binned_set
    local = {(r, a): i for i, (r, a) in enumerate(zip(binned[0].tolist(), binned[1].tolist(), strict=True))}
    entry = np.array([_unit_box_entry(binned[2][local[p]], 0.5 + BOX_MARGIN) for p in binned_set - walked_set])
    assert np.all(entry <= 1.001 + 0.01)  # extra pairs only between the limit and its margin
    blocked = scene.occluded_rays(rays, 1.0)
    assert 300 < blocked.sum() < len(rays) - 300
    np.testing.assert_array_equal(scene.occluded_rays(rays, 1.0, toward=(lamp, 0.1)), blocked)


def test_cell_lists_clip_spans_and_keep_items_ascending():
    start, item = cell_lists(2, 3, np.array([[-5, 9, 1, 2], [1, 2, 0, 3], [0, 0, 0, 3]]))  # the last is empty
    cells = [item[start[c]:start[c + 1]].tolist() for c in range(6)]
    assert cells == [[], [0], [], [1], [0, 1], [1]]


def test_short_segments_see_only_actors_in_reach_and_block_as_a_brute_force_cast():
    """occluded_rays with a finite t_max (the grid of actors in reach) against each actor cast alone."""
    rng = np.random.default_rng(9)
    n = 12
    boxes = Boxes3D(np.column_stack([rng.uniform(-40, 40, n), rng.uniform(-8, 8, n), np.full(n, 0.75)]),
                    np.tile([[4.5, 1.8, 1.5]], (n, 1)), rng.uniform(-np.pi, np.pi, n))
    cars = Actors(np.arange(1, n + 1), [ObjectClass.CAR] * n, boxes, np.full((n, 3), 0.5))
    scene = FrameScene(StaticScene([]), cars, threads=1)
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    # Some alone, some 8 from one origin near a car (as a pixel's sky-occlusion rays: its reach found once).
    origins = np.concatenate([rng.uniform([-45, -10, 0], [45, 10, 2], (3000, 3)),
                              np.repeat(boxes.center[rng.integers(0, n, 125)] + rng.normal(0, 2.0, (125, 3)), 8, 0)])
    rays = np.concatenate([origins, d], axis=1).astype(np.float32)
    for t_max in (0.5, 1.5, 6.0):
        expected = np.zeros(len(rays), bool)
        for a in range(n):
            hit, t = scene.cast_alone_rays(rays, np.full(len(rays), a))
            expected |= hit & (t <= t_max)
        got = scene.occluded_rays(rays, t_max)
        assert 20 < expected.sum() < len(rays) - 20
        np.testing.assert_array_equal(got, expected)
