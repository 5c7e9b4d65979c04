"""Façades: windows recessed by their stated depth (rays through a pane and through a pier), everything within the
footprint, lit windows in their stated share, deterministic draws, bounded triangle counts."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import SemanticClass
from pipeline.world import facades
from pipeline.world.facades import FLOOR_M, LIT_RATE, OVERHANG_M, SHOP_LIT_RATE, SINK_M, STYLES, layout
from pipeline.world.materials import MATERIAL_NAMES, material_index
from pipeline.world.primitives import PartBuilder
from pipeline.world.scene import StaticScene

GLASS = {material_index(n) for n in ("building_glass", "glass_tinted", "window_lit", "window_blind")}
WALLS = {material_index(n) for n in facades.WALLS}


def footprints(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n rectangles (clockwise seen from above, front first) of 8-20 m by 8-16 m at random places and headings, on
    ground 0-3 m high, on a 60 m grid, and heights of 2-8 floors (as the prop placer draws them)."""
    rng = np.random.default_rng(seed)
    width, depth, yaw = rng.uniform(8.0, 20.0, n), rng.uniform(8.0, 16.0, n), rng.uniform(-np.pi, np.pi, n)
    along = np.stack([np.cos(yaw), np.sin(yaw)], 1)
    out = np.stack([along[:, 1], -along[:, 0]], 1)  # the right of 'along': away from the street
    p0 = rng.uniform(-5.0, 5.0, (n, 2)) + np.stack([np.arange(n) % 20, np.arange(n) // 20], 1) * 60.0 - 300.0
    corners = np.stack([p0, p0 + along * width[:, None], p0 + along * width[:, None] + out * depth[:, None],
                        p0 + out * depth[:, None]], 1)
    z = np.repeat(rng.uniform(0.0, 3.0, n)[:, None, None], 4, 1)
    heights = rng.integers(2, 9, n) * FLOOR_M + rng.uniform(0.0, 1.0, n)
    return np.concatenate([corners, z], 2), heights


def mesh_of(built: facades.Facades):
    part = PartBuilder(SemanticClass.BUILDING)
    built.add_to(part)
    return part.build()


def test_columns_closed_form():
    # Punched: 14 m face, 1.4 m windows 1 m apart, corner piers >= 1 m: (14 - 2 + 1) // 2.4 = 5 windows, centred.
    s0, s1 = facades._columns(14.0, 1.4, 1.0, 1.0, fit=False)
    np.testing.assert_allclose(s1 - s0, 1.4)
    np.testing.assert_allclose(np.diff(s0), 2.4)
    np.testing.assert_allclose([s0[0], 14.0 - s1[-1]], [(14.0 - 5 * 1.4 - 4 * 1.0) / 2] * 2)
    # Bays stretch to fill the face between corner piers: round((10 - 1 + 0.1) / 1.6) = 6 bays of (9 - 0.5) / 6 m.
    s0, s1 = facades._columns(10.0, 1.5, 0.1, 0.5, fit=True)
    np.testing.assert_allclose(s1 - s0, (9.0 - 5 * 0.1) / 6)
    np.testing.assert_allclose([s0[0], s1[-1]], [0.5, 9.5])
    assert len(facades._columns(2.0, 1.4, 1.0, 1.0, fit=False)[0]) == 0  # too short for a window: a blank face


def _front_rays(built: facades.Facades, rects: np.ndarray, b: int, s: float, z: float, distance_m: float):
    """A ray towards the front face of building b at (along s, height z above its base), from distance_m outside."""
    n = np.array([-built.axis[4 * b, 1], built.axis[4 * b, 0]])  # outward: the left of 'along'
    target = rects[b, 0, :2] + built.axis[4 * b] * s
    origin = np.r_[target + n * distance_m, rects[b, 0, 2] + z]
    return np.r_[origin, -n, 0.0].astype(np.float32)


def test_windows_are_recessed_by_their_depth():
    """A ray square onto the front through a pane's centre meets glass at distance + depth; one through the corner
    pier, at the same height, meets the wall at the distance itself."""
    rects, heights = footprints(40)
    built = layout(rects, heights, np.random.default_rng(3))
    scene = StaticScene([mesh_of(built)])
    p = built.panes
    rays, want_t, want_glass = [], [], []
    for b in range(len(rects)):
        front = np.flatnonzero((p["frame"] == 4 * b) & (p["lo"][:, 2] > 5.0))  # above any door or shop sign
        if not len(front):
            continue
        i = front[len(front) // 2]
        z = 0.5 * (p["lo"][i, 2] + p["hi"][i, 2])
        rays.append(_front_rays(built, rects, b, 0.5 * (p["lo"][i, 0] + p["hi"][i, 0]), z, 10.0))
        want_t.append(10.0 + built.depth_m[b])
        want_glass.append(True)
        # The corner pier spans [0, the first column's left edge], which is at least 0.16 m and within 6 cm of the
        # first pane's left edge.
        rays.append(_front_rays(built, rects, b, 0.5 * p["lo"][front, 0].min(), z, 10.0))
        want_t.append(10.0)
        want_glass.append(False)
    assert len(rays) > 30
    t, prim, _ = scene.cast(np.array(rays))
    np.testing.assert_allclose(t, want_t, atol=2e-4)
    material = scene.triangle_material[prim]
    want_glass = np.array(want_glass)
    assert all(m in GLASS for m in material[want_glass])
    assert all(m in WALLS for m in material[~want_glass])
    assert {STYLES[s] for s in built.style} == set(STYLES)  # every style was tried


def test_building_stays_within_its_footprint():
    """Every vertex lies within the footprint grown by the cornice's overhang, between the sunk base and the top
    (a shop floor raises it by at most 1.3 m)."""
    rects, heights = footprints(30, seed=1)
    rng = np.random.default_rng(0)
    eps = 1e-9
    for b in range(len(rects)):
        built = layout(rects[b:b + 1], heights[b:b + 1], rng)
        mesh = mesh_of(built)
        axis = built.axis[0]
        rel = mesh.vertices[:, :2] - rects[b, 0, :2]
        s, q = rel @ axis, rel @ np.array([-axis[1], axis[0]])
        width, depth = (np.linalg.norm(rects[b, k, :2] - rects[b, 0, :2]) for k in (1, 3))
        assert s.min() >= -OVERHANG_M - eps and s.max() <= width + OVERHANG_M + eps
        assert q.min() >= -depth - OVERHANG_M - eps and q.max() <= OVERHANG_M + eps
        z = mesh.vertices[:, 2] - rects[b, 0, 2]
        assert z.min() >= -SINK_M - eps and z.max() <= heights[b] + 1.3 + eps


def test_lit_windows_share_and_spread():
    """Over many buildings the lit share is near its expectation (the mean of LIT_RATE, more in shops), and it varies
    from building to building (some dark, some bright)."""
    rects, heights = footprints(300, seed=2)
    p = layout(rects, heights, np.random.default_rng(1)).panes
    shop = p["shop"]
    expected = np.mean(LIT_RATE) * (~shop).mean() + SHOP_LIT_RATE * shop.mean()
    assert len(p["lit"]) > 20_000
    assert 0.2 <= p["lit"].mean() <= 0.35
    assert abs(p["lit"].mean() - expected) < 0.02
    per_building = np.bincount(p["frame"] // 4, p["lit"] & ~shop) / np.maximum(np.bincount(p["frame"] // 4, ~shop), 1)
    assert per_building.min() < 0.15 and per_building.max() > 0.38
    assert 0.15 < (p["blind"] > 0).mean() < 0.4 and (p["blind"][shop] == 0).all()


def test_deterministic_and_seeded():
    rects, heights = footprints(12, seed=4)
    a, b = (mesh_of(layout(rects, heights, np.random.default_rng(9))) for _ in range(2))
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    np.testing.assert_array_equal(a.material, b.material)
    c = mesh_of(layout(rects, heights, np.random.default_rng(10)))
    assert len(c) != len(a) or not np.array_equal(c.vertices, a.vertices)


def test_triangle_counts_and_materials():
    """About 500 triangles for an average town building (14 x 12 m, 5 floors), never more than 1500 for the
    largest (20 x 16 m, 8 floors); panes face outwards; walls come in more than three colours."""
    rects, heights = footprints(200, seed=5)
    built = layout(rects, heights, np.random.default_rng(2))
    mesh = mesh_of(built)
    per_building = len(mesh) / len(rects)
    assert 300 < per_building < 800
    big, _ = footprints(1, seed=6)
    big[0, 1, :2] = big[0, 0, :2] + (big[0, 1, :2] - big[0, 0, :2]) / np.linalg.norm(big[0, 1, :2] - big[0, 0, :2]) * 20
    assert len(mesh_of(layout(big, np.array([8 * FLOOR_M + 0.9]), np.random.default_rng(0)))) < 1500
    names = {MATERIAL_NAMES[m] for m in np.unique(mesh.material)}
    assert len(names & set(facades.WALLS)) >= 6
    glass = np.isin(mesh.material, list(GLASS))
    v = mesh.vertices[mesh.triangles[glass]]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    centre = v.mean(axis=1)
    nearest = np.argmin(np.linalg.norm(centre[:, None, :2] - rects[None, :, :, :2].mean(axis=2), axis=2), axis=1)
    outward = centre[:, :2] - rects[nearest, :, :2].mean(axis=1)
    assert (np.einsum("ij,ij->i", normal[:, :2], outward) > 0).all()


def test_counter_clockwise_footprints_are_refused():
    rects, heights = footprints(2)
    with pytest.raises(ValueError, match="clockwise"):
        layout(rects[:, ::-1], heights, np.random.default_rng(0))
