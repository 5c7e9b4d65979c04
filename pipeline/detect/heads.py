"""Raw detection heads of the common one-stage detector families: input conventions and decoding.

Each family's exported ONNX model ends in one tensor per batch image; the pre-processing it was
trained with is part of the family (:data:`PRESETS`):

- ``yolox`` (Megvii YOLOX, ``decode_in_inference=False`` exports such as ``yolox_nano.onnx``): output
  (B, N, 5 + C), per anchor (x, y, log w, log h, objectness, C class scores), one anchor per cell of
  the stride-8, 16 and 32 grids (in that order, each row-major). Centre = (x + col, y + row) * stride,
  size = exp(log w, log h) * stride, score = objectness * class score. Input BGR, 0-255, letterboxed
  at the top-left on grey 114; class-wise NMS at IoU 0.65.
- ``yolov5`` (Ultralytics YOLOv5 ``export.py``): output (B, 3N, 5 + C) with boxes already decoded,
  (cx, cy, w, h) in input pixels, then objectness and class scores; three anchors per cell.
  Input RGB / 255, letterboxed centred on grey 114; NMS at IoU 0.45.
- ``yolov8`` (Ultralytics YOLOv8/11 ``export``): output (B, 4 + C, N), channels first, (cx, cy, w, h)
  in input pixels then class scores, no objectness. Input as YOLOv5; NMS at IoU 0.7.
- ``decoded``: the model does its own decoding (boxes-scores-classes or an (N, 6) detections tensor;
  see :mod:`pipeline.detect.onnx`); our own exported detector is one.

:func:`guess_family` tells them apart by the output's shape: N equals the number of grid cells of the
input size (YOLOX, or YOLOv8 channels-first) or three times it (YOLOv5). The class of an anchor is
its best class (argmax), as in each family's own post-processing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

Family = Literal["yolox", "yolov5", "yolov8", "decoded"]
FAMILIES: tuple[str, ...] = ("yolox", "yolov5", "yolov8", "decoded")
DEFAULT_STRIDES: tuple[int, ...] = (8, 16, 32)


@dataclass(frozen=True)
class Preset:
    """How a family's images were prepared in training, and its NMS IoU."""

    channels: Literal["rgb", "bgr"]
    scale: float  # network input = pixel (0-255) * scale
    pad_value: float  # 0-255 grey of the letterbox padding
    placement: Literal["top-left", "centre"]
    interpolation: Literal["linear", "area"]
    nms_iou: float | None
    floor_size: bool = False  # resized size int(w * r) (YOLOX's preproc) instead of round(w * r)


PRESETS: dict[str, Preset] = {
    "yolox": Preset("bgr", 1.0, 114.0, "top-left", "linear", 0.65, floor_size=True),
    "yolov5": Preset("rgb", 1.0 / 255.0, 114.0, "centre", "linear", 0.45),
    "yolov8": Preset("rgb", 1.0 / 255.0, 114.0, "centre", "linear", 0.7),
    # Our exported detector: see pipeline.detect.data.letterbox (grey 0.5, INTER_AREA); it does its own decoding.
    "decoded": Preset("rgb", 1.0 / 255.0, 127.5, "top-left", "area", None),
}


