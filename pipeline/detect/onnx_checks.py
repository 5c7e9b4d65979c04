"""What an ONNX detector's options and graph must satisfy before the first image (:mod:`pipeline.detect.onnx`).

The checks that need only the options, or only shapes: the options' ranges (:func:`check_options`), the reading
of a graph shape (:func:`fixed_dim`, :func:`guess_layout`), and what each family's decoding reads from the outputs
(:func:`raw_mismatch`, :func:`decoded_mismatch`: a description of the expected outputs when they are not that).
Messages name the command line's flags; the caller prefixes the model file.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pipeline.detect import heads

if TYPE_CHECKING:
    from pipeline.detect.onnx import OnnxOptions

INPUT_TYPES = ("tensor(float)", "tensor(uint8)")
"""Input element types roadsynth feeds: scaled pixels (float32) or raw pixels (uint8)."""


def check_options(o: OnnxOptions, path: Path) -> None:
    """Refuse options that could only give an error deep inside a run or silently no detections (``path`` names
    the model in the message; the flags are the command line's)."""
    problems = []
    if not (math.isfinite(o.score_threshold) and 0.0 <= o.score_threshold <= 1.0):
        problems.append(f"--score-threshold {o.score_threshold}: expected a score in [0, 1]")
    if o.max_detections < 1:
        problems.append(f"--max-detections {o.max_detections}: expected an integer >= 1")
    if o.nms_iou is not None and not 0.0 < o.nms_iou <= 1.0:
        problems.append(f"--nms-iou {o.nms_iou}: expected an IoU in (0, 1] (1 turns NMS off)")
    if any(not math.isfinite(v) or v == 0.0 for v in o.std):
        problems.append(f"--std {' '.join(map(str, o.std))}: expected finite non-zero divisors")
    if any(not math.isfinite(v) for v in o.mean):
        problems.append(f"--mean {' '.join(map(str, o.mean))}: expected finite values")
    if o.scale is not None and not (math.isfinite(o.scale) and o.scale > 0.0):
        problems.append(f"--scale {o.scale}: expected a finite multiplier > 0")
    if o.pad_value is not None and not 0.0 <= o.pad_value <= 255.0:
        problems.append(f"--pad-value {o.pad_value}: expected a grey level in [0, 255]")
    if not o.strides or any(s < 1 for s in o.strides):
        problems.append(f"--strides {' '.join(map(str, o.strides))}: expected integers >= 1")
    if problems:
        raise ValueError(f"{path}: " + "; ".join(problems))


def fixed_dim(dim: Any) -> int | None:
    """A dimension of a graph shape as an int, None where it is symbolic or unknown (a name, None, <= 0)."""
    return int(dim) if isinstance(dim, (int, np.integer)) and dim > 0 else None


def guess_layout(shape: list) -> str:
    """nhwc where the last axis looks like the channels (3, or a few where axis 1 is wide), else nchw."""
    first, last = fixed_dim(shape[1]), fixed_dim(shape[3])
    if last == 3 and first != 3:
        return "nhwc"
    return "nhwc" if last is not None and last <= 4 and first is not None and first > 4 else "nchw"


def raw_mismatch(family: str, shape: tuple[int, ...], width: int, height: int,
                  strides: tuple[int, ...]) -> str | None:
    """What a raw head's decoding (:func:`pipeline.detect.heads.decode`) reads from its output, when ``shape``
    is not that; None when it is."""
    cells = heads.grid_cells(width, height, strides)
    anchors = 3 * cells if family == "yolov5" else cells
    if family == "yolov8":
        ok = len(shape) == 3 and shape[2] == cells and shape[1] > 4
        expected = f"(B, 4 + C, {cells})"
    else:
        ok = len(shape) == 3 and shape[1] == anchors and shape[2] > 5
        expected = f"(B, {anchors}, 5 + C)"
    return None if ok else f"one output {expected} (anchors of the grids at strides {strides})"


def decoded_mismatch(shapes: list[tuple[int, ...]], output_format: str | None) -> str | None:
    """What a decoded model's reading (``OnnxDetector._decoded``) expects, when ``shapes`` is not that."""
    fmt = output_format or ("boxes-scores-classes" if len(shapes) >= 3 else "detections")
    if fmt == "detections":
        out = shapes[0]
        ok = len(out) in (2, 3) and out[-1] in (6, 7)
        return None if ok else "'detections': one output (B, N, 6) or (N, 6) of box, score, class per row"
    expected = "'boxes-scores-classes': three outputs, boxes (B, N, 4) or (N, 4), scores and classes (B, N) or (N)"
    if len(shapes) < 3:
        return expected
    boxes, scores, classes = (tuple(s) for s in shapes[:3])
    rows = boxes[:-1]
    ok = len(boxes) in (2, 3) and boxes[-1] == 4 and all(s in (rows, (*rows, 1)) for s in (scores, classes))
    return None if ok else expected
