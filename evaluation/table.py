"""The paper's table: precision and recall of a detector at IoU thresholds, by group, class and bin.

Definitions (README.md has the full text):

- Matching is per image and class, greedy and one-to-one: detections in descending score (ties in file
  order) each take the still-free ground truth with the highest IoU, if that IoU >= the threshold (TP);
  otherwise the detection is a FP. Crowd regions are not objects: a detection matching one (IoU =
  intersection over the detection's area >= threshold) is neither TP nor FP, and crowds are never FN.
- Only detections with ``score >= score_threshold`` count. Because matching is greedy by score, the
  matches of the detections above a threshold do not depend on those below it, so one matching serves
  every threshold (the F1-optimal threshold and the PR curves reuse it).
- ``precision = tp / (tp + fp)``, ``recall = tp / (tp + fn)``, ``f1 = 2 p r / (p + r)``; ``null`` when the
  denominator is 0.
- Distance, box-height and occlusion rows bin the *ground truth*: recall, tp and fn per bin. A false
  positive has no such bin, so precision, fp and f1 are ``null`` there.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from evaluation.attributes import (
    DISTANCE_LABELS,
    HEIGHT_LABELS,
    KITTI_OCCLUSION_LABELS,
    OCCLUSION_FRACTION_LABELS,
    distance_bins,
    height_bins,
)
from evaluation.coco_ap import sort_detections
from evaluation.inputs import Detections, GroundTruth, image_groups
from evaluation.matching import greedy_match
from evaluation.validate import InputError

DEFAULT_IOU_THRESHOLDS = (0.5, 0.6, 0.7, 0.8)
DEFAULT_SCORE_THRESHOLD = 0.5


@dataclasses.dataclass(frozen=True)
class TableMatches:
    """One greedy matching of all detections at each IoU threshold.

    Attributes:
        iou_thresholds: (T,) float64.
        dt_tp: (Nd, T) bool, detection matched a real object (rows in detection file order).
        dt_fp: (Nd, T) bool, detection matched nothing (crowd matches are neither).
        gt_best_score: (Ng, T) float64 score of the detection that matched each ground truth, -inf if none.
        gt_object: (Ng,) bool, ground truth is a real object (not crowd).
        dt_matched_gt: (Nd, T) int64 index of the matched ground truth (gt order), -1 if none.
    """

    iou_thresholds: np.ndarray
    dt_tp: np.ndarray
    dt_fp: np.ndarray
    gt_best_score: np.ndarray
    gt_object: np.ndarray
    dt_matched_gt: np.ndarray


def match_table(gt: GroundTruth, dt: Detections, iou_thresholds) -> TableMatches:
    """Greedy one-to-one matching per (image, class) at each threshold, for all detections."""
    thr = np.asarray(iou_thresholds, dtype=np.float64)
    if thr.ndim != 1 or len(thr) == 0 or (thr <= 0).any() or (thr > 1).any():
        raise InputError(f"IoU thresholds must be in (0, 1], got {list(iou_thresholds)}")
    n_img = gt.num_images
    dt_problem = dt.category_index * n_img + dt.image_index
    order, _ = sort_detections(dt_problem, dt.score)
    gt_problem = gt.category_index * n_img + gt.image_index
    gorder = np.argsort(gt_problem, kind="stable")
    match_sorted = greedy_match(dt_problem[order], dt.bbox[order], gt_problem[gorder], gt.bbox[gorder],
                                gt.iscrowd[gorder], gt.iscrowd[gorder][:, None], thr, gt.num_categories * n_img)
    match = np.full((len(dt), len(thr)), -1, dtype=np.int64)
    hit = match_sorted[:, 0, :] >= 0
    if len(gorder):
        match[order] = np.where(hit, gorder[np.where(hit, match_sorted[:, 0, :], 0)], -1)
    matched = match >= 0
    crowd_hit = matched & gt.iscrowd[np.where(matched, match, 0)] if len(gt) else np.zeros_like(matched)
    dt_tp = matched & ~crowd_hit
    best = np.full((len(gt), len(thr)), -np.inf)
    d_i, t_i = np.nonzero(dt_tp)
    best[match[d_i, t_i], t_i] = dt.score[d_i]
    return TableMatches(iou_thresholds=thr, dt_tp=dt_tp, dt_fp=~matched, gt_best_score=best,
                        gt_object=~gt.iscrowd, dt_matched_gt=np.where(dt_tp, match, -1))


def _ratio(num: np.ndarray, den: np.ndarray) -> list[float | None]:
    return [None if d == 0 else float(n / d) for n, d in zip(num.tolist(), den.tolist(), strict=True)]


def _f1(p: list[float | None], r: list[float | None]) -> list[float | None]:
    return [None if a is None or b is None else (0.0 if a + b == 0 else 2 * a * b / (a + b))
            for a, b in zip(p, r, strict=True)]


def _counts(index: np.ndarray, weights: np.ndarray, size: int) -> np.ndarray:
    """(size, T) int64 per-index sums of (N, T) bool weights."""
    out = np.zeros((size, weights.shape[1]), dtype=np.int64)
    np.add.at(out, index, weights.astype(np.int64))
    return out


def table_rows(gt: GroundTruth, dt: Detections, m: TableMatches, score_threshold: float,
               group_by: str | None = None) -> list[dict[str, Any]]:
    """Rows of the table: (group | all) x (class | all) x IoU, then distance and occlusion bins."""
    groups, img_group = image_groups(gt, group_by)
    n_grp, n_cat = len(groups) + 1, gt.num_categories  # group 0 is "all"
    keep = dt.score >= score_threshold
    gt_tp = m.gt_best_score >= score_threshold
    slot = img_group + 1 if groups else np.zeros_like(img_group)  # slot 0 is "all"
    d_key = slot[dt.image_index] * (n_cat + 1) + dt.category_index + 1
    g_key = slot[gt.image_index] * (n_cat + 1) + gt.category_index + 1
    size = n_grp * (n_cat + 1)
    tp = _counts(d_key, m.dt_tp & keep[:, None], size).reshape(n_grp, n_cat + 1, -1)
    fp = _counts(d_key, m.dt_fp & keep[:, None], size).reshape(n_grp, n_cat + 1, -1)
    fn = _counts(g_key, ~gt_tp & m.gt_object[:, None], size).reshape(n_grp, n_cat + 1, -1)
    for arr in (tp, fp, fn):  # margins: "all" classes, "all" groups
        arr[:, 0] = arr[:, 1:].sum(axis=1)
        if groups:
            arr[0] = arr[1:].sum(axis=0)
    rows = []
    group_names = ["all", *groups]
    class_names = ["all", *gt.category_names]
    for gi, group in enumerate(group_names):
        for ki, cls in enumerate(class_names):
            rows += _rows(group, cls, m.iou_thresholds, tp[gi, ki], fp[gi, ki], fn[gi, ki])
    rows += _bin_rows(gt, m, gt_tp)
    return rows


def _rows(group, cls, thr, tp, fp, fn, with_precision: bool = True) -> list[dict[str, Any]]:
    p = _ratio(tp, tp + fp) if with_precision else [None] * len(thr)
    r = _ratio(tp, tp + fn)
    f = _f1(p, r) if with_precision else [None] * len(thr)
    return [{"group": group, "class": cls, "iou": float(t), "precision": p[i], "recall": r[i], "f1": f[i],
             "tp": int(tp[i]), "fp": int(fp[i]) if with_precision else None, "fn": int(fn[i])}
            for i, t in enumerate(thr)]


def _bin_rows(gt: GroundTruth, m: TableMatches, gt_tp: np.ndarray) -> list[dict[str, Any]]:
    rows = []
    bins = (("distance_m", gt.distance_valid, distance_bins(gt.distance_m)),
            ("height_px", np.ones(len(gt), bool), height_bins(gt.bbox[:, 3])),
            ("occlusion", gt.occlusion_valid, gt.occlusion))
    for prefix, valid, labels in bins:
        valid = valid & m.gt_object
        if not valid.any():
            continue
        for label in sorted(set(labels[valid].tolist()), key=_bin_key):
            in_bin = valid & (labels == label)
            for ki, cls in enumerate(["all", *gt.category_names]):
                sel = in_bin if ki == 0 else in_bin & (gt.category_index == ki - 1)
                if not sel.any():
                    continue
                tp = gt_tp[sel].sum(axis=0)
                fn = (~gt_tp[sel]).sum(axis=0)
                rows += _rows(f"{prefix}:{label}", cls, m.iou_thresholds, tp, np.zeros_like(tp), fn,
                              with_precision=False)
    return rows


_BIN_ORDER = {label: i for i, label in enumerate(
    (*DISTANCE_LABELS, *HEIGHT_LABELS, *OCCLUSION_FRACTION_LABELS, *KITTI_OCCLUSION_LABELS.values()))}


def _bin_key(label: str) -> tuple[int, str]:
    return _BIN_ORDER.get(label, len(_BIN_ORDER)), label
