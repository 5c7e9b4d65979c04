"""CenterNet targets and losses, with TTFNet-style dense box regression.

Targets (:func:`build_targets`, numpy, one image; shapes at stride 4 with ``h, w`` cells):

- ``heatmap`` ``(C, h, w) float32``: per class the max over its objects of an elliptical Gaussian
  centred on the object's centre cell, sigma = ``alpha`` * box size / 6, at least ``min_sigma`` cells
  (TTFNet's shape: elongated boxes get elongated peaks); exactly 1 at every centre cell. TTFNet's
  alpha is 0.54; the detector config uses a broader 2.0 (``train.gaussian_alpha``): a small network
  cannot place the centre of a large object to the cell, and with a sharp target it hedges, so even
  easy nearby vehicles scored ~0.3-0.45 (the broad peak lifted the median score of unoccluded vehicles
  within 30 m from 0.39 to 0.69 in a sweep on held-out runs).
- ``ignore`` ``(h, w) bool``: cells whose centre lies in a crowd (ignore) region; their negative
  heatmap loss is dropped (a detection there is neither right nor wrong).
- ``size`` / ``offset`` ``(2, h, w) float32``: log(w/4), log(h/4) of a box and its centre relative to
  the cell, ``(cx/4 - j, cy/4 - i)`` (in [0, 1) at the centre cell, beyond it elsewhere).
- ``reg_weight`` ``(h, w) float32``: where the box is regressed. Every cell whose index lies within
  ``REG_AREA`` / 2 of a box's size from its centre cell regresses that box, weighted by the heatmap
  Gaussian and normalised so that each object's weights sum to 1. A peak found a cell or two off the
  centre (common for large objects) then still carries a trained box; where regions overlap, the
  smaller box wins.
- ``reg_mask`` ``(h, w) bool``: the centre cells (one per object unless two share a cell).

Losses (:func:`detection_loss`): CenterNet's penalty-reduced focal loss (alpha 2, beta 4), L1 on log
size and L1 on the centre offset relative to the box size (at least one cell), the last two weighted
by ``reg_weight``; each normalised by the number of objects in the batch.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.nn import functional as F

from pipeline.detect.model import STRIDE

GAUSSIAN_ALPHA = 2.0  # the detector config's default (train.gaussian_alpha)
MIN_SIGMA_CELLS = 1.0  # train.min_sigma_cells
REG_AREA = 0.54
SIZE_WEIGHT = 1.0
OFFSET_WEIGHT = 1.0


def _regression_weights(col: np.ndarray, row: np.ndarray, bw: np.ndarray, bh: np.ndarray,
                        ex: np.ndarray, ey: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell the owning object (h, w) int64 (-1: none) and its weight (h, w) float32.

    Objects come sorted by descending area, so the last object covering a cell is the smallest.
    """
    n, w = ex.shape
    h = ey.shape[1]
    in_x = np.abs(np.arange(w)[None] - col[:, None]) <= REG_AREA * bw[:, None] / 2  # (N, w)
    in_y = np.abs(np.arange(h)[None] - row[:, None]) <= REG_AREA * bh[:, None] / 2  # (N, h)
    gauss = (ey * in_y)[:, :, None] * (ex * in_x)[:, None, :]  # (N, h, w), 1 at each centre cell
    covered = gauss > 0
    owner = n - 1 - np.argmax(covered[::-1], axis=0)
    owner = np.where(covered.any(axis=0), owner, -1)
    total = gauss.reshape(n, -1).sum(axis=1)  # >= 1: the centre cell is always inside
    safe = np.maximum(owner, 0)
    weight = np.take_along_axis(gauss, safe[None], axis=0)[0] / total[safe]
    return owner, np.where(owner >= 0, weight, 0.0).astype(np.float32)


