"""Greedy one-to-one matching of detections to ground truth, vectorised over all problems at once.

A *problem* is one (image, category) pair (or one image, for class-agnostic matching). Within a
problem, detections are visited in the order given (callers sort by descending score, ties by file
order); each takes, among ground truths with IoU >= the threshold that are still free, the one with the
highest IoU, preferring *regular* ground truths and falling back to *ignored* ones (crowd regions,
objects outside an area range) only when no regular one qualifies. Among equal IoUs the last ground
truth in file order wins. Crowd regions can be matched any number of times; everything else once.
This is pycocotools' ``evaluateImg`` rule, for every (area range, IoU threshold) pair at once.

The loop runs over detection *rank* (at most the largest problem's detection count), never over
problems: each step matches the d-th detection of every problem in which it overlaps anything.
Problems are bucketed by their ground-truth count rounded up to a power of two so padding stays small.
"""

from __future__ import annotations

import numpy as np

from evaluation.box_iou import box_iou_dense


def segments(problem: np.ndarray, n_problems: int) -> tuple[np.ndarray, np.ndarray]:
    """(P,) start offset and (P,) count of each problem in an array sorted by problem."""
    counts = np.bincount(problem, minlength=n_problems)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    return starts, counts


def dense_index(starts: np.ndarray, counts: np.ndarray, width: int) -> np.ndarray:
    """(P, width) int64 index into the sorted item array, -1 where a problem has fewer items."""
    col = np.arange(width)
    idx = starts[:, None] + col[None, :]
    return np.where(col[None, :] < counts[:, None], idx, -1)


def greedy_match(
    dt_problem: np.ndarray,
    dt_boxes: np.ndarray,
    gt_problem: np.ndarray,
    gt_boxes: np.ndarray,
    gt_crowd: np.ndarray,
    gt_ignore: np.ndarray,
    thresholds: np.ndarray,
    n_problems: int,
) -> np.ndarray:
    """Match detections to ground truth for every (ignore setting, IoU threshold).

    Args:
        dt_problem: (Nd,) int64 problem of each detection; sorted, and within a problem in matching order.
        dt_boxes: (Nd, 4) float64 xywh.
        gt_problem: (Ng,) int64 problem of each ground truth; sorted, and within a problem in file order.
        gt_boxes: (Ng, 4) float64 xywh.
        gt_crowd: (Ng,) bool crowd regions (IoU is intersection over detection area; reusable).
        gt_ignore: (Ng, A) bool ignored ground truths per setting (crowd regions must be ignored).
        thresholds: (T,) float64 IoU thresholds, > 0; a match needs IoU >= threshold.
        n_problems: number of problems (problem indices are < n_problems).

    Returns:
        (Nd, A, T) int64 index of the matched ground truth (into the gt arrays), -1 where unmatched.
    """
    thresholds = np.asarray(thresholds, dtype=np.float64)
    if (thresholds <= 0).any():
        raise ValueError(f"IoU thresholds must be > 0, got {thresholds.tolist()}")
    n_settings = gt_ignore.shape[1]
    out = np.full((len(dt_problem), n_settings, len(thresholds)), -1, dtype=np.int64)
    dt_start, dt_count = segments(dt_problem, n_problems)
    gt_start, gt_count = segments(gt_problem, n_problems)
    live = np.nonzero((dt_count > 0) & (gt_count > 0))[0]
    if len(live) == 0:
        return out
    width = 1 << np.ceil(np.log2(gt_count[live])).astype(np.int64)
    for w in np.unique(width):
        bucket = live[width == w]
        bucket = bucket[np.argsort(-dt_count[bucket], kind="stable")]
        _match_bucket(out, bucket, int(w), dt_start, dt_count, gt_start, gt_count, dt_boxes, gt_boxes, gt_crowd,
                      gt_ignore, thresholds)
    return out


def _match_bucket(out, bucket, width, dt_start, dt_count, gt_start, gt_count, dt_boxes, gt_boxes, gt_crowd,
                  gt_ignore, thresholds) -> None:
    depth = int(dt_count[bucket[0]])
    didx = dense_index(dt_start[bucket], dt_count[bucket], depth)
    gidx = dense_index(gt_start[bucket], gt_count[bucket], width)
    gvalid = gidx >= 0
    gsafe = np.where(gvalid, gidx, 0)
    iou = box_iou_dense(dt_boxes[np.where(didx >= 0, didx, 0)], gt_boxes[gsafe], gt_crowd[gsafe])
    iou[~np.broadcast_to(gvalid[:, None, :], iou.shape)] = -np.inf
    iou[didx < 0] = -np.inf
    candidate = (iou >= thresholds.min()).any(axis=2)  # (P, D): does the detection reach anything?
    crowd = gt_crowd[gsafe] & gvalid  # (P, G)
    ignore = np.transpose(gt_ignore[gsafe], (0, 2, 1))  # (P, A, G)
    n_set, n_thr = gt_ignore.shape[1], len(thresholds)
    taken = np.zeros((len(bucket), n_set, n_thr, width), dtype=bool)
    thr = thresholds[None, None, :, None]
    for d in range(depth):
        rows = np.nonzero(candidate[:, d])[0]
        if len(rows) == 0:
            continue
        iou_d = iou[rows, d][:, None, None, :]  # (r, 1, 1, G)
        free = ~(taken[rows] & ~crowd[rows][:, None, None, :])
        ok = (iou_d >= thr) & free  # (r, A, T, G)
        ign = ignore[rows][:, :, None, :]
        choice = _last_argmax(np.where(ok & ~ign, iou_d, -1.0))
        fallback = _last_argmax(np.where(ok & ign, iou_d, -1.0))
        choice = np.where(choice >= 0, choice, fallback)  # (r, A, T)
        r_i, a_i, t_i = np.nonzero(choice >= 0)
        g_i = choice[r_i, a_i, t_i]
        taken[rows[r_i], a_i, t_i, g_i] = True
        out[didx[rows[r_i], d], a_i, t_i] = gidx[rows[r_i], g_i]


def _last_argmax(key: np.ndarray) -> np.ndarray:
    """Index of the last maximum along the last axis where the maximum is >= 0, else -1."""
    width = key.shape[-1]
    rev = key[..., ::-1]
    pos = width - 1 - rev.argmax(axis=-1)
    best = np.take_along_axis(key, pos[..., None], axis=-1)[..., 0]
    return np.where(best >= 0, pos, -1)
