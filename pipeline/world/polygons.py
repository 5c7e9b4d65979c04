"""2D polygon and polyline helpers for building the static world: cleaning, ear-clipping triangulation,
offset polylines (mitred), ribbons between two polylines, walls along polylines, and resampling.

Conventions: points are (n, 2) or (n, 3) float64 in metres, world frame (x east, y north, z up). A polygon
is a closed ring given without its repeated first point; triangles are returned counter-clockwise seen
from above (+z), as :class:`pipeline.world.mesh.Mesh` expects for upward-facing surfaces.
"""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger(__name__)

_EPS = 1e-9


def signed_area(ring: np.ndarray) -> float:
    """Signed area (m^2) of a ring (n, >=2): positive when counter-clockwise."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def clean_ring(ring: np.ndarray, tol_m: float = 1e-4) -> np.ndarray:
    """Drop a repeated closing point and consecutive duplicates (closer than ``tol_m``) of a ring (n, d)."""
    ring = np.asarray(ring, dtype=np.float64)
    if len(ring) < 2:
        return ring
    step = np.linalg.norm(ring[:, :2] - np.roll(ring[:, :2], 1, axis=0), axis=1)
    return ring[step > tol_m] if (step > tol_m).any() else ring[:1]


def _cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0])


def triangulate_ring(ring: np.ndarray) -> np.ndarray:
    """Ear-clip a simple polygon ring (n, >=2) into (n-2, 3) int32 indices into ``ring``, CCW from above.

    Robust to clockwise input, collinear and duplicate points (clean first with :func:`clean_ring`).
    For a self-intersecting or degenerate ring no ear may exist; then the most convex vertex is clipped
    anyway, so the result always covers the ring with n-2 triangles (counted in the debug log).
    """
    n = len(ring)
    if n < 3:
        return np.zeros((0, 3), dtype=np.int32)
    pts = np.asarray(ring, dtype=np.float64)[:, :2]
    idx = list(range(n)) if signed_area(pts) >= 0 else list(range(n - 1, -1, -1))
    out, forced = [], 0
    while len(idx) > 3:
        cur = np.array(idx)
        prev, nxt = np.roll(cur, 1), np.roll(cur, -1)
        turn = _cross(pts[prev], pts[cur], pts[nxt])
        convex = np.flatnonzero(turn > _EPS)
        ear = -1
        for k in convex:
            a, b, c = pts[prev[k]], pts[cur[k]], pts[nxt[k]]
            others = pts[np.setdiff1d(cur, [prev[k], cur[k], nxt[k]])]
            inside = (_cross(a, b, others) > -_EPS) & (_cross(b, c, others) > -_EPS) & (_cross(c, a, others) > -_EPS)
            if not inside.any():
                ear = int(k)
                break
        if ear < 0:
            ear, forced = int(np.argmax(turn)), forced + 1
        out.append((prev[ear], cur[ear], nxt[ear]))
        idx.pop(ear)
    out.append(tuple(idx))
    if forced:
        log.debug("triangulate_ring: %d forced clips on a degenerate ring of %d points", forced, n)
    return np.asarray(out, dtype=np.int32)


_LEFT_TURN = np.array([-1.0, 1.0])  # (x, y) reversed and scaled by this: (-y, x), the left normal


def polyline_normals(points: np.ndarray, max_miter: float = 3.0) -> np.ndarray:
    """Left unit normals scaled for a mitred offset at each vertex of a polyline (n, >=2) -> (n, 2).

    Offsetting a vertex by ``d * normal`` keeps every segment's offset line at distance ``d``; the miter
    scale is clamped to ``max_miter`` at sharp turns.
    """
    # Called thousands of times per world on short lines: few numpy calls (the norms as numpy.linalg.norm computes
    # them, without its overhead).
    xy = np.asarray(points, dtype=np.float64)[:, :2]
    if len(xy) < 2:
        raise ValueError(f"a polyline needs at least 2 points, got {len(xy)}")
    seg = xy[1:] - xy[:-1]
    seg /= np.maximum(np.sqrt(np.add.reduce(seg * seg, axis=1, keepdims=True)), _EPS)
    seg_n = seg[:, ::-1] * _LEFT_TURN
    vert = np.empty((len(xy), 2))
    vert[0], vert[-1] = seg_n[0], seg_n[-1]
    np.add(seg_n[:-1], seg_n[1:], out=vert[1:-1])
    vert /= np.maximum(np.sqrt(np.add.reduce(vert * vert, axis=1, keepdims=True)), _EPS)
    cos_half = np.ones((len(xy), 1))
    cos_half[1:-1, 0] = np.einsum("ij,ij->i", vert[1:-1], seg_n[1:])
    return vert / np.clip(cos_half, 1.0 / max_miter, None)


def offset_polyline(points: np.ndarray, offset_m: float | np.ndarray, normals: np.ndarray | None = None
                    ) -> np.ndarray:
    """Polyline (n, 3) shifted sideways by ``offset_m`` (positive = left of travel); z unchanged. ``normals``:
    :func:`polyline_normals` of ``points`` when the caller already has them (several offsets of one line)."""
    out = np.array(points, dtype=np.float64)
    out[:, :2] += (polyline_normals(points) if normals is None else normals) * np.reshape(offset_m, (-1, 1))
    return out


def ribbon(left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quad strip between two polylines of equal length (n, 3), upward-facing when ``left`` is left of travel.

    Returns vertices (2n, 3) float64 (left then right) and triangles (2(n-1), 3) int32.
    """
    n = len(left)
    i = np.arange(n - 1)
    lft, rgt = i, i + n
    tris = np.concatenate([np.stack([rgt, rgt + 1, lft + 1], 1), np.stack([rgt, lft + 1, lft], 1)])
    return np.concatenate([left, right]), tris.astype(np.int32)


