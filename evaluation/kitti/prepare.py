"""Flatten KITTI frames into arrays, apply the devkit's class and difficulty filters, compute overlaps.

Objects of all frames are concatenated in (frame id, file line) order, which is the order the
devkit visits them; ``frame`` maps each object to its frame. Overlaps are computed only for
(ground truth, detection) pairs of the same frame and kept sparsely (pairs with overlap > 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from evaluation.kitti.iou import bev_iou, box3d_iou, image_box_overlap
from evaluation.kitti.readers import KittiFrame

__all__ = [
    "DIFFICULTIES", "NEIGHBOURS", "Difficulty", "Flat", "OverlapRules", "Pairs",
    "det_flags", "dontcare_overlap", "flatten", "gt_flags", "pairs",
]  # fmt: skip


@dataclass(frozen=True)
class Difficulty:
    """The devkit's filter for one difficulty level (ground truth outside it is ignored, not missed)."""

    name: str
    min_height_px: float
    max_occlusion: int
    max_truncation: float


DIFFICULTIES = (
    Difficulty("easy", 40, 0, 0.15),
    Difficulty("moderate", 25, 1, 0.30),
    Difficulty("hard", 25, 2, 0.50),
)
# ground truth of the neighbour class is ignored (neither TP nor FN) when evaluating the key class
NEIGHBOURS = {"car": "van", "pedestrian": "person_sitting"}


@dataclass(frozen=True)
class Flat:
    """All objects of one side (ground truth or detections) of all frames, N objects.

    Attributes:
        frame: (N,) int64 frame index (into the sorted frame ids).
        type: (N,) str lower-cased class name.
        truncated, alpha, score: (N,) float64 (score is 0 for ground truth).
        occluded: (N,) int64.
        bbox: (N, 4) float64 x1, y1, x2, y2.
        box3d: (N, 7) float64 x, y, z (bottom centre, camera frame), h, w, l, ry.
        has_box3d: (N,) bool, False for the "-1 -1 -1" no-3D-box sentinel.
    """

    frame: np.ndarray
    type: np.ndarray
    truncated: np.ndarray
    occluded: np.ndarray
    alpha: np.ndarray
    bbox: np.ndarray
    box3d: np.ndarray
    has_box3d: np.ndarray
    score: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    def starts(self, n_frames: int) -> np.ndarray:
        """(n_frames + 1,) int64 offsets: frame f owns objects starts[f]:starts[f + 1]."""
        return np.searchsorted(self.frame, np.arange(n_frames + 1))


def flatten(frames: list[KittiFrame]) -> Flat:
    """Concatenate frames (in the given order) into a Flat."""
    counts = np.array([len(f) for f in frames], dtype=np.int64)

    def cat(get, shape: tuple[int, ...] = ()) -> np.ndarray:
        parts = [get(f) for f in frames]
        return np.concatenate(parts) if parts else np.zeros((0, *shape))

    box3d = np.column_stack(
        [cat(lambda f: f.location, (3,)), cat(lambda f: f.dimensions, (3,)), cat(lambda f: f.rotation_y)]
    ).reshape(-1, 7)
    return Flat(
        frame=np.repeat(np.arange(len(frames)), counts),
        type=np.char.lower(cat(lambda f: f.type).astype(str)),
        truncated=cat(lambda f: f.truncated),
        occluded=cat(lambda f: f.occluded).astype(np.int64),
        alpha=cat(lambda f: f.alpha),
        bbox=cat(lambda f: f.bbox, (4,)).reshape(-1, 4),
        box3d=box3d,
        has_box3d=cat(lambda f: f.has_box3d).astype(bool),
        score=cat(lambda f: f.score if f.score is not None else np.zeros(len(f))),
    )


def gt_flags(gt: Flat, cls: str, diff: Difficulty) -> np.ndarray:
    """(N,) int8 devkit ``ignored_gt``: 0 counted, 1 ignored (neighbour class or outside the difficulty), -1 other."""
    cls = cls.lower()
    same = gt.type == cls
    neighbour = gt.type == NEIGHBOURS.get(cls, "\0")
    height = gt.bbox[:, 3] - gt.bbox[:, 1]
    too_hard = (
        (gt.occluded > diff.max_occlusion) | (gt.truncated > diff.max_truncation) | (height <= diff.min_height_px)
    )
    flags = np.full(len(gt), -1, dtype=np.int8)
    flags[neighbour | (same & too_hard)] = 1
    flags[same & ~too_hard] = 0
    return flags


def det_flags(det: Flat, cls: str, diff: Difficulty) -> np.ndarray:
    """(N,) int8 devkit ``ignored_det``: 0 counted, 1 ignored (too small: any class!), -1 other class."""
    height = np.abs(det.bbox[:, 3] - det.bbox[:, 1])
    flags = np.where(det.type == cls.lower(), 0, -1).astype(np.int8)
    flags[height < diff.min_height_px] = 1
    return flags


