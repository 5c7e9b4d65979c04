"""Axis-aligned 2D box IoU in COCO ``xywh``, bit-identical to pycocotools' ``maskUtils.iou`` for boxes.

The arithmetic follows the same IEEE operations in the same order (``w = min(x1+w1, x2+w2) - max(x1, x2)``,
zero when ``w <= 0`` or ``h <= 0``, ``union = area_dt + area_gt - inter``), so a detection at an IoU
exactly on a threshold is matched the same way. Against a crowd region the union is the detection's
own area (``inter / area_dt``): a detection inside a crowd has IoU 1 with it. Areas are ``w * h`` of the
boxes, not COCO's ``area`` field.
"""

from __future__ import annotations

import numpy as np


def box_iou_dense(dt: np.ndarray, gt: np.ndarray, crowd: np.ndarray) -> np.ndarray:
    """IoU of every detection with every ground truth, batched.

    Args:
        dt: (..., D, 4) float64 detection boxes xywh.
        gt: (..., G, 4) float64 ground-truth boxes xywh (same leading shape as ``dt``).
        crowd: (..., G) bool; crowd columns use the detection's area as the union.

    Returns:
        (..., D, G) float64 IoU in [0, 1].
    """
    d = dt[..., :, None, :]
    g = gt[..., None, :, :]
    w = np.minimum(d[..., 2] + d[..., 0], g[..., 2] + g[..., 0]) - np.maximum(d[..., 0], g[..., 0])
    h = np.minimum(d[..., 3] + d[..., 1], g[..., 3] + g[..., 1]) - np.maximum(d[..., 1], g[..., 1])
    inter = w * h
    da = d[..., 2] * d[..., 3]
    ga = g[..., 2] * g[..., 3]
    union = np.where(crowd[..., None, :], da, da + ga - inter)
    overlap = (w > 0) & (h > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        iou = inter / union
    return np.where(overlap, iou, 0.0)


def box_iou(dt: np.ndarray, gt: np.ndarray, crowd: np.ndarray | None = None) -> np.ndarray:
    """(N, M) float64 IoU of (N, 4) detections with (M, 4) ground truths (xywh); ``crowd`` is (M,) bool."""
    if crowd is None:
        crowd = np.zeros(len(gt), dtype=bool)
    return box_iou_dense(np.asarray(dt, np.float64), np.asarray(gt, np.float64), np.asarray(crowd, bool))
