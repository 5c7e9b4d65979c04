"""COCO bbox AP/AR, identical to pycocotools' ``COCOeval`` (stats and precision array to 1e-12).

Three steps, as in nuscenes-devkit: :func:`accumulate_coco` matches and builds the precision/recall
arrays (serialisable curve data), :func:`summarize_coco` turns them into the 12 stats and per-class AP,
and rendering reads only the saved arrays. The pycocotools semantics reproduced (see README.md):

- problems are (image, category); detections sorted by descending score, ties in file order (stable);
  at most ``max_dets[-1]`` detections per image per category, the smaller limits taken afterwards;
- ground truth is ignored when crowd (``iscrowd``) or when its ``area`` field is outside the area range,
  both ends inclusive; a detection matched to an ignored ground truth is ignored, and an unmatched one
  is ignored when its ``w*h`` is outside the range;
- thresholds are capped at ``1 - 1e-10``; recall thresholds ``np.linspace(0, 1, 101)``; precision made
  monotone from the right, then sampled at the first detection whose recall reaches each threshold
  (0 beyond the last); ``-1`` where a category has no non-ignored ground truth;
- precision ``tp / (tp + fp + eps)`` with ``eps = np.spacing(1)``, in float64, in the same order.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from evaluation.inputs import Detections, GroundTruth
from evaluation.matching import greedy_match

STAT_NAMES = (
    "AP", "AP50", "AP75", "AP_small", "AP_medium", "AP_large",
    "AR1", "AR10", "AR100", "AR_small", "AR_medium", "AR_large",
)  # fmt: skip


@dataclasses.dataclass(frozen=True)
class CocoParams:
    """Evaluation parameters; the defaults are pycocotools' bbox defaults (the 12 stats assume them)."""

    iou_thresholds: np.ndarray = dataclasses.field(
        default_factory=lambda: np.linspace(0.5, 0.95, int(np.round((0.95 - 0.5) / 0.05)) + 1, endpoint=True)
    )
    rec_thresholds: np.ndarray = dataclasses.field(
        default_factory=lambda: np.linspace(0.0, 1.00, int(np.round((1.00 - 0.0) / 0.01)) + 1, endpoint=True)
    )
    area_ranges: tuple[tuple[float, float], ...] = ((0, 1e5**2), (0, 32**2), (32**2, 96**2), (96**2, 1e5**2))
    area_labels: tuple[str, ...] = ("all", "small", "medium", "large")
    max_dets: tuple[int, ...] = (1, 10, 100)

    def __post_init__(self) -> None:
        if len(self.area_ranges) != len(self.area_labels):
            raise ValueError("area_ranges and area_labels differ in length")
        if list(self.max_dets) != sorted(self.max_dets) or min(self.max_dets) < 1:
            raise ValueError(f"max_dets must be ascending positive integers, got {self.max_dets}")


@dataclasses.dataclass(frozen=True)
class CocoAccumulation:
    """Curve data of a COCO evaluation.

    Attributes:
        precision: (T, R, K, A, M) float64, pycocotools' ``eval['precision']``; -1 where undefined.
        recall: (T, K, A, M) float64, pycocotools' ``eval['recall']``; -1 where undefined.
        num_gt: (K, A) int64 non-ignored ground truths per category and area range.
        num_dt: (K,) int64 detections per category kept (after the per-image ``max_dets[-1]`` limit).
        dropped_beyond_max_dets: detections beyond ``max_dets[-1]`` per image and category (not scored).
    """

    params: CocoParams
    precision: np.ndarray
    recall: np.ndarray
    num_gt: np.ndarray
    num_dt: np.ndarray
    dropped_beyond_max_dets: int


