"""Precision/recall curves and average precision, in the devkit's way (official) and by recall (exact).

Both return a 41-point precision array p[0..40]; AP_R40 = mean(p[1:41]) and AP_R11 = mean(p[0::4]),
the devkit's sums. They differ in what p[i] is:

- official: p[i] is the precision at the i-th score threshold chosen by the devkit's
  ``getThresholds`` (about one per 1/40 of recall when there are 40 or more ground-truth objects;
  fewer thresholds otherwise, the rest of the array staying 0), with TP/FP recounted at each
  threshold by the devkit's overlap-priority assignment, then made non-increasing.
- exact: p[i] = max precision over all operating points with recall >= i/40 (0 if none), from one
  threshold-independent assignment evaluated at every distinct score.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from evaluation.kitti.match import Problem, greedy_assign, overlap_priority, score_priority

__all__ = ["N_SAMPLE_PTS", "Curve", "devkit_thresholds", "exact_curve", "official_curve"]

N_SAMPLE_PTS = 41


@dataclass(frozen=True)
class Curve:
    """Sampled precision (and orientation similarity) of one evaluation.

    Attributes:
        precision: (41,) float64, non-increasing.
        aos: (41,) float64 or None.
        n_gt: ground truth counted for recall.
        n_thresholds: score thresholds evaluated.
    """

    precision: np.ndarray
    aos: np.ndarray | None
    n_gt: int
    n_thresholds: int

    @staticmethod
    def _ap(values: np.ndarray | None, n_gt: int, *, exact: bool) -> dict[str, float | None]:
        if values is None or (exact and n_gt == 0):
            return {"ap_r40": None, "ap_r11": None}
        return {"ap_r40": float(np.mean(values[1:])), "ap_r11": float(np.mean(values[0::4]))}

    def summary(self, *, exact: bool) -> dict[str, dict[str, float | None]]:
        """{"ap": {"ap_r40", "ap_r11"}, "aos": {...}} as fractions in [0, 1]; None where undefined."""
        return {
            "ap": self._ap(self.precision, self.n_gt, exact=exact),
            "aos": self._ap(self.aos, self.n_gt, exact=exact),
        }


def devkit_thresholds(scores: np.ndarray, n_gt: int) -> np.ndarray:
    """The devkit's getThresholds: scores of true positives at which recall passes each 1/40 step.

    Args:
        scores: (K,) float64 scores of the true positives of the score-priority assignment.
        n_gt: ground truth counted for recall.

    Returns:
        (T,) float64 descending thresholds, T <= 41.
    """
    v = np.sort(scores)[::-1]
    n = len(v)
    left = np.arange(1, n + 1) / n_gt if n else np.zeros(0)
    right = np.r_[left[1:], left[-1:]]
    chosen, current, pos = [], 0.0, 0
    while pos < n:
        # skip while the next recall is closer to the current step than this one (never the last)
        take = ~((right[pos:] - current) < (current - left[pos:]))
        take[-1] = True
        pos += int(np.argmax(take))
        chosen.append(v[pos])
        current += 1.0 / (N_SAMPLE_PTS - 1.0)
        pos += 1
    return np.array(chosen, dtype=np.float64)


def _similarity(problem: Problem, gt: np.ndarray, det: np.ndarray) -> np.ndarray:
    return (1.0 + np.cos(problem.gt_alpha[gt] - problem.det_alpha[det])) / 2.0


def _fp_counts(problem: Problem, thresholds: np.ndarray, assigned: np.ndarray) -> np.ndarray:
    """(T,) false positives: counted detections above each threshold, not assigned, not in DontCare.

    assigned: (T, U) detection index per ground truth or -1.
    """
    counted = problem.det_flag == 0
    scores = np.sort(problem.det_score[counted])
    dontcare_scores = np.sort(problem.det_score[counted & problem.det_in_dontcare])
    above = len(scores) - np.searchsorted(scores, thresholds, side="left")
    above_dc = len(dontcare_scores) - np.searchsorted(dontcare_scores, thresholds, side="left")
    safe = np.where(assigned >= 0, assigned, 0)
    taken = (assigned >= 0) & counted[safe]
    taken_dc = taken & problem.det_in_dontcare[safe]
    return above - taken.sum(axis=1) - (above_dc - taken_dc.sum(axis=1))


def official_curve(problem: Problem, *, compute_aos: bool) -> Curve:
    """The devkit's (and the common Python port's) curve, defects included."""
    n_gt = problem.n_gt
    first = greedy_assign(problem, score_priority(problem), np.ones((1, len(problem.det_score)), dtype=bool))
    tp, _ = first.outcomes(problem)
    thresholds = devkit_thresholds(problem.det_score[first.det[0][tp[0]]], n_gt)
    available = problem.det_score[None, :] >= thresholds[:, None]
    assignment = greedy_assign(problem, overlap_priority(problem), available)
    tp, _ = assignment.outcomes(problem)
    n_tp = tp.sum(axis=1)
    n_fp = _fp_counts(problem, thresholds, assignment.det)
    t = len(thresholds)
    precision = np.zeros(N_SAMPLE_PTS)
    with np.errstate(divide="ignore", invalid="ignore"):
        precision[:t] = np.nan_to_num(n_tp / (n_tp + n_fp))
    aos = None
    if compute_aos:
        gt_idx = np.broadcast_to(assignment.gt, tp.shape)
        sim = np.where(tp, _similarity(problem, gt_idx, np.where(tp, assignment.det, 0)), 0.0).sum(axis=1)
        aos = np.zeros(N_SAMPLE_PTS)
        with np.errstate(divide="ignore", invalid="ignore"):
            aos[:t] = np.nan_to_num(sim / (n_tp + n_fp))
        aos = np.maximum.accumulate(aos[::-1])[::-1]
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    return Curve(precision=precision, aos=aos, n_gt=n_gt, n_thresholds=t)


def exact_curve(problem: Problem, *, compute_aos: bool) -> Curve:
    """Precision interpolated at exact recall points from every operating point.

    One score-priority assignment serves every threshold: restricting it to the detections above a
    threshold gives the same assignment as running it on them alone.
    """
    n_gt = problem.n_gt
    assignment = greedy_assign(problem, score_priority(problem), np.ones((1, len(problem.det_score)), dtype=bool))
    tp, swallowed = (m[0] for m in assignment.outcomes(problem))
    dets = assignment.det[0]
    taken = np.zeros(len(problem.det_score), dtype=bool)
    taken[dets[dets >= 0]] = True
    fp_scores = problem.det_score[(problem.det_flag == 0) & ~taken & ~problem.det_in_dontcare]
    tp_scores = problem.det_score[dets[tp]]
    sw_scores = problem.det_score[dets[swallowed]]
    # every score where a count changes (a swallowed ground truth changes the recall denominator)
    points = np.unique(np.concatenate([tp_scores, fp_scores, sw_scores]))[::-1]

    def at_least(values: np.ndarray) -> np.ndarray:
        ordered = np.sort(values)
        return len(ordered) - np.searchsorted(ordered, points, side="left")

    n_tp, n_fp = at_least(tp_scores), at_least(fp_scores)
    denom = n_gt - at_least(sw_scores)
    defined = denom > 0
    level = np.where(defined, (40 * n_tp) // np.maximum(denom, 1), -1)  # recall >= level / 40, exactly

    def envelope(values: np.ndarray) -> np.ndarray:
        best = np.zeros(N_SAMPLE_PTS)
        np.maximum.at(best, level[defined], values[defined])
        return np.maximum.accumulate(best[::-1])[::-1]

    with np.errstate(divide="ignore", invalid="ignore"):
        precision = envelope(np.nan_to_num(n_tp / (n_tp + n_fp)))
        aos = None
        if compute_aos:
            sim_sorted = np.cumsum(_similarity(problem, assignment.gt[tp], dets[tp])[np.argsort(-tp_scores)])
            n_sim = np.r_[0.0, sim_sorted][n_tp]
            aos = envelope(np.nan_to_num(n_sim / (n_tp + n_fp)))
    return Curve(precision=precision, aos=aos, n_gt=n_gt, n_thresholds=len(points))
