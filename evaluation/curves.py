"""Score sweeps of the table's matching: PR curves and the F1-optimal score threshold.

Detections are ordered by descending score; the curve has one point per *distinct* score (a run of
equal scores enters together), giving the precision and recall that ``score_threshold = that score``
would give. Curve data is what plots read (render never recomputes metrics).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from evaluation.inputs import Detections, GroundTruth, image_groups
from evaluation.table import TableMatches

MAX_CURVE_POINTS = 200


def score_sweep(score: np.ndarray, tp: np.ndarray, fp: np.ndarray, n_pos: int) -> dict[str, np.ndarray]:
    """Precision/recall/F1 at every distinct score.

    Args:
        score: (N,) float64 detection scores.
        tp, fp: (N,) bool per detection (crowd matches are neither).
        n_pos: number of real ground-truth objects.

    Returns:
        dict of (P,) arrays: ``score`` (descending), ``tp``, ``fp`` (int64), ``precision``, ``recall``, ``f1``
        (float64; precision is NaN where every counted detection matched a crowd region, recall is NaN when
        ``n_pos == 0``).
    """
    order = np.argsort(-score, kind="stable")
    s = score[order]
    ctp = np.cumsum(tp[order], dtype=np.int64)
    cfp = np.cumsum(fp[order], dtype=np.int64)
    last = np.r_[s[1:] != s[:-1], True] if len(s) else np.zeros(0, bool)
    s, ctp, cfp = s[last], ctp[last], cfp[last]
    with np.errstate(divide="ignore", invalid="ignore"):
        precision = ctp / (ctp + cfp)
        recall = ctp / n_pos if n_pos else np.full(len(ctp), np.nan)
        f1 = np.where(precision + recall > 0, 2 * precision * recall / (precision + recall), 0.0)
    return {"score": s, "tp": ctp, "fp": cfp, "precision": precision, "recall": recall, "f1": f1}


def _best_f1(sweep: dict[str, np.ndarray], iou: float, n_pos: int) -> dict[str, Any]:
    f1 = np.where(np.isnan(sweep["f1"]), -1.0, sweep["f1"])
    if len(f1) == 0 or n_pos == 0:
        return {"iou": iou, "score_threshold": None, "precision": None, "recall": None, "f1": None,
                "tp": 0, "fp": 0, "fn": n_pos}
    i = int(np.argmax(f1))
    tp = int(sweep["tp"][i])
    return {"iou": iou, "score_threshold": float(sweep["score"][i]), "precision": _num(sweep["precision"][i]),
            "recall": _num(sweep["recall"][i]), "f1": float(f1[i]), "tp": tp, "fp": int(sweep["fp"][i]),
            "fn": n_pos - tp}


def _num(x: float) -> float | None:
    return None if np.isnan(x) else float(x)


def _subsample(sweep: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    n = len(sweep["score"])
    if n <= MAX_CURVE_POINTS:
        return sweep
    idx = np.unique(np.linspace(0, n - 1, MAX_CURVE_POINTS).round().astype(np.int64))
    return {k: v[idx] for k, v in sweep.items()}


def sweeps(gt: GroundTruth, dt: Detections, m: TableMatches, group_by: str | None):
    """F1-optimal thresholds (list of dicts, per group and IoU) and PR curves (per group and IoU).

    Returns ``(f1_optimal, curves)``; ``curves`` is a list of dicts with ``group``, ``iou`` and the
    subsampled (P,) arrays of :func:`score_sweep` as lists.
    """
    groups, img_group = image_groups(gt, group_by)
    gt_group = img_group[gt.image_index]
    dt_group = img_group[dt.image_index]
    best, curves = [], []
    for gi, group in enumerate(["all", *groups]):
        dsel = np.ones(len(dt), bool) if gi == 0 else dt_group == gi - 1
        n_pos = int((m.gt_object & (np.ones(len(gt), bool) if gi == 0 else gt_group == gi - 1)).sum())
        for t, iou in enumerate(m.iou_thresholds.tolist()):
            sweep = score_sweep(dt.score[dsel], m.dt_tp[dsel, t], m.dt_fp[dsel, t], n_pos)
            best.append({"group": group, **_best_f1(sweep, iou, n_pos)})
            small = _subsample(sweep)
            curves.append({"group": group, "iou": iou,
                           **{k: [_num(x) for x in v.tolist()] for k, v in small.items()}})
    return best, curves