def sort_detections(problem: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Order detections by (problem, descending score, file order); return (order, rank within problem)."""
    order = np.lexsort((np.arange(len(score)), -score, problem))
    sorted_problem = problem[order]
    n = len(order)
    if n == 0:
        return order, np.zeros(0, np.int64)
    first = np.r_[True, sorted_problem[1:] != sorted_problem[:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(n), 0))
    return order, np.arange(n) - start


def match_coco(gt: GroundTruth, dt: Detections, params: CocoParams):
    """Match per (image, category) for every area range and threshold.

    Returns (kept detection indices (Nk,), their rank (Nk,), dt_matched (Nk, A, T) bool,
    dt_ignored (Nk, A, T) bool, gt_ignore (Ng, A) bool in gt order).
    """
    n_img = gt.num_images
    dt_problem = dt.category_index * n_img + dt.image_index
    order, rank = sort_detections(dt_problem, dt.score)
    keep = rank < params.max_dets[-1]
    kept, rank = order[keep], rank[keep]

    lo = np.array([a[0] for a in params.area_ranges], dtype=np.float64)
    hi = np.array([a[1] for a in params.area_ranges], dtype=np.float64)
    gt_ignore = gt.iscrowd[:, None] | (gt.area[:, None] < lo) | (gt.area[:, None] > hi)  # (Ng, A)
    gt_problem = gt.category_index * n_img + gt.image_index
    gorder = np.argsort(gt_problem, kind="stable")
    thresholds = np.minimum(params.iou_thresholds, 1 - 1e-10)
    match = greedy_match(dt_problem[kept], dt.bbox[kept], gt_problem[gorder], gt.bbox[gorder], gt.iscrowd[gorder],
                         gt_ignore[gorder], thresholds, gt.num_categories * n_img)
    matched = match >= 0
    a_idx = np.arange(len(params.area_ranges))[None, :, None]
    matched_ignored = gt_ignore[gorder][np.where(matched, match, 0), a_idx] if len(gorder) else np.zeros_like(matched)
    area = dt.area[kept]
    outside = (area[:, None] < lo) | (area[:, None] > hi)  # (Nk, A)
    ignored = np.where(matched, matched_ignored, outside[:, :, None])
    return kept, rank, matched, ignored, gt_ignore


def accumulate_coco(gt: GroundTruth, dt: Detections, params: CocoParams | None = None) -> CocoAccumulation:
    """Match and accumulate: pycocotools' ``evaluate()`` + ``accumulate()`` for iouType ``bbox``."""
    params = params or CocoParams()
    kept, rank, matched, ignored, gt_ignore = match_coco(gt, dt, params)
    n_thr, n_rec = len(params.iou_thresholds), len(params.rec_thresholds)
    n_cat, n_area, n_max = gt.num_categories, len(params.area_ranges), len(params.max_dets)
    precision = -np.ones((n_thr, n_rec, n_cat, n_area, n_max))
    recall = -np.ones((n_thr, n_cat, n_area, n_max))
    num_gt = np.zeros((n_cat, n_area), dtype=np.int64)
    np.add.at(num_gt, gt.category_index, (~gt_ignore).astype(np.int64))

    cat = dt.category_index[kept]
    score = dt.score[kept]
    # Stable on an array already in (category, image, rank) order: pycocotools' tie order.
    order = np.lexsort((-score, cat))
    tps_all = matched & ~ignored
    fps_all = ~matched & ~ignored
    for m, max_det in enumerate(params.max_dets):
        sel = order[rank[order] < max_det]
        cat_sel = cat[sel]
        bounds = np.searchsorted(cat_sel, np.arange(n_cat + 1))
        tps, fps = tps_all[sel], fps_all[sel]
        for k in range(n_cat):
            areas = np.nonzero(num_gt[k] > 0)[0]
            if len(areas) == 0:
                continue
            lo, hi = bounds[k], bounds[k + 1]
            tp = np.cumsum(tps[lo:hi][:, areas], axis=0, dtype=np.int64).astype(np.float64)
            fp = np.cumsum(fps[lo:hi][:, areas], axis=0, dtype=np.int64).astype(np.float64)
            q, rc = _curves(tp, fp, num_gt[k, areas], params.rec_thresholds)
            precision[:, :, k, areas, m] = q
            recall[:, k, areas, m] = rc
    return CocoAccumulation(params=params, precision=precision, recall=recall, num_gt=num_gt,
                            num_dt=np.bincount(cat, minlength=n_cat), dropped_beyond_max_dets=len(dt) - len(kept))


def _curves(tp: np.ndarray, fp: np.ndarray, npig: np.ndarray, rec_thresholds: np.ndarray):
    """Precision at recall thresholds and final recall of one category.

    Args:
        tp, fp: (n, A, T) float64 cumulative true / false positive counts in score order.
        npig: (A,) int64 non-ignored ground truths (> 0).
        rec_thresholds: (R,) float64.

    Returns:
        precision (T, R, A) float64 and recall (T, A) float64.
    """
    n, n_area, n_thr = tp.shape
    rc = tp / npig[None, :, None]
    pr = tp / (fp + tp + np.spacing(1))
    recall = rc[-1].T if n else np.zeros((n_thr, n_area))
    envelope = np.maximum.accumulate(pr[::-1], axis=0)[::-1]
    q = np.zeros((n_thr, len(rec_thresholds), n_area))
    for a in range(n_area):
        for t in range(n_thr):
            inds = np.searchsorted(rc[:, a, t], rec_thresholds, side="left")
            valid = inds < n
            q[t, valid, a] = envelope[inds[valid], a, t]
    return q, recall


def _summarize(acc: CocoAccumulation, ap: bool, iou: float | None = None, area: str = "all", max_dets: int = 100,
               k: int | slice = slice(None)) -> float:
    """One summary number: the mean of the defined (> -1) entries, -1 when there are none (pycocotools)."""
    p = acc.params
    aind = [i for i, label in enumerate(p.area_labels) if label == area]
    mind = [i for i, m in enumerate(p.max_dets) if m == max_dets]
    s = acc.precision if ap else acc.recall
    if iou is not None:
        s = s[np.where(iou == p.iou_thresholds)[0]]
    s = s[:, :, k, aind, mind] if ap else s[:, k, aind, mind]
    defined = s[s > -1]
    return -1.0 if len(defined) == 0 else float(np.mean(defined))


def coco_stats(acc: CocoAccumulation) -> list[float]:
    """The 12 stats in pycocotools' order (:data:`STAT_NAMES`); -1 where undefined."""
    big = acc.params.max_dets[-1]
    specs = [(True, None, "all", big), (True, 0.5, "all", big), (True, 0.75, "all", big),
             (True, None, "small", big), (True, None, "medium", big), (True, None, "large", big)]
    specs += [(False, None, "all", m) for m in acc.params.max_dets]
    specs += [(False, None, "small", big), (False, None, "medium", big), (False, None, "large", big)]
    return [_summarize(acc, *spec) for spec in specs]


def coco_stats_by_group(gt: GroundTruth, dt: Detections, group_index: np.ndarray, group_names: list[str],
                        params: CocoParams | None = None) -> dict[str, list[float]]:
    """The 12 stats of each image group, each group's images evaluated on their own (as if the files held only
    them: pycocotools on that subset gives the same numbers).

    Args:
        group_index: (I,) int64 group of each ground-truth image, an index into ``group_names``.
        group_names: the group labels.
    """
    out = {}
    for g, name in enumerate(group_names):
        keep = group_index == g
        out[name] = coco_stats(accumulate_coco(gt.select_images(keep), dt.select_images(keep), params))
    return out


def summarize_coco(acc: CocoAccumulation, category_names: list[str]) -> dict:
    """The 12 stats in pycocotools' order and per-class AP: the ``coco`` section of metrics.json.

    Per class: ``ap`` (0.5:0.95), ``ap50``, ``ap75``, ``ap_small/medium/large``, ``ar100`` are
    pycocotools' numbers restricted to the class (-1 where it has no non-ignored ground truth, as
    pycocotools reports; ``valid`` says so explicitly), ``num_gt`` and ``num_dt`` are counts.
    """
    big = acc.params.max_dets[-1]
    stats = coco_stats(acc)
    per_class = {}
    for k, name in enumerate(category_names):
        sl = slice(k, k + 1)
        per_class[name] = {
            "ap": _summarize(acc, True, None, "all", big, sl),
            "ap50": _summarize(acc, True, 0.5, "all", big, sl),
            "ap75": _summarize(acc, True, 0.75, "all", big, sl),
            "ap_small": _summarize(acc, True, None, "small", big, sl),
            "ap_medium": _summarize(acc, True, None, "medium", big, sl),
            "ap_large": _summarize(acc, True, None, "large", big, sl),
            "ar100": _summarize(acc, False, None, "all", big, sl),
            "num_gt": int(acc.num_gt[k, 0]),
            "num_dt": int(acc.num_dt[k]),
            "valid": bool(acc.num_gt[k, 0] > 0),
        }
    return {"stats": stats, "names": list(STAT_NAMES), "per_class": per_class}
