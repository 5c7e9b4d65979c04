"""ONNX: export our detector, and run any ONNX detector (onnxruntime) into COCO results.

**Families** (:mod:`pipeline.detect.heads`): raw heads of ``yolox``, ``yolov5`` and ``yolov8`` are
decoded here (grids, objectness, best class); ``decoded`` models do their own decoding. ``auto`` (the
default) picks the family from the output shapes of one run on a blank image and logs why. The family
sets the pre-processing it was trained with (channel order, pixel scale, letterbox grey and placement,
interpolation) and its NMS IoU; every one can be overridden (:class:`OnnxOptions`).

**Expected model I/O**:

- one image input: ``nchw`` (B, 3, H, W) or ``nhwc`` (B, H, W, 3); ``float`` inputs get ``(pixel *
  scale - mean) / std`` per channel (pixel 0-255), ``uint8`` inputs get raw pixels. The image is
  resized to (W, H) by ``letterbox`` (uniform scale, ``top-left`` or ``centre``, padded with
  ``pad_value``) or ``stretch``. A dynamic batch axis runs ``batch_size`` images per call; a static
  batch of 1 runs one at a time.
- ``decoded`` outputs, ``boxes-scores-classes``: three tensors, boxes (B, N, 4) or (N, 4), scores,
  classes (the first three outputs, or ``output_names``); ``detections``: one (B, N, 6) or (N, 6)
  tensor of box, score, class. Boxes ``xyxy``, ``xywh`` or ``cxcywh`` in input pixels
  (``normalized``: in [0, 1]).
- classes are COCO category ids, or model indices mapped by ``class_map`` ({model class: COCO id};
  :func:`pipeline.detect.classmap.coco80_map` for the standard 80 classes, the default of raw heads
  with 80 classes). Classes without an id are dropped and counted (:attr:`OnnxDetector.unmapped`).
- post-processing: score threshold, class-wise NMS (``nms_iou``; None when the model does its own),
  ``max_detections`` (:func:`pipeline.detect.infer.postprocess`), boxes back to original pixels.

**Checked before the first image** (each a ValueError naming the model file, the option and the mismatch):
one rank-4 ``tensor(float)`` or ``tensor(uint8)`` input with 3 channels on the layout's channel axis;
``input_size`` > 0 and equal to a fixed input size; ``batch_size`` >= 1 and at most a fixed batch; the
family (given, stored or guessed) reading the output shapes of one run on a blank image (a raw head
(B, anchors, 5 + C) or (B, 4 + C, anchors) for the input size and strides; ``decoded``: the shapes
above); output names the model has; options in range (score threshold in [0, 1], ``max_detections``
>= 1, non-zero ``std``...).

**Non-finite outputs**: an output row (anchor, detection) whose box or score is NaN or inf is dropped and
counted (:attr:`OnnxDetector.nonfinite_rows` of :attr:`OnnxDetector.rows`); :meth:`OnnxDetector.check_finite`
fails when every row of a run was non-finite (a broken model or pre-processing, which would otherwise read
as "nothing detected") and warns with the counts when some were (an overflowing anchor should not void
the rest of an evaluation).

Sessions use every core this process may run on for one inference (``intra_op_num_threads``), which
on a CPU gives the best images/s for single-image models, and CUDA when onnxruntime offers it.

Our export (:func:`export_onnx`, classic TorchScript exporter, opset 17) contains the network and the
heatmap decoding (peaks, top-k, boxes) but not NMS: input ``images`` (B, 3, H, W) float RGB in [0, 1],
outputs ``boxes`` (B, K, 4) xyxy input pixels, ``scores`` (B, K), ``classes`` (B, K) int64 model
indices. Its options (class map, NMS IoU, ...) are stored as JSON in the model's metadata property
``roadsynth.onnx_options``; :class:`OnnxDetector` starts from them and explicit options override.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import warnings
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import torch

from pipeline.detect import heads
from pipeline.detect.classmap import coco80_map, metadata_names, names_map
from pipeline.detect.infer import Detections, Detector, postprocess
from pipeline.detect.model import decode
from pipeline.detect.onnx_checks import (
    INPUT_TYPES,
    check_options,
    decoded_mismatch,
    fixed_dim,
    guess_layout,
    raw_mismatch,
)

log = logging.getLogger(__name__)
METADATA_KEY = "roadsynth.onnx_options"
DEFAULT_BATCH_SIZE = 4  # images per run of a model with a dynamic batch axis, unless asked otherwise
_INTERPOLATION = {"linear": cv2.INTER_LINEAR, "area": cv2.INTER_AREA}


@dataclass(frozen=True)
class OnnxOptions:
    """Pre/post-processing of an ONNX detector; None fields take the family's value (heads.PRESETS)."""

    family: Literal["auto", "yolox", "yolov5", "yolov8", "decoded"] = "auto"
    input_size: tuple[int, int] | None = None  # W, H; None: the model's static input shape
    resize: Literal["letterbox", "stretch"] = "letterbox"
    placement: Literal["top-left", "centre"] | None = None
    pad_value: float | None = None  # 0-255
    layout: Literal["nchw", "nhwc"] | None = None  # None: from the input shape
    channels: Literal["rgb", "bgr"] | None = None
    scale: float | None = None
    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: tuple[float, float, float] = (1.0, 1.0, 1.0)
    strides: tuple[int, ...] = heads.DEFAULT_STRIDES
    output_format: Literal["boxes-scores-classes", "detections"] | None = None
    output_names: tuple[str, ...] | None = None
    box_format: Literal["xyxy", "xywh", "cxcywh"] = "xyxy"
    normalized: bool = False
    class_map: dict[int, int] | None = None  # None: decoded -> classes are COCO ids; raw heads -> names/COCO-80
    score_threshold: float = 0.05
    nms_iou: float | None = None
    max_detections: int = 100

    def replace(self, **changes: Any) -> OnnxOptions:
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})

    def to_json(self) -> str:
        data = dataclasses.asdict(self)
        if self.class_map is not None:
            data["class_map"] = {str(k): v for k, v in self.class_map.items()}
        return json.dumps(data, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> OnnxOptions:
        data = json.loads(text)
        unknown = set(data) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ValueError(f"unknown ONNX options {sorted(unknown)}")
        for key in ("input_size", "mean", "std", "output_names", "strides"):
            if data.get(key) is not None:
                data[key] = tuple(data[key])
        return cls(**{**data, "class_map": parse_class_map(data.get("class_map"))})


def parse_class_map(value: str | dict | None) -> dict[int, int] | None:
    """``coco80``, a JSON object text or file ({"model class": COCO id}), or a dict."""
    if value is None or isinstance(value, dict):
        return None if value is None else {int(k): int(v) for k, v in value.items()}
    if value == "coco80":
        return coco80_map()
    text = Path(value).read_text() if Path(value).is_file() else value
    try:
        data = json.loads(text)
        return {int(k): int(v) for k, v in data.items()}
    except (json.JSONDecodeError, AttributeError, ValueError, TypeError):
        raise ValueError(f"--class-map: expected 'coco80', a JSON object or a JSON file, got {value!r}") from None


class _Exported(torch.nn.Module):
    def __init__(self, detector: Detector):
        super().__init__()
        self.model, self.candidates = detector.model, detector.config.infer.candidates

    def forward(self, images: torch.Tensor):
        return decode(self.model(images), self.candidates)


def export_onnx(detector: Detector, path: Path) -> OnnxOptions:
    """Write ``path`` (network + decoding, see the module docstring); returns the options stored in it."""
    import onnx

    cfg = detector.config
    options = OnnxOptions(family="decoded", input_size=cfg.input_size, class_map=dict(enumerate(detector.category_ids)),
                          score_threshold=cfg.infer.score_threshold, nms_iou=cfg.infer.nms_iou,
                          max_detections=cfg.infer.max_detections, output_format="boxes-scores-classes")
    model = _Exported(detector).cpu().eval()
    dummy = torch.zeros(1, 3, cfg.input_size[1], cfg.input_size[0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter announces its deprecation
        torch.onnx.export(model, (dummy,), str(path), dynamo=False, opset_version=17, input_names=["images"],
                          output_names=["boxes", "scores", "classes"], dynamic_axes={"images": {0: "batch"}})
    proto = onnx.load(str(path))
    onnx.helper.set_model_props(proto, {METADATA_KEY: options.to_json()})
    onnx.save(proto, str(path))
    detector.model.to(detector.device)
    return options


@dataclass(frozen=True)
class Placement:
    """Original -> input pixels: ``x_in = sx * x + dx``, ``y_in = sy * y + dy``."""

    sx: float
    sy: float
    dx: float = 0.0
    dy: float = 0.0

    def to_original(self, boxes: np.ndarray, width: int, height: int) -> np.ndarray:
        """(N, 4) input-pixel boxes to original pixels, clipped to the image."""
        out = (boxes - np.array([self.dx, self.dy, self.dx, self.dy])) / np.array([self.sx, self.sy, self.sx, self.sy])
        out[:, 0::2] = out[:, 0::2].clip(0, width)
        out[:, 1::2] = out[:, 1::2].clip(0, height)
        return out


def _threads() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _providers(device: str) -> list[str]:
    import onnxruntime as ort

    available = ort.get_available_providers()
    if device == "cuda" and "CUDAExecutionProvider" not in available:
        raise RuntimeError(f"--device cuda: onnxruntime offers no CUDA provider (available: {', '.join(available)})")
    if device in ("auto", "cuda") and "CUDAExecutionProvider" in available:
        return ["CUDAExecutionProvider", "CPUExecutionProvider"]
    return ["CPUExecutionProvider"]


class OnnxDetector:
    """Any ONNX detector under :class:`OnnxOptions`; :meth:`predict` maps RGB images to Detections.

    Attributes:
        family: the head family in use (``yolox``, ``yolov5``, ``yolov8`` or ``decoded``).
        batch: images per session run (the model's static batch, else ``batch_size``).
        unmapped: detections above the score threshold dropped because their model class has no
            COCO id, by model class index (summed over every :meth:`predict`).
    """

    def __init__(self, path: Path, options: OnnxOptions | None = None, *, batch_size: int | None = None,
                 device: str = "auto", threads: int | None = None, **overrides: Any):
        import onnxruntime as ort

        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"{self.path}: ONNX model not found")
        so = ort.SessionOptions()
        so.intra_op_num_threads = threads or _threads()
        so.inter_op_num_threads = 1
        so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        # Threads that spin between runs take the cores the next image's reading and the decoding need.
        so.add_session_config_entry("session.intra_op.allow_spinning", "0")
        try:
            self.session = ort.InferenceSession(str(self.path), so, providers=_providers(device))
        except Exception as exc:  # onnxruntime raises its own exception types for unreadable models
            raise ValueError(f"{self.path}: onnxruntime cannot load the model: {exc}") from None
        meta = self.session.get_modelmeta().custom_metadata_map
        stored = meta.get(METADATA_KEY)
        base = options or (OnnxOptions.from_json(stored) if stored else OnnxOptions())
        o = base.replace(**overrides)
        # Everything the graph declares is checked before the first run, so that a contradiction is one message
        # naming the option, not onnxruntime's traceback or a silently empty result.
        check_options(o, self.path)
        self.input = self._image_input()
        shape = self.input.shape
        layout = o.layout or guess_layout(shape)
        self._check_channels(layout, given=o.layout is not None)
        o = dataclasses.replace(o, layout=layout, input_size=self._input_size(layout, o.input_size))
        self.fixed_batch = fixed_dim(shape[0])
        self.batch = self._batch(batch_size)
        self._check_output_names(o.output_names)
        self.options = o
        self.output_shapes = self._probe(o)
        try:
            self.family, why = (o.family, "given") if o.family != "auto" else heads.guess_family(
                self.output_shapes, *o.input_size, o.strides)
        except ValueError as exc:  # the shapes fit no family: name the model and its outputs
            raise ValueError(f"{self.path}: family auto: {exc}") from None
        if o.family == "auto":
            source = f"family {self.family} (auto: {why})"
        elif overrides.get("family") is not None:
            source = f"--family {o.family}"
        else:
            source = f"family {o.family} ({'the model metadata' if options is None else 'the options'})"
        self._check_family(o, source)
        self.options = self._resolve(o, meta)
        self.unmapped: Counter[int] = Counter()
        self.rows = 0
        self.nonfinite_rows = 0
        shown = dataclasses.replace(self.options, class_map=None).to_json()
        classes = "COCO ids" if self.options.class_map is None else f"{len(self.options.class_map)} mapped to COCO ids"
        log.info("%s: input %s %s %s; family %s (%s); %d image(s) per run on %s, %d threads; classes %s; options %s",
                 self.path, self.input.name, shape, self.input.type, self.family, why, self.batch,
                 self.session.get_providers()[0], so.intra_op_num_threads, classes, shown)

    # --- the model's graph against the options (see check_options for the options alone) ---

    def _image_input(self):
        """The model's one input, a rank-4 float32 or uint8 tensor."""
        inputs = self.session.get_inputs()
        if len(inputs) != 1:
            listed = ", ".join(f"{i.name!r} {i.shape} {i.type}" for i in inputs)
            raise ValueError(f"{self.path}: the model has {len(inputs)} inputs ({listed}); roadsynth feeds one image "
                             "tensor: expected exactly one input")
        image = inputs[0]
        if len(image.shape) != 4:
            raise ValueError(f"{self.path}: input {image.name!r} has shape {image.shape}; expected an image batch "
                             "(B, 3, H, W) or (B, H, W, 3)")
        if image.type not in INPUT_TYPES:
            raise ValueError(f"{self.path}: input {image.name!r} is {image.type}; roadsynth feeds "
                             f"{' or '.join(INPUT_TYPES)} (scaled or raw pixels)")
        return image

    def _check_channels(self, layout: str, *, given: bool) -> None:
        shape = self.input.shape
        channels = fixed_dim(shape[1] if layout == "nchw" else shape[3])
        if channels is None or channels == 3:
            return
        how = f"--layout {layout}" if given else f"layout {layout}, from the shape"
        other = "nhwc" if layout == "nchw" else "nchw"
        hint = f" (the shape fits --layout {other})" if fixed_dim(shape[3 if layout == "nchw" else 1]) == 3 else ""
        raise ValueError(f"{self.path}: input {self.input.name!r} {shape} has {channels} channel(s) ({how}); roadsynth "
                         f"feeds RGB images: expected 3 channels{hint}")

    def _input_size(self, layout: str, size: tuple[int, int] | None) -> tuple[int, int]:
        """(W, H) of the network input: ``--input-size`` where given (it must fit a fixed size), else the model's."""
        shape = self.input.shape
        h, w = (shape[2], shape[3]) if layout == "nchw" else (shape[1], shape[2])
        fixed_w, fixed_h = fixed_dim(w), fixed_dim(h)
        if size is None:
            if fixed_w is None or fixed_h is None:
                raise ValueError(f"{self.path}: input {self.input.name} has a dynamic size {shape}; "
                                 "pass --input-size W H")
            return fixed_w, fixed_h
        size = tuple(size)
        if len(size) != 2 or any(not isinstance(v, (int, np.integer)) or v <= 0 for v in size):
            raise ValueError(f"{self.path}: --input-size {' '.join(map(str, size))}: expected two integers > 0 "
                             "(the network input's width and height)")
        if (fixed_w is not None and size[0] != fixed_w) or (fixed_h is not None and size[1] != fixed_h):
            fixed = f"{fixed_w or 'any'}x{fixed_h or 'any'}"
            raise ValueError(f"{self.path}: --input-size {size[0]} {size[1]} contradicts input {self.input.name!r} "
                             f"{shape} ({layout}), whose size is fixed at {fixed} (W x H); leave --input-size out")
        return int(size[0]), int(size[1])

    def _batch(self, batch_size: int | None) -> int:
        """Images per run: the model's fixed batch, else ``batch_size`` (default :data:`DEFAULT_BATCH_SIZE`)."""
        if batch_size is not None and batch_size < 1:
            raise ValueError(f"{self.path}: --batch-size {batch_size}: expected an integer >= 1")
        if self.fixed_batch is not None:
            if batch_size is not None and batch_size > self.fixed_batch:
                raise ValueError(f"{self.path}: --batch-size {batch_size}: input {self.input.name!r} "
                                 f"{self.input.shape} has a fixed batch of {self.fixed_batch}; expected --batch-size "
                                 f"<= {self.fixed_batch}, or leave it out")
            return self.fixed_batch
        return DEFAULT_BATCH_SIZE if batch_size is None else batch_size

    def _check_output_names(self, names: tuple[str, ...] | None) -> None:
        outputs = [x.name for x in self.session.get_outputs()]
        missing = [n for n in names or () if n not in outputs]
        if missing:
            raise ValueError(f"{self.path}: --output-names {' '.join(missing)}: the model has no such output; its "
                             f"outputs: {', '.join(outputs)}")

    def _check_family(self, o: OnnxOptions, source: str) -> None:
        """The probed output shapes must be what the family's decoding reads (``source`` names who chose it)."""
        names = list(o.output_names) if o.output_names else [x.name for x in self.session.get_outputs()]
        shapes = self.output_shapes
        w, h = o.input_size
        if self.family == "decoded":
            expected = decoded_mismatch(shapes, o.output_format)
        else:
            expected = raw_mismatch(self.family, shapes[0], w, h, o.strides)
        listed = ", ".join(f"{n} {tuple(s)}" for n, s in zip(names, shapes, strict=False))
        if expected is None:
            if self.family == "decoded" and len(shapes[0]) == 2 and self.batch > 1:
                raise ValueError(f"{self.path}: {self.batch} images per run (--batch-size), but the outputs {listed} "
                                 "have no batch axis, so they cannot be told apart: expected --batch-size 1")
            return
        try:
            fits = "; they fit family {} ({})".format(*heads.guess_family(shapes, w, h, o.strides))
        except ValueError:
            fits = ""
        raise ValueError(f"{self.path}: {source} reads {expected}; the model's outputs for a {w}x{h} input are "
                         f"{listed}{fits}")

    def _run(self, x: np.ndarray) -> list[np.ndarray]:
        o = self.options
        try:
            return self.session.run(list(o.output_names) if o.output_names else None, {self.input.name: x})
        except Exception as exc:  # onnxruntime's own exception types; the checks above leave only the model's own
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ValueError(f"{self.path}: onnxruntime failed on input {self.input.name!r} of shape {x.shape} "
                             f"{x.dtype} (input size {o.input_size[0]}x{o.input_size[1]}, layout {o.layout}): "
                             f"{first}") from None

    def _probe(self, o: OnnxOptions) -> list[tuple[int, ...]]:
        """Concrete output shapes: one run on a blank image (exported shapes are often symbolic)."""
        w, h = o.input_size
        dims = (3, h, w) if o.layout == "nchw" else (h, w, 3)
        dtype = np.uint8 if self.input.type == "tensor(uint8)" else np.float32
        return [tuple(p.shape) for p in self._run(np.zeros((self.fixed_batch or 1, *dims), dtype))]

    def _resolve(self, o: OnnxOptions, meta: dict[str, str]) -> OnnxOptions:
        """Fill the family's defaults and the class map of a raw head."""
        preset = heads.PRESETS[self.family]
        o = dataclasses.replace(
            o, family=self.family, channels=o.channels or preset.channels,
            scale=preset.scale if o.scale is None else o.scale,
            pad_value=preset.pad_value if o.pad_value is None else o.pad_value,
            placement=o.placement or preset.placement,
            nms_iou=preset.nms_iou if o.nms_iou is None else o.nms_iou)
        if self.family == "decoded":
            fmt = o.output_format or ("boxes-scores-classes" if len(self.output_shapes) >= 3 else "detections")
            return dataclasses.replace(o, output_format=fmt)
        if o.class_map is None:
            out = self.output_shapes[0]
            n_classes = out[1] - 4 if self.family == "yolov8" else out[2] - 5
            names = metadata_names(meta["names"]) if "names" in meta else None
            if names is not None:
                mapping, missing = names_map(names)
                if missing:
                    log.warning("%s: classes without a COCO id (their detections are dropped and counted): %s",
                                self.path, ", ".join(missing))
                o = dataclasses.replace(o, class_map=mapping)
            elif n_classes == 80:
                o = dataclasses.replace(o, class_map=coco80_map())
            else:
                raise ValueError(f"{self.path}: the {self.family} head has {n_classes} classes, not COCO's 80, and "
                                 "no 'names' metadata; pass --names FILE or --class-map JSON")
        return o

    def _prepare(self, rgb: np.ndarray) -> tuple[np.ndarray, Placement]:
        """(H, W, 3) float32 (or uint8) network input of one image, in the model's channel order and layout."""
        o = self.options
        w_in, h_in = o.input_size
        h, w = rgb.shape[:2]
        img = rgb[:, :, ::-1] if o.channels == "bgr" else rgb
        preset = heads.PRESETS[self.family]
        interp = _INTERPOLATION[preset.interpolation]
        if o.resize == "stretch":
            canvas = cv2.resize(img, (w_in, h_in), interpolation=interp)
            place = Placement(w_in / w, h_in / h)
        else:
            s = min(w_in / w, h_in / h)
            fit = int if preset.floor_size else round
            nw, nh = min(fit(w * s), w_in), min(fit(h * s), h_in)
            # Ultralytics centres with round(pad / 2 - 0.1): the odd pixel goes right / bottom.
            dx, dy = (round((w_in - nw) / 2 - 0.1), round((h_in - nh) / 2 - 0.1)) if o.placement == "centre" else (0, 0)
            # uint8 canvas when the grey is a whole level (all families'): a quarter of the memory traffic
            dtype = np.uint8 if float(o.pad_value).is_integer() and 0 <= o.pad_value <= 255 else np.float32
            canvas = np.full((h_in, w_in, 3), o.pad_value, dtype)
            canvas[dy:dy + nh, dx:dx + nw] = cv2.resize(img, (nw, nh), interpolation=interp)
            place = Placement(s, s, dx, dy)
        if o.layout == "nchw":
            canvas = canvas.transpose(2, 0, 1)
            shape = (3, 1, 1)
        else:
            shape = (1, 1, 3)
        if self.input.type == "tensor(uint8)":
            return np.round(canvas).astype(np.uint8), place
        x = canvas.astype(np.float32)  # one contiguous copy, in the model's layout
        if o.scale != 1.0:
            x *= np.float32(o.scale)
        if any(o.mean):
            x -= np.array(o.mean, np.float32).reshape(shape)
        if any(v != 1.0 for v in o.std):
            x /= np.array(o.std, np.float32).reshape(shape)
        return x, place

    def _decoded(self, outputs: list[np.ndarray], n: int) -> list[tuple[heads.Decoded, int]]:
        """Every row of a decoded model's outputs for each of ``n`` images, boxes in input pixels, and the row
        count; rows with a non-finite box, score or class are left out here (counted by :meth:`_usable`)."""
        o = self.options
        if o.output_format == "detections":
            det = outputs[0]
            per_image = [det.reshape(-1, det.shape[-1])] if n == 1 else list(det)
            parts = [(d[:, :4], d[:, 4], d[:, 5]) for d in per_image]
        else:
            b, s, c = outputs[:3]
            parts = ([(b.reshape(-1, 4), s.reshape(-1), c.reshape(-1))] if n == 1
                     else [(b[i].reshape(-1, 4), s[i].reshape(-1), c[i].reshape(-1)) for i in range(n)])
        result = []
        for boxes, scores, classes in parts:
            boxes = boxes.astype(np.float64)
            if o.normalized:
                boxes = boxes * np.array([*o.input_size, *o.input_size], np.float64)
            if o.box_format == "xywh":
                boxes = np.concatenate([boxes[:, :2], boxes[:, :2] + boxes[:, 2:]], axis=1)
            elif o.box_format == "cxcywh":
                boxes = np.concatenate([boxes[:, :2] - boxes[:, 2:] / 2, boxes[:, :2] + boxes[:, 2:] / 2], axis=1)
            scores, classes = scores.astype(np.float64), classes.astype(np.float64)
            finite = np.isfinite(boxes).all(axis=1) & np.isfinite(scores) & np.isfinite(classes)
            result.append((heads.Decoded(boxes[finite], scores[finite], np.round(classes[finite]).astype(np.int64)),
                           len(scores)))
        return result

    def _usable(self, d: heads.Decoded, rows: int) -> heads.Decoded:
        """The candidates of one image: ``d``'s rows with a finite box and score, at or above the score threshold.
        Of the image's ``rows`` output rows (anchors, detections), those not in ``d`` or not finite are counted
        in :attr:`nonfinite_rows` (a decoding leaves out rows whose score is NaN, so the count is ``rows`` less the
        finite ones)."""
        finite = np.isfinite(d.boxes).all(axis=1) & np.isfinite(d.scores)
        self.rows += rows
        self.nonfinite_rows += rows - int(finite.sum())
        keep = finite & (d.scores >= self.options.score_threshold)
        return heads.Decoded(d.boxes[keep], d.scores[keep], d.classes[keep])

    def check_finite(self) -> None:
        """After a run: fail when every output row of every image had a non-finite box or score (the model gave no
        usable output at all, which would otherwise read as "nothing detected"); warn with the counts when some
        had (those rows were dropped, as a few overflowing anchors should not void the rest)."""
        if not self.nonfinite_rows:
            return
        counts = f"{self.nonfinite_rows} of {self.rows} output rows (anchors or detections)"
        if self.nonfinite_rows == self.rows:
            raise ValueError(f"{self.path}: all {counts} have a non-finite (NaN or inf) box or score; expected "
                             "finite outputs (check the model and the pre-processing: --scale, --mean, --std, "
                             "--channels)")
        log.warning("%s: dropped %s with a non-finite (NaN or inf) box or score (%.2g%%)", self.path, counts,
                    100.0 * self.nonfinite_rows / self.rows)

    def _to_coco(self, d: heads.Decoded) -> heads.Decoded:
        """Model classes -> COCO ids (unchanged without a class map); unmapped ones counted and dropped."""
        if self.options.class_map is None:
            return d
        table = self.options.class_map
        ids = np.array([table.get(int(c), 0) for c in d.classes], np.int64)
        mapped = ids > 0
        if not mapped.all():
            self.unmapped.update(int(c) for c in d.classes[~mapped])
        return heads.Decoded(d.boxes[mapped], d.scores[mapped], ids[mapped])

    def predict(self, rgbs: list[np.ndarray]) -> list[Detections]:
        # NMS of a few hundred candidates is small work: torch's thread pool waking for it fights
        # onnxruntime for the cores (measured many times slower per image on 2 cores: docs/performance.md).
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        try:
            return self._predict(rgbs)
        finally:
            torch.set_num_threads(threads)

    def _predict(self, rgbs: list[np.ndarray]) -> list[Detections]:
        o = self.options
        dets: list[Detections] = []
        for start in range(0, len(rgbs), self.batch):
            chunk = rgbs[start:start + self.batch]
            prepared = [self._prepare(rgb) for rgb in chunk]
            x = np.stack([p[0] for p in prepared])
            if self.fixed_batch and len(chunk) < self.fixed_batch:  # a static batch > 1: pad the last run
                x = np.concatenate([x, np.zeros((self.fixed_batch - len(chunk), *x.shape[1:]), x.dtype)])
            outputs = self._run(np.ascontiguousarray(x))
            if self.family == "decoded":
                decoded = self._decoded(outputs, len(x))
            else:
                # Every anchor whose score is not NaN, so that the non-finite ones are counted (_usable).
                out = outputs[0]
                anchors = out.shape[2] if self.family == "yolov8" else out.shape[1]
                decoded = [(d, anchors) for d in heads.decode(self.family, out, *o.input_size, -np.inf, o.strides)]
            for rgb, (_, place), (d, rows) in zip(chunk, prepared, decoded, strict=False):
                d = self._to_coco(self._usable(d, rows))
                dets.append(postprocess(torch.from_numpy(d.boxes), torch.from_numpy(d.scores),
                                        torch.from_numpy(d.classes), place, rgb.shape[1], rgb.shape[0],
                                        score_threshold=o.score_threshold, nms_iou=o.nms_iou,
                                        max_detections=o.max_detections))
        return dets