def wall(line: np.ndarray, height_m: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertical wall from polyline ``line`` (n, 3) up by ``height_m``, facing right of travel.

    Returns vertices (2n, 3) (bottom then top) and triangles (2(n-1), 3) int32.
    """
    top = np.array(line, dtype=np.float64)
    top[:, 2] += height_m
    n = len(line)
    i = np.arange(n - 1)
    bot, up = i, i + n
    tris = np.concatenate([np.stack([bot, bot + 1, up + 1], 1), np.stack([bot, up + 1, up], 1)])
    return np.concatenate([line, top]), tris.astype(np.int32)


def cumulative_length(points: np.ndarray) -> np.ndarray:
    """Arc length (n,) float64 along a polyline (n, >=2), metres, in the xy plane."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1))])


def interpolate(points: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (m, 3) at arc lengths ``s`` (m,) along a polyline (n, 3), and unit directions (m, 2) there."""
    arc = cumulative_length(points)
    seg = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(points) - 2)
    length = np.maximum(arc[seg + 1] - arc[seg], _EPS)
    t = np.clip((s - arc[seg]) / length, 0.0, 1.0)[:, None]
    pos = points[seg] * (1 - t) + points[seg + 1] * t
    direction = (points[seg + 1, :2] - points[seg, :2]) / length[:, None]
    return pos, direction


def resample(points: np.ndarray, step_m: float) -> np.ndarray:
    """Polyline (n, 3) resampled so no segment is longer than ``step_m``; original vertices kept."""
    arc = cumulative_length(points)
    pieces = np.maximum(np.ceil(np.diff(arc) / step_m).astype(int), 1)
    t = np.concatenate([np.arange(k) / k for k in pieces])
    seg = np.repeat(np.arange(len(points) - 1), pieces)
    out = points[seg] + (points[seg + 1] - points[seg]) * t[:, None]
    return np.concatenate([out, points[-1:]])
