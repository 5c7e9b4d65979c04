"""Trees that read as trees: a tapering trunk that forks into limbs under an irregular crown, in a few species.

A deciduous crown is LOBES overlapping leafy lobes (icosahedra with jittered vertices, each squashed like the
crown) placed in its envelope, an ellipsoid of semi-axes (along, across, up) = ``radius_m`` (2,) and ``crown_up_m``:
one in the middle, one on top, the rest on a ring around, so its silhouette has lobes; the trunk (a tapered
hexagonal frustum) forks at ``fork_m`` into limbs (tapered pentagonal frusta) that reach into the ring lobes, seen
under the crown. A conifer is a trunk under TIERS stacked cones with jagged, drooping rims. The renderer shades
foliage and bark with smooth normals (pipeline.world.scene SMOOTH_MATERIALS), so a lobe reads as a round clump,
not as a faceted gem; the foliage texture (pipeline.sensors.textures) adds clumps of light and shade.

Species (SPECIES): round (lime, maple), oval (taller than wide: hornbeam, pear), spreading (wide and flat: plane),
conifer (spruce, pine); each with its size ranges and foliage materials. Every crown vertex lies within its
tree's ``radius_m`` (horizontally, in the crown's frame) and below ``height_m``. All draws come from the caller's
generator in a fixed order: one vectorised set per call, whatever the species.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.world.materials import material_index
from pipeline.world.primitives import ICO_FACES, ICO_VERTICES

LOBES = 5
TIERS = 4
TRUNK_SIDES, LIMB_SIDES, RIM_POINTS = 6, 5, 10
LIMB_LOBES = (2, 3, 4)  # the ring lobes the limbs reach into
VERTEX_JITTER = 0.15  # lobe vertices lie at 1 +- this of the lobe's radius
# name: (fork height m, crown radius m, crown height / radius, trunk radius m, foliage materials): (lo, hi) ranges.
SPECIES = {
    "round": ((2.0, 3.2), (2.0, 3.2), (0.9, 1.15), (0.14, 0.24), ("foliage", "foliage_light")),
    "oval": ((1.8, 2.8), (1.4, 2.2), (1.5, 2.0), (0.12, 0.2), ("foliage_light", "foliage")),
    "spreading": ((2.4, 3.4), (2.8, 3.8), (0.6, 0.8), (0.2, 0.3), ("foliage", "foliage")),
    "conifer": ((0.6, 1.2), (1.4, 2.6), (2.4, 3.4), (0.12, 0.2), ("foliage_dark", "foliage_dark")),
}
# Lobes in the crown's unit envelope: (x, y, z) of the centres and the radii, before jitter (the ring of 3 is turned
# per tree). Each lobe, jittered, stays inside the unit sphere: |centre| + radius * (1 + VERTEX_JITTER) <= 1.
_RING = 0.42
_LOBE_R = np.array([0.5, 0.45, 0.5, 0.5, 0.5])
_LOBE_Z = np.array([0.0, 0.45, -0.1, 0.15, -0.2])


_NONE = (np.zeros((0, 3)), np.zeros((0, 3), np.int32), np.zeros(0, np.int32), np.zeros(0, np.int64), np.zeros(0))


@dataclass(frozen=True)
class Trees:
    """Meshes and sizes of N trees.

    Attributes:
        vertices: (V, 3) float64 world; triangles: (T, 3) int32; material: (T,) int32; tree: (V,) int64 the tree of
            each vertex.
        base: (N, 3) float64 foot of the trunk; radius_m: (N,) horizontal reach of the crown from the trunk's axis;
            height_m: (N,) the top above the base; species: (N,) int64 index into SPECIES.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    material: np.ndarray
    tree: np.ndarray
    base: np.ndarray
    radius_m: np.ndarray
    height_m: np.ndarray
    species: np.ndarray


