"""Error breakdown in the spirit of TIDE (Bolya et al. 2020), as counts at IoU 0.5.

Starts from the table's matching at ``fg = 0.5`` and the table's score threshold, so the error counts
partition the table's FP at IoU 0.5 (``fp == duplicate + classification + localisation + both +
background``) and ``missed <= fn``. Each false positive, by its highest IoU with real (non-crowd) ground
truth of the same class (``iou_same``) and of other classes (``iou_other``) in its image, is, in this order:

- duplicate: ``iou_same >= fg`` (the object was already taken by a higher-scored detection);
- classification: ``iou_other >= fg``;
- localisation: ``bg <= iou_same < fg`` (``bg = 0.1``);
- both (classification and localisation): ``bg <= iou_other < fg``;
- background: everything else.

A ground-truth object not found (FN) is *missed* unless it is the best-overlapping target of a
classification, localisation or both error (the detector saw it, wrongly).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from evaluation.box_iou import box_iou_dense
from evaluation.inputs import Detections, GroundTruth
from evaluation.matching import dense_index, segments
from evaluation.table import TableMatches

FG_IOU = 0.5
BG_IOU = 0.1
ERROR_TYPES = ("duplicate", "classification", "localisation", "both", "background")


def _best_overlaps(gt: GroundTruth, dt: Detections, dt_sel: np.ndarray, gt_sel: np.ndarray):
    """For each selected detection: max IoU and its gt index, same class and other class.

    Returns four (len(dt_sel),) arrays: iou_same, arg_same, iou_other, arg_other (arg = gt index, -1 if none).
    """
    n = len(dt_sel)
    out = (np.zeros(n), np.full(n, -1), np.zeros(n), np.full(n, -1))
    if n == 0 or len(gt_sel) == 0:
        return out
    n_img = gt.num_images
    d_order = dt_sel[np.argsort(dt.image_index[dt_sel], kind="stable")]
    g_order = gt_sel[np.argsort(gt.image_index[gt_sel], kind="stable")]
    d_start, d_count = segments(dt.image_index[d_order], n_img)
    g_start, g_count = segments(gt.image_index[g_order], n_img)
    live = np.nonzero((d_count > 0) & (g_count > 0))[0]
    if len(live) == 0:
        return out
    pos = np.empty(len(dt), np.int64)
    pos[dt_sel] = np.arange(n)
    width = 1 << np.ceil(np.log2(g_count[live])).astype(np.int64)
    for w in np.unique(width):
        imgs = live[width == w]
        depth = int(d_count[imgs].max())
        didx = dense_index(d_start[imgs], d_count[imgs], depth)
        gidx = dense_index(g_start[imgs], g_count[imgs], int(w))
        dsafe, gsafe = d_order[np.maximum(didx, 0)], g_order[np.maximum(gidx, 0)]
        iou = box_iou_dense(dt.bbox[dsafe], gt.bbox[gsafe], np.zeros(gsafe.shape, bool))  # (P, D, G)
        iou = np.where((gidx >= 0)[:, None, :], iou, -1.0)
        same = dt.category_index[dsafe][:, :, None] == gt.category_index[gsafe][:, None, :]
        valid = didx >= 0
        target = pos[dsafe[valid]]
        for slot, mask in ((0, same), (2, ~same)):
            masked = np.where(mask, iou, -1.0)
            arg = masked.argmax(axis=2)
            best = np.take_along_axis(masked, arg[..., None], axis=2)[..., 0]
            hit = best >= 0
            out[slot][target] = np.maximum(best, 0.0)[valid]
            out[slot + 1][target] = np.where(hit, gsafe[np.arange(len(imgs))[:, None], arg], -1)[valid]
    return out


def error_breakdown(gt: GroundTruth, dt: Detections, m: TableMatches, score_threshold: float) -> dict[str, Any]:
    """The ``errors`` section of metrics.json: counts overall and per class at IoU ``FG_IOU``."""
    t = np.nonzero(np.isclose(m.iou_thresholds, FG_IOU))[0]
    if len(t) == 0:
        raise ValueError(f"the error breakdown needs the table matched at IoU {FG_IOU}")
    t = int(t[0])
    keep = dt.score >= score_threshold
    fp_idx = np.nonzero(keep & m.dt_fp[:, t])[0]
    iou_same, arg_same, iou_other, arg_other = _best_overlaps(gt, dt, fp_idx, np.nonzero(m.gt_object)[0])
    kind = np.select(
        [iou_same >= FG_IOU, iou_other >= FG_IOU, iou_same >= BG_IOU, iou_other >= BG_IOU],
        [0, 1, 2, 3], default=4,
    )
    target = np.select([kind == 1, kind == 2, kind == 3], [arg_other, arg_same, arg_other], default=-1)
    found = m.gt_best_score[:, t] >= score_threshold
    seen = np.zeros(len(gt), bool)
    seen[target[target >= 0]] = True
    missed = m.gt_object & ~found & ~seen
    n_cat = gt.num_categories
    by_class = np.zeros((n_cat, len(ERROR_TYPES)), dtype=np.int64)
    np.add.at(by_class, (dt.category_index[fp_idx], kind), 1)
    missed_by_class = np.bincount(gt.category_index[missed], minlength=n_cat)

    def counts(row: np.ndarray, n_missed: int) -> dict[str, int]:
        return {**{name: int(v) for name, v in zip(ERROR_TYPES, row, strict=True)}, "missed": int(n_missed)}

    return {
        "iou": FG_IOU,
        "background_iou": BG_IOU,
        "score_threshold": score_threshold,
        "counts": counts(by_class.sum(axis=0), int(missed.sum())),
        "per_class": {name: counts(by_class[k], int(missed_by_class[k])) for k, name in enumerate(gt.category_names)},
        "fp": len(fp_idx),
        "fn": int((m.gt_object & ~found).sum()),
    }
