"""Trees: crowns within their declared reach, trunks that taper and fork, exact triangle counts, determinism."""

from __future__ import annotations

import numpy as np

from pipeline.world import trees
from pipeline.world.materials import material_index
from pipeline.world.trees import LIMB_SIDES, LOBES, SPECIES, TIERS, TRUNK_SIDES, grow

CONIFER = list(SPECIES).index("conifer")
BARK = material_index("bark")


def forest(n: int = 400, seed: int = 0, **kwargs) -> trees.Trees:
    rng = np.random.default_rng(seed)
    base = np.column_stack([rng.uniform(-300, 300, (n, 2)), rng.uniform(0.0, 5.0, n)])
    return grow(base, rng.integers(0, len(SPECIES), n), rng, **kwargs)


def test_crowns_stay_within_their_reach_and_height():
    t = forest()
    rel = t.vertices - t.base[t.tree]
    reach = np.linalg.norm(rel[:, :2], axis=1)
    assert (reach <= t.radius_m[t.tree] + 1e-9).all()
    assert (rel[:, 2] <= t.height_m[t.tree] + 1e-9).all() and (rel[:, 2] >= -0.1 - 1e-9).all()
    # ... and fill most of it: each tree reaches at least 70 % of its radius (its three ring lobes need not lie on
    # its long axis) and its full height.
    widest = np.zeros(len(t.base))
    np.maximum.at(widest, t.tree, reach)
    assert (widest >= 0.7 * t.radius_m).all()
    top = np.full(len(t.base), -np.inf)
    np.maximum.at(top, t.tree, rel[:, 2])
    np.testing.assert_allclose(top, t.height_m)
    lo = np.array([SPECIES[name][1][0] for name in SPECIES])[t.species]
    assert (t.radius_m >= 0.8 * lo).all()  # the across axis is at least 0.8 of the along one


def test_street_crowns_stay_narrow_across_the_street():
    """With a heading and ``max_across_m``, no crown vertex lies farther than that across the heading, and no crown
    is longer than 1.5 times its width."""
    rng = np.random.default_rng(3)
    n = 200
    base = np.column_stack([rng.uniform(-100, 100, (n, 2)), np.zeros(n)])
    yaw = rng.uniform(-np.pi, np.pi, n)
    t = grow(base, rng.integers(0, 3, n), rng, yaw=yaw, max_across_m=1.7)
    rel = t.vertices - t.base[t.tree]
    across = -rel[:, 0] * np.sin(yaw[t.tree]) + rel[:, 1] * np.cos(yaw[t.tree])
    assert np.abs(across).max() <= 1.7 + 1e-9
    assert (t.radius_m <= 1.5 * 1.7 + 1e-9).all()


def test_trunks_taper_and_fork_into_limbs_under_the_crown():
    """A deciduous tree's bark is its trunk (a foot ring 10 cm below the ground, a ring 0.75 times as wide at the
    fork, 1.8 m up or more) and three limbs from the fork (half the trunk's width) up and out into the crown."""
    t = forest(50, seed=1)
    bark_tris = t.triangles[t.material == BARK]
    first = t.tree[bark_tris[:, 0]]
    for i in np.flatnonzero(t.species != CONIFER)[:10]:
        v = t.vertices[np.unique(bark_tris[first == i])] - t.base[i]  # trunk (2 rings), then the limbs (2 rings each)
        assert len(v) == 2 * TRUNK_SIDES + 3 * 2 * LIMB_SIDES
        r = np.linalg.norm(v[:, :2], axis=1)
        foot, fork = r[:TRUNK_SIDES], r[TRUNK_SIDES:2 * TRUNK_SIDES]
        np.testing.assert_allclose(v[:TRUNK_SIDES, 2], -0.1)
        assert v[TRUNK_SIDES, 2] >= 1.8
        np.testing.assert_allclose(fork, 0.75 * foot, rtol=1e-9)
        limbs = v[2 * TRUNK_SIDES:].reshape(3, 2, LIMB_SIDES, 3)
        np.testing.assert_allclose(limbs[:, 0, :, 2].mean(axis=1), v[TRUNK_SIDES, 2] - 0.05, atol=1e-9)
        tips = limbs[:, 1].mean(axis=1)
        assert (tips[:, 2] > v[TRUNK_SIDES, 2]).all()
        np.testing.assert_allclose(np.linalg.norm(tips[:, :2], axis=1) / t.radius_m[i], 0.42, atol=0.12)


def test_triangle_counts_per_species():
    """A deciduous tree is LOBES icosahedra, a trunk and three limbs; a conifer TIERS cones of 2 x 10 triangles and
    a trunk: so 142 and 92 triangles."""
    t = forest(300, seed=2)
    conifer = t.species == CONIFER
    per_deciduous = LOBES * 20 + 2 * TRUNK_SIDES + 3 * 2 * LIMB_SIDES
    per_conifer = TIERS * 2 * trees.RIM_POINTS + 2 * TRUNK_SIDES
    assert (per_deciduous, per_conifer) == (142, 92)
    assert len(t.triangles) == per_deciduous * (~conifer).sum() + per_conifer * conifer.sum()
    counts = np.bincount(t.tree[t.triangles[:, 0]], minlength=len(t.base))
    assert set(counts[conifer]) == {per_conifer} and set(counts[~conifer]) == {per_deciduous}


def test_closed_lobes_face_outwards():
    """Every crown lobe is a closed surface whose triangles face away from its centre."""
    t = forest(20, seed=4, yaw=np.zeros(20))
    foliage = np.flatnonzero(t.material != BARK)
    v = t.vertices[t.triangles[foliage]]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    species = t.species[t.tree[t.triangles[foliage, 0]]]
    lobes = v[species != CONIFER].reshape(-1, 20, 3, 3)  # 20 triangles per lobe
    centre = lobes.reshape(len(lobes), -1, 3).mean(axis=1)
    out = lobes.mean(axis=2) - centre[:, None]
    assert (np.einsum("lti,lti->lt", normal[species != CONIFER].reshape(-1, 20, 3), out) > 0).all()


def test_deterministic():
    a, b = forest(seed=7), forest(seed=7)
    for name in ("vertices", "triangles", "material", "tree", "radius_m", "height_m"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(forest(seed=8).vertices[:100], a.vertices[:100])


def test_no_trees():
    t = grow(np.zeros((0, 3)), np.zeros(0, np.int64), np.random.default_rng(0))
    assert len(t.vertices) == 0 and len(t.triangles) == 0
