"""Smooth shading normals for curved actor bodies: per-corner normals, interpolated at each hit.

A lofted body is a few thousand flat triangles; shaded with each triangle's own normal it shows its facets, and a
car's highlights and reflections, which should trace its curvature, break into bands. Each triangle corner gets the
area-weighted mean normal of the triangles around its vertex whose normals lie within ``CREASE_DEG`` of its own
(a crease, such as a wheel's tread meeting its sidewall or a box's edge, stays sharp), and a hit's shading normal
is the corners' normals weighted by its barycentric coordinates (Phong's interpolation).

Normals are computed in the model's metric frame (its unit-box mesh scaled back by its extent, so a crease is
judged on the real shape) and returned in the unit-box frame, where the renderer casts (a normal maps by the
inverse transpose: n_unit ~ n_metric * extent). Where the interpolated normal and the triangle's own face opposite
sides of the ray (at silhouettes), the triangle's own normal is kept, so a normal never faces away from the viewer
on a surface that faces it.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.jit import kernel

CREASE_DEG = 35.0


def corner_normals(vertices: np.ndarray, triangles: np.ndarray, extent: np.ndarray,
                   crease_deg: float = CREASE_DEG) -> np.ndarray:
    """(T, 3, 3) float32 unit normals per triangle corner, unit-box frame, oriented like each triangle's winding.

    Args:
        vertices: (V, 3) unit-box vertices; triangles: (T, 3) indices; extent: (3,) the model's metric size (the
            factors the unit box was scaled by).
    """
    extent = np.asarray(extent, np.float64)
    metric = np.asarray(vertices, np.float64) * extent
    tris = np.asarray(triangles, np.int64)
    a, b, c = (metric[tris[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)  # area-weighted
    length = np.linalg.norm(face, axis=1)
    unit = face / np.where(length > 0, length, 1.0)[:, None]
    # The corners grouped by vertex (sorted by vertex, stably); each corner sums the faces of its group's corners on
    # its side of the crease.
    corner_vertex = tris.reshape(-1)
    corner_tri = np.repeat(np.arange(len(tris)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    starts = np.r_[np.flatnonzero(np.r_[True, np.diff(corner_vertex[order]) != 0]), len(order)].astype(np.int64)
    summed = _same_side_sums(np.ascontiguousarray(face), np.ascontiguousarray(unit), corner_tri[order],
                             starts, float(np.cos(np.radians(crease_deg))))
    normal_metric = np.empty((len(order), 3))
    normal_metric[order] = summed
    normal_metric = normal_metric.reshape(-1, 3, 3)
    # Degenerate sums (no area around the corner) fall back to the face's own normal.
    degenerate = np.linalg.norm(normal_metric, axis=2) <= 0
    normal_metric[degenerate] = np.repeat(unit, 3, axis=0).reshape(-1, 3, 3)[degenerate]
    normal_unit = normal_metric * extent
    return (normal_unit / np.linalg.norm(normal_unit, axis=2, keepdims=True)).astype(np.float32)


def interpolate(corner: np.ndarray, uv: np.ndarray, face_normal: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(K, 3) float32 shading normals of K hits: corner normals (K, 3, 3) weighted by the barycentric (u, v) (K, 2)
    (Embree's: the hit is (1 - u - v) p0 + u p1 + v p2), normalised; the triangle's own ``face_normal`` (K, 3)
    where the two face opposite sides of the ray ``directions`` (K, 3)."""
    u, v = uv[:, 0:1], uv[:, 1:2]
    n = (1.0 - u - v) * corner[:, 0] + u * corner[:, 1] + v * corner[:, 2]
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), np.float32(1e-12))
    flipped = np.einsum("ij,ij->i", n, directions) * np.einsum("ij,ij->i", face_normal, directions) < 0
    n[flipped] = face_normal[flipped]
    return n.astype(np.float32)


@kernel("float32[:, ::1](float32[:, :, ::1], int64[::1], float32[:, ::1], float32[:, ::1], float32[:, ::1])")
def interpolated(corners, rows, uv, face_normal, directions):
    """:func:`interpolate` of the corner normals ``corners[rows]`` ((T, 3, 3) float32 table, (K,) int64 rows) in one
    compiled pass, without the (K, 3, 3) gather: the same float32 operations in the same order, so the same bits
    (the renderer's hot path: every actor cast, per model)."""
    k = rows.size
    out = np.empty((k, 3), np.float32)
    one, tiny = np.float32(1.0), np.float32(1e-12)
    for i in range(k):
        c = corners[rows[i]]
        u, v = uv[i, 0], uv[i, 1]
        w = one - u - v
        n0 = w * c[0, 0] + u * c[1, 0] + v * c[2, 0]
        n1 = w * c[0, 1] + u * c[1, 1] + v * c[2, 1]
        n2 = w * c[0, 2] + u * c[1, 2] + v * c[2, 2]
        norm = max(np.sqrt(n0 * n0 + n1 * n1 + n2 * n2), tiny)
        n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
        d0, d1, d2 = directions[i, 0], directions[i, 1], directions[i, 2]
        f0, f1, f2 = face_normal[i, 0], face_normal[i, 1], face_normal[i, 2]
        if (n0 * d0 + n1 * d1 + n2 * d2) * (f0 * d0 + f1 * d1 + f2 * d2) < 0:
            n0, n1, n2 = f0, f1, f2
        out[i, 0], out[i, 1], out[i, 2] = n0, n1, n2
    return out


@kernel("float64[:, ::1](float64[:, ::1], float64[:, ::1], int64[::1], int64[::1], float64)")
def _same_side_sums(face, unit, tri_of, starts, cos_crease):
    """Per corner (in the vertex-sorted order), the sum of the area-weighted ``face`` normals of the triangles
    ``tri_of`` of its vertex group (``starts[g]`` .. ``starts[g + 1]`` - 1) whose ``unit`` normal lies within the
    crease of its own (dot >= ``cos_crease``), added in the group's order."""
    out = np.zeros((tri_of.size, 3))
    for g in range(starts.size - 1):
        lo, hi = starts[g], starts[g + 1]
        for i in range(lo, hi):
            ti = tri_of[i]
            s0 = s1 = s2 = 0.0
            for j in range(lo, hi):
                tj = tri_of[j]
                if unit[ti, 0] * unit[tj, 0] + unit[ti, 1] * unit[tj, 1] + unit[ti, 2] * unit[tj, 2] >= cos_crease:
                    s0 += face[tj, 0]
                    s1 += face[tj, 1]
                    s2 += face[tj, 2]
            out[i, 0] = s0
            out[i, 1] = s1
            out[i, 2] = s2
    return out
