"""The devkit's greedy assignment of detections to ground truth, vectorised over frames and thresholds.

The devkit visits the ground truth of a frame in file order; each ground truth object takes one
unassigned candidate detection (overlap strictly above the class threshold) by a priority rule.
Objects of different frames never compete, so the k-th candidate-owning object of every frame is
processed at once; the loop runs over k (a few dozen steps at most), and each step handles all
score thresholds in parallel as a leading axis.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = ["Assignment", "Problem", "greedy_assign", "overlap_priority", "score_priority"]


@dataclass(frozen=True)
class Problem:
    """One (class, difficulty, metric, overlap threshold) evaluation, E candidate edges.

    Attributes:
        edge_gt: (E,) int64 ground-truth index of each candidate pair (overlap > threshold).
        edge_det: (E,) int64 detection index.
        edge_overlap: (E,) float64 overlap.
        gt_frame: (G,) int64 frame of every ground-truth object (sorted).
        gt_flag: (G,) int8 devkit ignored_gt: 0 counted, 1 ignored, -1 not of this class.
        det_flag: (D,) int8 devkit ignored_det: 0 counted, 1 ignored (too small), -1 other class.
        det_score: (D,) float64.
        gt_alpha, det_alpha: (G,), (D,) float64 observation angles (for AOS).
        det_in_dontcare: (D,) bool, detection lies in a DontCare region (share above threshold);
            all False where the metric ignores DontCare (BEV, 3D).
    """

    edge_gt: np.ndarray
    edge_det: np.ndarray
    edge_overlap: np.ndarray
    gt_frame: np.ndarray
    gt_flag: np.ndarray
    det_flag: np.ndarray
    det_score: np.ndarray
    gt_alpha: np.ndarray
    det_alpha: np.ndarray
    det_in_dontcare: np.ndarray

    @property
    def n_gt(self) -> int:
        """Ground truth counted for recall (flag 0)."""
        return int(np.count_nonzero(self.gt_flag == 0))


@dataclass(frozen=True)
class Assignment:
    """Result of :func:`greedy_assign` for T thresholds and U ground-truth objects with candidates.

    Attributes:
        gt: (U,) int64 ground-truth indices that have at least one candidate.
        det: (T, U) int64 detection assigned to each of them at each threshold, -1 for none.
    """

    gt: np.ndarray
    det: np.ndarray

    def outcomes(self, problem: Problem) -> tuple[np.ndarray, np.ndarray]:
        """(T, U) bool true positive, (T, U) bool counted ground truth swallowed by an ignored detection."""
        has = self.det >= 0
        det_flag = problem.det_flag[np.where(has, self.det, 0)]
        counted_gt = (problem.gt_flag[self.gt] == 0)[None, :]
        return has & counted_gt & (det_flag == 0), has & counted_gt & (det_flag == 1)


def _ranks(edge_gt: np.ndarray, gt_frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unique candidate-owning gt (U,), the index into them of each edge (E,), their rank in frame (U,)."""
    owners, inverse = np.unique(edge_gt, return_inverse=True)
    frames = gt_frame[owners]
    rank = np.arange(len(owners)) - np.searchsorted(frames, frames, side="left")
    return owners, inverse, rank


def greedy_assign(problem: Problem, priority: tuple[np.ndarray, ...], available: np.ndarray) -> Assignment:
    """Run the devkit's per-frame greedy assignment for T thresholds at once.

    Args:
        problem: the candidates.
        priority: (E,) arrays, most significant first; among its available candidates a ground-truth
            object takes the one with the smallest keys (ties are impossible: the last key is the
            detection index).
        available: (T, D) bool, detections that may be assigned at each threshold (modified).

    Returns:
        The assignment.
    """
    n_thresholds = available.shape[0]
    owners, owner_of_edge, rank = _ranks(problem.edge_gt, problem.gt_frame)
    edge_rank = rank[owner_of_edge]
    order = np.lexsort((*reversed(priority), owner_of_edge, edge_rank))
    det_sorted = problem.edge_det[order]
    owner_sorted = owner_of_edge[order]
    rank_sorted = edge_rank[order]
    assigned = np.full((n_thresholds, len(owners)), -1, dtype=np.int64)
    if len(order) == 0:
        return Assignment(gt=owners, det=assigned)
    rank_bounds = np.searchsorted(rank_sorted, np.arange(rank_sorted[-1] + 2))
    segment_start = np.flatnonzero(np.r_[True, owner_sorted[1:] != owner_sorted[:-1]])
    for lo, hi in itertools.pairwise(rank_bounds):
        dets = det_sorted[lo:hi]
        starts = segment_start[(segment_start >= lo) & (segment_start < hi)]
        width = hi - lo
        position = np.where(available[:, dets], np.arange(width), width)
        first = np.minimum.reduceat(position, starts - lo, axis=1)  # (T, S)
        found = first < width
        chosen = np.where(found, dets[np.minimum(first, width - 1)], -1)
        assigned[:, owner_sorted[starts]] = chosen
        t_idx, s_idx = np.nonzero(found)
        available[t_idx, chosen[t_idx, s_idx]] = False
    return Assignment(gt=owners, det=assigned)


def score_priority(problem: Problem) -> tuple[np.ndarray, ...]:
    """The devkit's rule when collecting recall thresholds: highest score, then first in file."""
    return (-problem.det_score[problem.edge_det], problem.edge_det)


def overlap_priority(problem: Problem) -> tuple[np.ndarray, ...]:
    """The devkit's rule when counting TP/FP at a threshold: a counted detection with the largest
    overlap (first in file on ties), else the first ignored (too small) detection."""
    flag = problem.det_flag[problem.edge_det]
    return (flag, np.where(flag == 0, -problem.edge_overlap, 0.0), problem.edge_det)