@dataclass(frozen=True)
class OverlapRules:
    """How a mode computes overlaps.

    Attributes:
        rotated: the BEV intersection algorithm, "float64" or "port" (see :mod:`evaluation.kitti.iou`).
        sentinel_is_box: the devkit reads the "-1 -1 -1" no-3D-box sentinel as sizes, so such an
            object is a 1 x 1 m square at its location (x, z = -1000 for KITTI's DontCare) and
            overlaps another sentinel there; False leaves objects without a 3D box out of BEV/3D.
        dontcare_metrics: the box metrics in which DontCare regions absorb unassigned detections
            (the devkit: all three, each with its own overlap; the Python port: "bbox" only).
    """

    rotated: str
    sentinel_is_box: bool
    dontcare_metrics: tuple[str, ...]


@dataclass(frozen=True)
class Pairs:
    """Sparse overlaps of (ground truth, detection) pairs of the same frame, K pairs with overlap > 0.

    Attributes:
        gt: (K,) int64 index into the ground truth Flat.
        det: (K,) int64 index into the detection Flat.
        overlap: (K,) float64 IoU of the metric.
    """

    gt: np.ndarray
    det: np.ndarray
    overlap: np.ndarray


def _all_pairs(gt: Flat, det: Flat, n_frames: int, gt_mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every (gt, det) index pair of the same frame, gt restricted to gt_mask; sorted by gt then det."""
    det_start = det.starts(n_frames)
    gt_idx = np.nonzero(gt_mask)[0]
    frame = gt.frame[gt_idx]
    n_det = det_start[frame + 1] - det_start[frame]
    g = np.repeat(gt_idx, n_det)
    within = np.arange(len(g)) - np.repeat(np.cumsum(n_det) - n_det, n_det)
    d = np.repeat(det_start[frame], n_det) + within
    return g, d


def _box_overlap(
    first: Flat, i: np.ndarray, second: Flat, j: np.ndarray, metric: str, rules: OverlapRules, criterion: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Overlap of the pairs (first[i], second[j]) of a metric, only where it can be positive.

    Returns the kept (i, j) and their overlap; criterion "a" divides by the size of ``first``.
    """
    if metric == "bbox":
        return i, j, image_box_overlap(first.bbox[i], second.bbox[j], criterion=criterion)
    if metric not in ("bev", "3d"):
        raise ValueError(f"unknown metric {metric!r}; expected 'bbox', 'bev' or '3d'")
    a, b = first.box3d[i], second.box3d[j]
    # cheap rejection by circumscribed circles before the polygon clipping
    radius_a = np.hypot(a[:, 4], a[:, 5]) / 2
    radius_b = np.hypot(b[:, 4], b[:, 5]) / 2
    near = np.hypot(a[:, 0] - b[:, 0], a[:, 2] - b[:, 2]) < radius_a + radius_b
    if not rules.sentinel_is_box:
        near &= first.has_box3d[i] & second.has_box3d[j]
    i, j, a, b = i[near], j[near], a[near], b[near]
    if metric == "bev":
        cols = [0, 2, 5, 4, 6]
        return i, j, bev_iou(a[:, cols], b[:, cols], rotated=rules.rotated, criterion=criterion)
    return i, j, box3d_iou(a, b, rotated=rules.rotated, criterion=criterion)


def pairs(gt: Flat, det: Flat, n_frames: int, metric: str, rules: OverlapRules) -> Pairs:
    """Overlaps of the metric ("bbox", "bev" or "3d") for all same-frame pairs with overlap > 0.

    DontCare ground truth is left out (it only enters through :func:`dontcare_overlap`).
    """
    g, d = _all_pairs(gt, det, n_frames, gt.type != "dontcare")
    d, g, overlap = _box_overlap(det, d, gt, g, metric, rules, "union")
    keep = overlap > 0
    return Pairs(gt=g[keep], det=d[keep], overlap=overlap[keep])


def dontcare_overlap(gt: Flat, det: Flat, n_frames: int, metric: str, rules: OverlapRules) -> np.ndarray:
    """(N_det,) float64: per detection, the largest share of its box (2D area, BEV area or volume,
    by metric) inside one DontCare region; 0 where the mode ignores DontCare for the metric."""
    best = np.zeros(len(det))
    if metric not in rules.dontcare_metrics:
        return best
    g, d = _all_pairs(gt, det, n_frames, gt.type == "dontcare")
    d, g, share = _box_overlap(det, d, gt, g, metric, rules, "a")
    np.maximum.at(best, d, share)
    return best
