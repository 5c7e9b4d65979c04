"""The baseline detector network: a small conv backbone, a top-down neck, CenterNet-style heads.

Conventions:

- Input: ``(B, 3, H, W) float32`` RGB in [0, 1] (the network normalises internally, so the ONNX
  export and every caller feed plain scaled pixels), H and W multiples of 32.
- Outputs at stride :data:`STRIDE` = 4, ``h = H/4``, ``w = W/4``: ``heatmap`` ``(B, C, h, w)``
  logits (one channel per class), ``size`` ``(B, 2, h, w)`` = log(box width / 4), log(box height / 4),
  ``offset`` ``(B, 2, h, w)`` = position of the box centre relative to the cell, in cells (in [0, 1)
  at the centre cell; other cells near the centre predict the same box, see
  :mod:`pipeline.detect.losses`).
- A cell (i, j) covers input pixels [4j, 4j+4) x [4i, 4i+4); a box centre (cx, cy) lies in the
  cell (floor(cy/4), floor(cx/4)) with offset (cx/4 - j, cy/4 - i).
- :func:`decode` turns outputs into ``candidates`` boxes per image ``(B, K, 4)`` x1, y1, x2, y2 in
  input pixels, scores ``(B, K)`` (sigmoid of the peak) and class indices ``(B, K) int64``. Each cell
  keeps only its most likely class, and a peak is a cell whose score equals the 3x3 max of these
  per-cell scores, so one object yields one peak whatever the classes disagree on. It is traced into
  the ONNX export; NMS is not.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from pipeline.core.config import BackboneConfig

STRIDE = 4
MEAN = (0.485, 0.456, 0.406)
STD = (0.229, 0.224, 0.225)
# Focal-loss prior: the heatmap starts at sigmoid(-2.19) = 0.1 (CenterNet's initialisation).
HEATMAP_PRIOR_BIAS = -2.19


def conv_bn(c_in: int, c_out: int, stride: int = 1, kernel: int = 3) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, kernel, stride=stride, padding=kernel // 2, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=True),
    )


class Backbone(nn.Module):
    """Five stride-2 stages (strides 2..32), each a strided 3x3 conv then a 3x3 conv (BN, ReLU)."""

    def __init__(self, widths: tuple[int, ...]):
        super().__init__()
        stages, c_in = [], 3
        for i, c in enumerate(widths):
            layers = [conv_bn(c_in, c, stride=2)]
            if i > 0:  # the stem stays a single conv: at stride 2 it is the costliest layer
                layers.append(conv_bn(c, c))
            stages.append(nn.Sequential(*layers))
            c_in = c
        self.stages = nn.ModuleList(stages)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        feats = []
        for stage in self.stages:
            x = stage(x)
            feats.append(x)
        return feats  # strides 2, 4, 8, 16, 32


class Neck(nn.Module):
    """Top-down path (FPN-like): stride 32 -> 16 -> 8 with ``neck`` channels, then to stride 4."""

    def __init__(self, widths: tuple[int, ...], neck: int, head: int):
        super().__init__()
        self.lateral = nn.ModuleList([conv_bn(widths[i], neck, kernel=1) for i in (4, 3, 2)])
        self.smooth = nn.ModuleList([conv_bn(neck, neck) for _ in (3, 2)])
        self.lateral4 = conv_bn(widths[1], head, kernel=1)
        self.reduce4 = conv_bn(neck, head, kernel=1)
        self.smooth4 = conv_bn(head, head)

    def forward(self, feats: list[torch.Tensor]) -> torch.Tensor:
        x = self.lateral[0](feats[4])
        for lateral, smooth, feat in zip(self.lateral[1:], self.smooth, (feats[3], feats[2]), strict=True):
            x = smooth(lateral(feat) + F.interpolate(x, scale_factor=2.0, mode="nearest"))
        x = self.reduce4(F.interpolate(x, scale_factor=2.0, mode="nearest"))
        return self.smooth4(x + self.lateral4(feats[1]))


class CenterNet(nn.Module):
    """Backbone + neck + three 1x1 heads on one shared 3x3 conv. See the module docstring for I/O."""

    def __init__(self, num_classes: int, backbone: BackboneConfig):
        super().__init__()
        self.num_classes = num_classes
        self.register_buffer("mean", torch.tensor(MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(STD).view(1, 3, 1, 1), persistent=False)
        self.backbone = Backbone(backbone.widths)
        self.neck = Neck(backbone.widths, backbone.neck_channels, backbone.head_channels)
        c = backbone.head_channels
        self.shared = conv_bn(c, c)
        self.heatmap = nn.Conv2d(c, num_classes, 1)
        self.size = nn.Conv2d(c, 2, 1)
        self.offset = nn.Conv2d(c, 2, 1)
        nn.init.constant_(self.heatmap.bias, HEATMAP_PRIOR_BIAS)
        nn.init.normal_(self.size.weight, std=0.01)
        nn.init.constant_(self.size.bias, 1.0)  # exp(1) * 4 = an 11 px box to start from
        nn.init.normal_(self.offset.weight, std=0.01)
        nn.init.constant_(self.offset.bias, 0.5)  # the middle of the centre cell

    def forward(self, images: torch.Tensor) -> dict[str, torch.Tensor]:
        x = (images - self.mean) / self.std
        x = self.shared(self.neck(self.backbone(x)))
        return {"heatmap": self.heatmap(x), "size": self.size(x), "offset": self.offset(x)}


def decode(outputs: dict[str, torch.Tensor], candidates: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Top ``candidates`` heatmap peaks per image as boxes (B, K, 4), scores (B, K), classes (B, K)."""
    # One class per cell, the most likely: car and truck peaks at the same place are one object.
    heat, best = torch.sigmoid(outputs["heatmap"]).max(dim=1, keepdim=True)  # (B, 1, h, w): 4-D for MaxPool
    b, _, h, w = heat.shape
    peaks = heat * (F.max_pool2d(heat, 3, stride=1, padding=1) == heat).to(heat.dtype)
    k = min(candidates, h * w)
    scores, cell = torch.topk(peaks.reshape(b, -1), k)
    classes = torch.gather(best.reshape(b, -1), 1, cell)
    row = torch.div(cell, w, rounding_mode="floor")
    col = cell - row * w
    size = outputs["size"].reshape(b, 2, h * w)
    offset = outputs["offset"].reshape(b, 2, h * w)
    gather = cell.unsqueeze(1).expand(b, 2, k)
    wh = torch.exp(torch.gather(size, 2, gather).clamp(max=8.0)) * STRIDE
    off = torch.gather(offset, 2, gather)
    cx = (col.to(heat.dtype) + off[:, 0]) * STRIDE
    cy = (row.to(heat.dtype) + off[:, 1]) * STRIDE
    boxes = torch.stack([cx - wh[:, 0] / 2, cy - wh[:, 1] / 2, cx + wh[:, 0] / 2, cy + wh[:, 1] / 2], dim=-1)
    return boxes, scores, classes


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