def build_targets(boxes: np.ndarray, labels: np.ndarray, ignore: np.ndarray, num_classes: int,
                  out_hw: tuple[int, int], alpha: float = GAUSSIAN_ALPHA,
                  min_sigma: float = MIN_SIGMA_CELLS) -> dict[str, np.ndarray]:
    """Targets of one image from ``boxes`` (N, 4) x1 y1 x2 y2 input pixels, ``labels`` (N,), ``ignore`` (M, 4).

    ``alpha`` and ``min_sigma`` shape the heatmap Gaussians (module docstring).
    """
    h, w = out_hw
    gy, gx = np.arange(h, dtype=np.float32), np.arange(w, dtype=np.float32)
    heat = np.zeros((num_classes, h, w), np.float32)
    size = np.zeros((2, h, w), np.float32)
    offset = np.zeros((2, h, w), np.float32)
    reg_mask = np.zeros((h, w), bool)
    reg_weight = np.zeros((h, w), np.float32)
    if len(boxes):
        order = np.argsort(-(boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1]), kind="stable")
        boxes, labels = boxes[order], labels[order]
        bw = np.maximum(boxes[:, 2] - boxes[:, 0], 1e-3) / STRIDE
        bh = np.maximum(boxes[:, 3] - boxes[:, 1], 1e-3) / STRIDE
        cx = (boxes[:, 0] + boxes[:, 2]) / (2 * STRIDE)
        cy = (boxes[:, 1] + boxes[:, 3]) / (2 * STRIDE)
        col = np.clip(np.floor(cx), 0, w - 1).astype(np.int64)
        row = np.clip(np.floor(cy), 0, h - 1).astype(np.int64)
        sx = np.maximum(alpha * bw / 6, min_sigma)[:, None]
        sy = np.maximum(alpha * bh / 6, min_sigma)[:, None]
        ex = np.exp(-((gx[None] - col[:, None]) ** 2) / (2 * sx**2))  # (N, w)
        ey = np.exp(-((gy[None] - row[:, None]) ** 2) / (2 * sy**2))  # (N, h)
        np.maximum.at(heat, labels, ey[:, :, None] * ex[:, None, :])
        heat[labels, row, col] = 1.0
        owner, reg_weight = _regression_weights(col, row, bw, bh, ex, ey)
        safe = np.maximum(owner, 0)
        size = np.log(np.stack([bw[safe], bh[safe]])).astype(np.float32) * (owner >= 0)
        offset = np.stack([cx[safe] - gx[None, :], cy[safe] - gy[:, None]]).astype(np.float32) * (owner >= 0)
        reg_mask[row, col] = True
    ignore_mask = np.zeros((h, w), bool)
    if len(ignore):
        px, py = (gx + 0.5) * STRIDE, (gy + 0.5) * STRIDE
        in_x = (px[None] >= ignore[:, 0:1]) & (px[None] < ignore[:, 2:3])  # (M, w)
        in_y = (py[None] >= ignore[:, 1:2]) & (py[None] < ignore[:, 3:4])  # (M, h)
        ignore_mask = (in_y[:, :, None] & in_x[:, None, :]).any(axis=0)
    return {"heatmap": heat, "ignore": ignore_mask, "size": size, "offset": offset, "reg_mask": reg_mask,
            "reg_weight": reg_weight}


def collate_targets(targets: list[dict[str, np.ndarray]]) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(np.stack([t[k] for t in targets])) for k in targets[0]}


def focal_loss(logits: torch.Tensor, target: torch.Tensor, ignore: torch.Tensor) -> torch.Tensor:
    """Sum of CenterNet's focal loss over (B, C, h, w); negatives in ``ignore`` (B, h, w) are dropped."""
    pos = target.eq(1.0)
    p = torch.sigmoid(logits)
    pos_term = F.logsigmoid(logits) * (1 - p) ** 2
    neg_term = F.logsigmoid(-logits) * p**2 * (1 - target) ** 4
    neg_term = neg_term * (~ignore).unsqueeze(1).to(neg_term.dtype)
    return -(torch.where(pos, pos_term, neg_term)).sum()


def detection_loss(outputs: dict[str, torch.Tensor], targets: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """``{"loss", "heatmap", "size", "offset"}``, each a scalar; ``loss`` is the weighted total."""
    num = targets["reg_mask"].sum().clamp(min=1).to(outputs["heatmap"].dtype)
    heat = focal_loss(outputs["heatmap"], targets["heatmap"], targets["ignore"]) / num
    weight = targets["reg_weight"].unsqueeze(1).to(outputs["size"].dtype)
    size = (F.l1_loss(outputs["size"], targets["size"], reduction="none") * weight).sum() / num
    # Centre error relative to the box (at least a cell): equally strict for small and large objects.
    scale = torch.exp(targets["size"]).clamp(min=1.0)
    offset_error = F.l1_loss(outputs["offset"], targets["offset"], reduction="none") / scale
    offset = (offset_error * weight).sum() / num
    total = heat + SIZE_WEIGHT * size + OFFSET_WEIGHT * offset
    return {"loss": total, "heatmap": heat, "size": size, "offset": offset}