def grid_cells(width: int, height: int, strides: tuple[int, ...] = DEFAULT_STRIDES) -> int:
    """Number of cells of all stride grids of a W x H input."""
    return sum((height // s) * (width // s) for s in strides)


def anchor_grid(width: int, height: int, strides: tuple[int, ...] = DEFAULT_STRIDES) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) float32 cell (col, row) of every anchor and its (N, 1) float32 stride, grids in stride order."""
    cells, stride = [], []
    for s in strides:
        rows, cols = np.meshgrid(np.arange(height // s), np.arange(width // s), indexing="ij")
        cells.append(np.stack([cols.ravel(), rows.ravel()], axis=1))
        stride.append(np.full((cols.size, 1), s))
    return np.concatenate(cells).astype(np.float32), np.concatenate(stride).astype(np.float32)


def guess_family(shapes: list[tuple[int, ...]], width: int, height: int,
                 strides: tuple[int, ...] = DEFAULT_STRIDES) -> tuple[str, str]:
    """The family of a model from its (concrete) output shapes and input size, and why.

    Raises ValueError when the shapes fit no family (the message lists them).
    """
    cells = grid_cells(width, height, strides)
    if len(shapes) >= 3:
        return "decoded", f"{len(shapes)} outputs (boxes, scores, classes)"
    if len(shapes) == 1 and len(shapes[0]) == 3:
        _, a, b = shapes[0]
        if a == b == cells:
            raise ValueError(f"output {shapes[0]} fits YOLOX and YOLOv8 for a {width}x{height} input; pass --family")
        if a == cells and b > 5:
            return "yolox", f"output {shapes[0]}: {cells} anchors = grid cells of {width}x{height} at strides {strides}"
        if a == 3 * cells and b > 5:
            return "yolov5", f"output {shapes[0]}: {a} anchors = 3 x grid cells of {width}x{height}"
        if b == cells and a > 4:
            return "yolov8", f"output {shapes[0]}: channels first, {cells} anchors = grid cells of {width}x{height}"
    if len(shapes) == 1 and shapes[0] and shapes[0][-1] in (6, 7):
        return "decoded", f"output {shapes[0]}: one detection (box, score, class) per row"
    raise ValueError(f"output shapes {shapes} fit no known head for a {width}x{height} input at strides {strides} "
                     f"(YOLOX (B, {cells}, 5+C), YOLOv5 (B, {3 * cells}, 5+C), YOLOv8 (B, 4+C, {cells}), "
                     "or decoded outputs); pass --family")


def _check(out: np.ndarray, family: str, axis: int, expected: int, what: str) -> None:
    if out.ndim != 3 or out.shape[axis] != expected:
        raise ValueError(f"{family} head: output shape {out.shape}, expected {expected} {what} on axis {axis}")


def _best_class(cls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = cls.argmax(axis=-1)
    return idx, np.take_along_axis(cls, idx[..., None], axis=-1)[..., 0]


def _cxcywh_to_xyxy(cxcy: np.ndarray, wh: np.ndarray) -> np.ndarray:
    return np.concatenate([cxcy - wh / 2, cxcy + wh / 2], axis=-1)


@dataclass(frozen=True)
class Decoded:
    """Candidates of one image: boxes (K, 4) float64 x1 y1 x2 y2 in input pixels, scores (K,) float64,
    classes (K,) int64 model indices; only anchors scoring >= the threshold."""

    boxes: np.ndarray
    scores: np.ndarray
    classes: np.ndarray


def decode(family: str, out: np.ndarray, width: int, height: int, score_threshold: float,
           strides: tuple[int, ...] = DEFAULT_STRIDES) -> list[Decoded]:
    """Decode a raw head's (B, ...) output tensor into candidates per image (see the module docstring)."""
    cells = grid_cells(width, height, strides)
    if family == "yolov8":
        _check(out, family, 2, cells, "anchors (grid cells)")
        out = out.transpose(0, 2, 1)  # (B, N, 4 + C)
        cls, score = _best_class(out[..., 4:])
        boxes = _cxcywh_to_xyxy(out[..., :2], out[..., 2:4])
    elif family in ("yolox", "yolov5"):
        n = cells if family == "yolox" else 3 * cells
        _check(out, family, 1, n, "anchors")
        cls, best = _best_class(out[..., 5:])
        score = out[..., 4] * best
        if family == "yolox":
            grid, stride = anchor_grid(width, height, strides)
            boxes = _cxcywh_to_xyxy((out[..., :2] + grid) * stride, np.exp(out[..., 2:4]) * stride)
        else:
            boxes = _cxcywh_to_xyxy(out[..., :2], out[..., 2:4])
    else:
        raise ValueError(f"no raw-head decoding for family {family!r} (known: yolox, yolov5, yolov8)")
    result = []
    for b in range(out.shape[0]):
        keep = score[b] >= score_threshold
        result.append(Decoded(boxes[b][keep].astype(np.float64), score[b][keep].astype(np.float64),
                              cls[b][keep].astype(np.int64)))
    return result
