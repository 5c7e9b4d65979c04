"""Overlap of KITTI boxes: 2D image boxes, rotated bird's-eye-view (BEV) rectangles and 3D boxes.

All functions take P explicit pairs (row i of ``a`` against row i of ``b``) and are vectorised over
them; callers choose the pairs (same frame, near enough) so nothing is quadratic.

Conventions (KITTI rectified camera frame: x right, y down, z forward):

- BEV box: (x, z, l, w, ry), centre in the ground plane, length l along the heading
  (cos ry, -sin ry) in (x, z) and width w across it.
- 3D box: BEV box plus bottom y and height h; the box spans [y - h, y] vertically (y points down).

Two rotated-rectangle intersections are provided:

- :func:`bev_intersection_exact`: float64 convex clipping that treats boundary contacts and
  collinear edges robustly (agrees with shapely to ~1e-12). This is what the official KITTI devkit
  computes (evaluate_object.cpp intersects boost::geometry double-precision polygons), up to the
  last bits of rounding; ``mode="official"`` and ``mode="exact"`` use it.
- :func:`bev_intersection_port`: the single-precision algorithm of the common Python port
  (kitti_object_eval_python ``rotate_iou``), reproduced for ``mode="port"``: corners inside the
  other rectangle by a non-tolerant dot-product test, edge crossings by strict orientation tests
  (collinear edges never cross), vertices sorted by a pseudo-angle, fan-triangulated area. Because
  the tests have no tolerance, coincident or edge-sharing rotated rectangles lose vertices to
  float32 rounding and their intersection collapses (often to 0).

IoU definitions are the devkit's: BEV = intersection / (l_a w_a + l_b w_b - intersection); 3D =
BEV intersection x vertical overlap / (h_a w_a l_a + h_b w_b l_b - that); criterion "a" divides by
the area (volume) of ``a`` alone (the devkit's DontCare test, ``a`` = the detection).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "ROTATED",
    "bev_intersection_exact",
    "bev_intersection_port",
    "bev_iou",
    "box3d_iou",
    "image_box_overlap",
    "rect_corners",
]


def image_box_overlap(a: np.ndarray, b: np.ndarray, *, criterion: str = "union") -> np.ndarray:
    """Overlap of P pairs of axis-aligned image boxes.

    Args:
        a, b: (P, 4) float64 x1, y1, x2, y2.
        criterion: "union" (IoU) or "a" (intersection / area of a, the devkit's DontCare test).

    Returns:
        (P,) float64; 0 where the boxes do not overlap with positive width and height.
    """
    w = np.minimum(a[:, 2], b[:, 2]) - np.maximum(a[:, 0], b[:, 0])
    h = np.minimum(a[:, 3], b[:, 3]) - np.maximum(a[:, 1], b[:, 1])
    inter = np.where((w > 0) & (h > 0), w * h, 0.0)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    if criterion == "union":
        denom = area_a + (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1]) - inter
    elif criterion == "a":
        denom = area_a
    else:
        raise ValueError(f"unknown criterion {criterion!r}; expected 'union' or 'a'")
    return np.divide(inter, denom, out=np.zeros_like(inter), where=inter > 0)


def rect_corners(boxes: np.ndarray) -> np.ndarray:
    """(P, 5) BEV boxes (x, z, l, w, ry) -> (P, 4, 2) corners, counter-clockwise in (x, z) when l, w > 0."""
    c, s = np.cos(boxes[:, 4]), np.sin(boxes[:, 4])
    half_l, half_w = boxes[:, 2] / 2, boxes[:, 3] / 2
    # heading (cos ry, -sin ry); lateral axis perpendicular to it: (sin ry, cos ry)
    sign_l = np.array([1.0, -1.0, -1.0, 1.0])
    sign_w = np.array([1.0, 1.0, -1.0, -1.0])
    dl = sign_l[None, :] * half_l[:, None]
    dw = sign_w[None, :] * half_w[:, None]
    x = boxes[:, 0, None] + dl * c[:, None] + dw * s[:, None]
    z = boxes[:, 1, None] - dl * s[:, None] + dw * c[:, None]
    return np.stack([x, z], axis=-1)


def _polygon_area(points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Area of the convex hull of the valid points of each row, given they are its vertices.

    Args:
        points: (P, K, 2) float64 candidate vertices (duplicates allowed).
        valid: (P, K) bool.

    Returns:
        (P,) float64 area; 0 for fewer than 3 valid points.
    """
    count = valid.sum(axis=1)
    centre = np.einsum("pk,pkd->pd", valid.astype(np.float64), points) / np.maximum(count, 1)[:, None]
    rel = points - centre[:, None, :]
    angle = np.where(valid, np.arctan2(rel[..., 1], rel[..., 0]), np.inf)
    order = np.argsort(angle, axis=1, kind="stable")
    rel = np.take_along_axis(rel, order[..., None], axis=1)
    valid_sorted = np.take_along_axis(valid, order, axis=1)
    # invalid points (sorted last) collapse onto the first point: their edges add nothing
    rel = np.where(valid_sorted[..., None], rel, rel[:, :1, :])
    nxt = np.roll(rel, -1, axis=1)
    area = 0.5 * np.abs(np.sum(rel[..., 0] * nxt[..., 1] - rel[..., 1] * nxt[..., 0], axis=1))
    return np.where(count >= 3, area, 0.0)


def _inside(points: np.ndarray, corners: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """(P, K, 2) points inside the (P, 4, 2) counter-clockwise rectangles, within (P,) tolerance."""
    edge = np.roll(corners, -1, axis=1) - corners  # (P, 4, 2)
    rel = points[:, :, None, :] - corners[:, None, :, :]  # (P, K, 4, 2)
    cross = edge[:, None, :, 0] * rel[..., 1] - edge[:, None, :, 1] * rel[..., 0]
    length = np.linalg.norm(edge, axis=-1)[:, None, :]
    return np.all(cross >= -tol[:, None, None] * length, axis=-1)


def bev_intersection_exact(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact intersection area of P pairs of rotated rectangles, float64.

    Args:
        a, b: (P, 5) float64 BEV boxes (x, z, l, w, ry), l and w of one sign (the devkit's "-1 -1 -1"
            sentinel is a unit square: a rectangle turned by pi).

    Returns:
        (P,) float64 area in m^2.
    """
    if len(a) == 0:
        return np.zeros(0)
    # work relative to a's centre: less cancellation for boxes far from the camera
    origin = a[:, :2].copy()
    a, b = a.copy(), b.copy()
    a[:, :2] -= origin
    b[:, :2] -= origin
    ca, cb = rect_corners(a), rect_corners(b)
    scale = np.maximum(np.max(np.abs(ca), axis=(1, 2)), np.max(np.abs(cb), axis=(1, 2)))
    tol = 1e-12 * np.maximum(scale, 1e-300)
    in_a = _inside(ca, cb, tol)
    in_b = _inside(cb, ca, tol)
    # all 16 edge pairs: p + t r crosses q + u s with t, u in [0, 1]
    p, r = ca[:, :, None, :], (np.roll(ca, -1, axis=1) - ca)[:, :, None, :]
    q, s = cb[:, None, :, :], (np.roll(cb, -1, axis=1) - cb)[:, None, :, :]
    denom = r[..., 0] * s[..., 1] - r[..., 1] * s[..., 0]
    qp = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (qp[..., 0] * s[..., 1] - qp[..., 1] * s[..., 0]) / denom
        u = (qp[..., 0] * r[..., 1] - qp[..., 1] * r[..., 0]) / denom
    parallel = np.abs(denom) <= 1e-14 * np.maximum(scale, 1e-300)[:, None, None] ** 2
    crosses = ~parallel & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    cross_pts = p + np.where(crosses, t, 0.0)[..., None] * r
    points = np.concatenate([ca, cb, cross_pts.reshape(-1, 16, 2)], axis=1)
    valid = np.concatenate([in_a, in_b, crosses.reshape(-1, 16)], axis=1)
    return _polygon_area(points, valid)


def bev_intersection_port(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection area as the common Python port computes it (single precision, no tolerance).

    Args:
        a, b: (P, 5) BEV boxes (x, z, l, w, ry); converted to float32 like the port.

    Returns:
        (P,) float64 area (float32 vertices, summed in float64).
    """
    if len(a) == 0:
        return np.zeros(0)
    ca, cb = _port_corners(a.astype(np.float32)), _port_corners(b.astype(np.float32))
    in_a, in_b = _port_inside(ca, cb), _port_inside(cb, ca)
    cross_valid, cross_pts = _port_crossings(ca, cb)
    # the port appends corner i of a, then corner i of b, for i = 0..3, then the crossings
    corners = np.stack([ca, cb], axis=2).reshape(-1, 8, 2)
    corner_valid = np.stack([in_a, in_b], axis=2).reshape(-1, 8)
    points = np.concatenate([corners, cross_pts.reshape(-1, 16, 2)], axis=1)
    valid = np.concatenate([corner_valid, cross_valid.reshape(-1, 16)], axis=1)
    return _port_area(points, valid)


def _port_corners(boxes: np.ndarray) -> np.ndarray:
    """float32 corners in the port's order (its rotation is the mirror image of ours; IoU is unchanged)."""
    c, s = np.cos(boxes[:, 4]), np.sin(boxes[:, 4])
    half_l, half_w = boxes[:, 2] / np.float32(2), boxes[:, 3] / np.float32(2)
    px = np.stack([-half_l, -half_l, half_l, half_l], axis=1)
    py = np.stack([-half_w, half_w, half_w, -half_w], axis=1)
    x = c[:, None] * px + s[:, None] * py + boxes[:, 0, None]
    y = -s[:, None] * px + c[:, None] * py + boxes[:, 1, None]
    return np.stack([x, y], axis=-1)


def _port_inside(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(P, 4) bool: dot-product inclusion test of the port, no tolerance."""
    ab = corners[:, 1] - corners[:, 0]
    ad = corners[:, 3] - corners[:, 0]
    ap = points - corners[:, None, 0]
    abab = (ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1])[:, None]
    adad = (ad[:, 0] * ad[:, 0] + ad[:, 1] * ad[:, 1])[:, None]
    abap = ab[:, None, 0] * ap[..., 0] + ab[:, None, 1] * ap[..., 1]
    adap = ad[:, None, 0] * ap[..., 0] + ad[:, None, 1] * ap[..., 1]
    return (abab >= abap) & (abap >= 0) & (adad >= adap) & (adap >= 0)


def _port_crossings(ca: np.ndarray, cb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P, 4, 4) bool and (P, 4, 4, 2) float32: strict-orientation segment crossings of the port."""
    A, B = ca[:, :, None, :], np.roll(ca, -1, axis=1)[:, :, None, :]
    C, D = cb[:, None, :, :], np.roll(cb, -1, axis=1)[:, None, :, :]
    BA, DA, CA = B - A, D - A, C - A
    acd = DA[..., 1] * CA[..., 0] > CA[..., 1] * DA[..., 0]
    bcd = (D[..., 1] - B[..., 1]) * (C[..., 0] - B[..., 0]) > (C[..., 1] - B[..., 1]) * (D[..., 0] - B[..., 0])
    abc = CA[..., 1] * BA[..., 0] > BA[..., 1] * CA[..., 0]
    abd = DA[..., 1] * BA[..., 0] > BA[..., 1] * DA[..., 0]
    valid = (acd != bcd) & (abc != abd)
    DC = D - C
    abba = A[..., 0] * B[..., 1] - B[..., 0] * A[..., 1]
    cddc = C[..., 0] * D[..., 1] - D[..., 0] * C[..., 1]
    dh = BA[..., 1] * DC[..., 0] - BA[..., 0] * DC[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (abba * DC[..., 0] - BA[..., 0] * cddc) / dh
        y = (abba * DC[..., 1] - BA[..., 1] * cddc) / dh
    pts = np.stack([np.where(valid, x, 0), np.where(valid, y, 0)], axis=-1).astype(np.float32)
    return valid, pts


def _port_area(points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Pseudo-angle sort around the float32 centroid, then the fan area from the first vertex."""
    count = valid.sum(axis=1)
    masked = np.where(valid[..., None], points, np.float32(0))
    centre = masked.sum(axis=1, dtype=np.float32) / np.maximum(count, 1)[:, None].astype(np.float32)
    rel = points - centre[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = rel / np.sqrt(rel[..., 0] ** 2 + rel[..., 1] ** 2)[..., None]
    key = np.where(unit[..., 1] < 0, np.float32(-2) - unit[..., 0], unit[..., 0])
    key = np.where(valid, key, np.inf)
    order = np.argsort(key, axis=1, kind="stable")
    pts = np.take_along_axis(points, order[..., None], axis=1).astype(np.float64)
    first = pts[:, :1, :]
    u, v = pts[:, 1:-1, :] - first, pts[:, 2:, :] - first
    tri = np.abs(u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]) / 2
    k = np.arange(tri.shape[1])[None, :]
    return np.sum(np.where(k < (count - 2)[:, None], tri, 0.0), axis=1)


ROTATED = ("float64", "port")


def _bev_intersection(a: np.ndarray, b: np.ndarray, rotated: str) -> np.ndarray:
    if rotated == "float64":
        return bev_intersection_exact(a, b)
    if rotated == "port":
        return bev_intersection_port(a, b)
    raise ValueError(f"unknown rotated-intersection algorithm {rotated!r}; expected one of {ROTATED}")


def _ratio(inter: np.ndarray, denom: np.ndarray) -> np.ndarray:
    # a zero intersection is no overlap whatever the denominator (the devkit's 0 / 0 is NaN: no match either)
    return np.divide(inter, denom, out=np.zeros_like(inter), where=(inter > 0) & (denom != 0))


def bev_iou(a: np.ndarray, b: np.ndarray, *, rotated: str, criterion: str = "union") -> np.ndarray:
    """Overlap of P pairs of BEV boxes (x, z, l, w, ry), (P, 5) -> (P,) float64.

    Args:
        a, b: (P, 5) float64 BEV boxes.
        rotated: "float64" (polygon clipping in double precision, as the devkit's boost::geometry) or
            "port" (the common Python port's float32 algorithm).
        criterion: "union" (intersection / (area a + area b - intersection)) or "a" (intersection /
            area of a: the devkit's DontCare test with a = the detection).

    Areas are the signed products l * w, as the devkit's polygon areas: its "-1 -1 -1" sentinel box is
    a 1 x 1 m square.
    """
    inter = _bev_intersection(a, b, rotated)
    area_a = a[:, 2] * a[:, 3]
    if criterion == "union":
        return _ratio(inter, area_a + b[:, 2] * b[:, 3] - inter)
    if criterion == "a":
        return _ratio(inter, area_a)
    raise ValueError(f"unknown criterion {criterion!r}; expected 'union' or 'a'")


def box3d_iou(a: np.ndarray, b: np.ndarray, *, rotated: str, criterion: str = "union") -> np.ndarray:
    """Overlap of P pairs of 3D boxes.

    Args:
        a, b: (P, 7) float64 (x, y, z, h, w, l, ry): bottom centre in the camera frame, sizes, yaw.
        rotated: the BEV intersection algorithm, as in :func:`bev_iou`.
        criterion: "union" or "a" (intersection volume / volume of a), as in :func:`bev_iou`.

    Returns:
        (P,) float64 = BEV intersection x vertical overlap / union of volumes (volumes h * w * l, as
        the devkit's box3DOverlap).
    """
    bev_a, bev_b = a[:, [0, 2, 5, 4, 6]], b[:, [0, 2, 5, 4, 6]]
    inter_area = _bev_intersection(bev_a, bev_b, rotated)
    overlap_h = np.minimum(a[:, 1], b[:, 1]) - np.maximum(a[:, 1] - a[:, 3], b[:, 1] - b[:, 3])
    inter = inter_area * np.maximum(overlap_h, 0.0)
    volume_a = a[:, 3] * a[:, 4] * a[:, 5]
    if criterion == "union":
        return _ratio(inter, volume_a + b[:, 3] * b[:, 4] * b[:, 5] - inter)
    if criterion == "a":
        return _ratio(inter, volume_a)
    raise ValueError(f"unknown criterion {criterion!r}; expected 'union' or 'a'")