def frusta(p0: np.ndarray, p1: np.ndarray, r0: np.ndarray, r1: np.ndarray, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """Open tapered tubes from p0 (N, 3) of radius r0 (N,) to p1 (N, 3) of radius r1 (N,), ``sides`` faces around.
    Returns (2 sides N, 3) vertices, (2 sides N, 3) triangles facing outwards."""
    axis = p1 - p0
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    ref = np.where(np.abs(axis[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(axis, ref)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(axis, u)
    ang = np.arange(sides) * 2.0 * np.pi / sides
    ring = np.cos(ang)[None, :, None] * u[:, None] + np.sin(ang)[None, :, None] * v[:, None]  # (N, sides, 3)
    verts = np.concatenate([p0[:, None] + r0[:, None, None] * ring, p1[:, None] + r1[:, None, None] * ring], 1)
    i = np.arange(sides)
    j = (i + 1) % sides
    tris = np.concatenate([np.stack([i, j, j + sides], 1), np.stack([i, j + sides, i + sides], 1)])
    return verts.reshape(-1, 3), _instances(tris, len(p0), 2 * sides)


def _instances(tris: np.ndarray, count: int, stride: int) -> np.ndarray:
    return (tris[None] + (np.arange(count) * stride)[:, None, None]).reshape(-1, 3).astype(np.int32)


def _rotate_z(points: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Points (..., 3) turned by yaw (...,) (broadcast) about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([points[..., 0] * c - points[..., 1] * s, points[..., 0] * s + points[..., 1] * c,
                     points[..., 2]], -1)


def grow(base: np.ndarray, species: np.ndarray, rng: np.random.Generator, yaw: np.ndarray | None = None,
         max_across_m: float = np.inf) -> Trees:
    """Trees at ``base`` (N, 3) of ``species`` (N,) (indices into SPECIES). ``yaw`` (N,): the direction of each crown's
    first axis (random if None); ``max_across_m``: the crown's largest half-width across it (a street tree's crown
    stays clear of the façades behind it)."""
    n = len(base)
    table = list(SPECIES.values())
    lo = np.array([[t[k][0] for k in range(4)] for t in table])[species]  # (N, 4)
    hi = np.array([[t[k][1] for k in range(4)] for t in table])[species]
    fork, radius, aspect, trunk_r = (lo + (hi - lo) * rng.random((n, 4))).T
    mats = np.array([[material_index(m) for m in t[4]] for t in table])[species, rng.integers(0, 2, n)]
    yaw = rng.uniform(0.0, np.pi, n) if yaw is None else np.asarray(yaw, np.float64)
    across = np.minimum(radius * rng.uniform(0.8, 1.0, n), max_across_m)
    semi = np.stack([np.minimum(radius, 1.5 * across), across, radius * aspect], 1)  # no crown longer than 1.5:1
    turn = rng.uniform(0.0, 2.0 * np.pi, n)
    lobe_yaw = rng.uniform(0.0, 2.0 * np.pi, (n, LOBES))
    jitter = 1.0 + VERTEX_JITTER * rng.uniform(-1.0, 1.0, (n, LOBES, len(ICO_VERTICES)))
    tier_jitter = rng.uniform(-1.0, 1.0, (n, TIERS, RIM_POINTS))
    conifer = species == list(SPECIES).index("conifer")
    parts = [_deciduous(base[~conifer], fork[~conifer], trunk_r[~conifer], semi[~conifer], yaw[~conifer],
                        turn[~conifer], lobe_yaw[~conifer], jitter[~conifer], mats[~conifer]),
             _conifer(base[conifer], fork[conifer], trunk_r[conifer], semi[conifer], tier_jitter[conifer],
                      mats[conifer])]
    verts, tris, mat, tree, top = [], [], [], [], np.zeros(n)
    count = 0
    for (v, t, m, per_tree, height), which in zip(parts, (np.flatnonzero(~conifer), np.flatnonzero(conifer)),
                                                  strict=True):
        verts.append(v)
        tris.append(t + count)
        mat.append(m)
        tree.append(which[per_tree])
        top[which] = height
        count += len(v)
    return Trees(np.concatenate(verts), np.concatenate(tris).astype(np.int32), np.concatenate(mat).astype(np.int32),
                 np.concatenate(tree), base, np.maximum(semi[:, 0], semi[:, 1]), top, species)


def _deciduous(base, fork, trunk_r, semi, yaw, turn, lobe_yaw, jitter, foliage):
    """Trunk, limbs and lobed crown of n deciduous trees: (vertices, triangles, material, tree per vertex, height)."""
    n = len(base)
    if not n:
        return _NONE
    ring = np.arange(3) * 2.0 * np.pi / 3.0
    unit = np.zeros((n, LOBES, 3))
    unit[:, 2:, 0], unit[:, 2:, 1] = _RING * np.cos(ring + turn[:, None]), _RING * np.sin(ring + turn[:, None])
    unit[:, :, 2] = _LOBE_Z
    centre_z = fork + 0.7 * semi[:, 2]
    crown = base + np.stack([np.zeros(n), np.zeros(n), centre_z], 1)
    lobe_c = crown[:, None] + _rotate_z(unit * semi[:, None], yaw[:, None])  # (n, LOBES, 3)
    local = _rotate_z(ICO_VERTICES[None, None] * jitter[..., None], lobe_yaw[..., None])  # unit lobes, turned
    lobe_v = lobe_c[:, :, None] + _rotate_z(local * _LOBE_R[None, :, None, None] * semi[:, None, None],
                                            yaw[:, None, None])
    lobe_t = _instances(ICO_FACES, n * LOBES, len(ICO_VERTICES))
    fork_p = base + np.stack([np.zeros(n), np.zeros(n), fork], 1)
    trunk_v, trunk_t = frusta(base - [0.0, 0.0, 0.1], fork_p, trunk_r, 0.75 * trunk_r, TRUNK_SIDES)
    ends = lobe_c[:, LIMB_LOBES].reshape(-1, 3)
    k = len(LIMB_LOBES)
    limb_v, limb_t = frusta(np.repeat(fork_p - [0.0, 0.0, 0.05], k, 0), ends, np.repeat(0.5 * trunk_r, k),
                            np.repeat(0.2 * trunk_r, k), LIMB_SIDES)
    bark = material_index("bark")
    verts = np.concatenate([lobe_v.reshape(-1, 3), trunk_v, limb_v])
    tris = np.concatenate([lobe_t, trunk_t + len(lobe_v.reshape(-1, 3)),
                           limb_t + len(lobe_v.reshape(-1, 3)) + len(trunk_v)])
    mat = np.concatenate([np.repeat(foliage, LOBES * len(ICO_FACES)), np.full(len(trunk_t) + len(limb_t), bark)])
    tree = np.concatenate([np.repeat(np.arange(n), LOBES * len(ICO_VERTICES)), np.repeat(np.arange(n), 2 * TRUNK_SIDES),
                           np.repeat(np.arange(n), 2 * LIMB_SIDES * k)])
    return verts, tris, mat, tree, lobe_v[..., 2].reshape(n, -1).max(axis=1) - base[:, 2]


def _conifer(base, fork, trunk_r, semi, tier_jitter, foliage):
    """Trunk and TIERS jagged cones of n conifers (crown height semi[:, 2] above ``fork``; rim radius semi[:, 0] at
    the bottom tier, less above): (vertices, triangles, material, tree per vertex, height)."""
    n = len(base)
    if not n:
        return _NONE
    crown_h = semi[:, 2]
    tier = np.arange(TIERS) / TIERS
    bottom = fork[:, None] + crown_h[:, None] * tier[None] * 0.85  # (n, TIERS) rim heights
    apex = bottom + crown_h[:, None] * (0.45 - 0.1 * tier[None])
    rim_r = semi[:, 0:1] * (1.0 - 0.7 * tier[None])  # (n, TIERS)
    ang = np.arange(RIM_POINTS) * 2.0 * np.pi / RIM_POINTS
    reach = np.where(np.arange(RIM_POINTS) % 2 == 0, 1.0, 0.8) * (1.0 - 0.08 * (tier_jitter + 1.0) / 2.0)
    rim = np.stack([np.cos(ang) * reach, np.sin(ang) * reach, -0.15 * (tier_jitter + 1.0) / 2.0], -1)  # (n, T, R, 3)
    rim = rim * np.stack([rim_r, rim_r, rim_r * 0.6], -1)[:, :, None]
    rim[..., 2] += bottom[:, :, None]
    axis = np.zeros((n, TIERS, 2, 3))
    axis[:, :, 0, 2], axis[:, :, 1, 2] = apex, bottom + 0.12 * (apex - bottom)  # apex, underside centre
    cone = np.concatenate([rim, axis], 2) + base[:, None, None]  # (n, TIERS, RIM_POINTS + 2, 3)
    i = np.arange(RIM_POINTS)
    j = (i + 1) % RIM_POINTS
    tier_t = np.concatenate([np.stack([i, j, np.full(RIM_POINTS, RIM_POINTS)], 1),  # sides up to the apex
                             np.stack([j, i, np.full(RIM_POINTS, RIM_POINTS + 1)], 1)])  # the underside
    cone_t = _instances(tier_t, n * TIERS, RIM_POINTS + 2)
    top = base + np.stack([np.zeros(n), np.zeros(n), bottom[:, 1]], 1)
    trunk_v, trunk_t = frusta(base - [0.0, 0.0, 0.1], top, trunk_r, 0.5 * trunk_r, TRUNK_SIDES)
    cone_v = cone.reshape(-1, 3)
    verts = np.concatenate([cone_v, trunk_v])
    tris = np.concatenate([cone_t, trunk_t + len(cone_v)])
    mat = np.concatenate([np.repeat(foliage, TIERS * len(tier_t)), np.full(len(trunk_t), material_index("bark"))])
    tree = np.concatenate([np.repeat(np.arange(n), TIERS * (RIM_POINTS + 2)), np.repeat(np.arange(n),
                                                                                         2 * TRUNK_SIDES)])
    return verts, tris, mat, tree, apex.max(axis=1)
