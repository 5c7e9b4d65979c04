"""ONNX: export our detector, and run any ONNX detector (onnxruntime) into COCO results.

**Expected model I/O** (:class:`OnnxOptions` describes the variations):

- one image input, batch 1 (a dynamic batch axis is fine): ``nchw`` (1, 3, H, W) or ``nhwc``
  (1, H, W, 3); ``float`` inputs get ``(pixel * scale - mean) / std`` per channel (``scale``
  default 1/255), ``uint8`` inputs get raw pixels; ``rgb`` or ``bgr`` channel order. The image is
  resized to (W, H) by ``letterbox`` (uniform scale, top-left, grey padding) or ``stretch``.
- outputs, ``boxes-scores-classes``: three tensors, boxes (1, N, 4) or (N, 4), scores (N), classes (N)
  (the first three outputs, or ``output_names``); ``detections``: one (1, N, 6) or (N, 6) tensor of
  box, score, class. Boxes ``xyxy``, ``xywh`` or ``cxcywh`` in input pixels (``normalized``: in [0, 1]).
- classes are COCO category ids, or model indices mapped by ``class_map`` ({model class: COCO id};
  ``coco80`` = the usual contiguous 0..79 COCO indices); unmapped classes are dropped.
- post-processing: score threshold, optional class-wise NMS (``nms_iou``; None when the model does
  its own), ``max_detections`` (:func:`pipeline.detect.infer.postprocess`).

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
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
import torch

from pipeline.detect.data import letterbox
from pipeline.detect.infer import Detections, Detector, postprocess
from pipeline.detect.model import decode

log = logging.getLogger(__name__)
METADATA_KEY = "roadsynth.onnx_options"
# COCO's 80 contiguous training indices -> category ids, for the classes roadsynth labels.
COCO80 = {0: 1, 1: 2, 2: 3, 3: 4, 5: 6, 7: 8}


@dataclass(frozen=True)
class OnnxOptions:
    input_size: tuple[int, int] | None = None  # W, H; None: the model's static input shape
    resize: Literal["letterbox", "stretch"] = "letterbox"
    layout: Literal["nchw", "nhwc"] | None = None  # None: from the input shape
    channels: Literal["rgb", "bgr"] = "rgb"
    scale: float = 1.0 / 255.0
    mean: tuple[float, float, float] = (0.0, 0.0, 0.0)
    std: tuple[float, float, float] = (1.0, 1.0, 1.0)
    output_format: Literal["boxes-scores-classes", "detections"] = "boxes-scores-classes"
    output_names: tuple[str, ...] | None = None
    box_format: Literal["xyxy", "xywh", "cxcywh"] = "xyxy"
    normalized: bool = False
    class_map: dict[int, int] | None = None  # None: classes are COCO ids
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
        for key in ("input_size", "mean", "std", "output_names"):
            if data.get(key) is not None:
                data[key] = tuple(data[key])
        return cls(**{**data, "class_map": parse_class_map(data.get("class_map"))})


def parse_class_map(value: str | dict | None) -> dict[int, int] | None:
    """``coco80``, a JSON object text or file ({"model class": COCO id}), or a dict."""
    if value is None or isinstance(value, dict):
        return None if value is None else {int(k): int(v) for k, v in value.items()}
    if value == "coco80":
        return dict(COCO80)
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
    options = OnnxOptions(input_size=cfg.input_size, class_map=dict(enumerate(detector.category_ids)),
                          score_threshold=cfg.infer.score_threshold, nms_iou=cfg.infer.nms_iou,
                          max_detections=cfg.infer.max_detections)
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
class _Stretch:
    sx: float
    sy: float

    def to_original(self, boxes: np.ndarray, width: int, height: int) -> np.ndarray:
        out = boxes / np.array([self.sx, self.sy, self.sx, self.sy])
        out[:, 0::2] = out[:, 0::2].clip(0, width)
        out[:, 1::2] = out[:, 1::2].clip(0, height)
        return out


class OnnxDetector:
    """Any ONNX detector under :class:`OnnxOptions`; :meth:`predict` maps RGB images to Detections."""

    def __init__(self, path: Path, options: OnnxOptions | None = None, **overrides: Any):
        import onnxruntime as ort

        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"{self.path}: ONNX model not found")
        so = ort.SessionOptions()
        so.intra_op_num_threads = 2
        self.session = ort.InferenceSession(str(self.path), so, providers=["CPUExecutionProvider"])
        stored = self.session.get_modelmeta().custom_metadata_map.get(METADATA_KEY)
        base = options or (OnnxOptions.from_json(stored) if stored else OnnxOptions())
        self.options = base.replace(**overrides)
        self.input = self.session.get_inputs()[0]
        shape = self.input.shape
        layout = self.options.layout or ("nhwc" if shape[-1] == 3 and shape[1] != 3 else "nchw")
        size = self.options.input_size
        if size is None:
            h, w = (shape[2], shape[3]) if layout == "nchw" else (shape[1], shape[2])
            if not (isinstance(w, int) and isinstance(h, int)):
                raise ValueError(f"{self.path}: input {self.input.name} has a dynamic size {shape}; "
                                 "pass --input-size W H")
            size = (w, h)
        self.options = dataclasses.replace(self.options, layout=layout, input_size=tuple(size))
        log.info("%s: input %s %s %s; options %s", self.path, self.input.name, shape, self.input.type,
                 self.options.to_json())

    def _prepare(self, rgb: np.ndarray):
        o = self.options
        if o.resize == "letterbox":
            img, tf = letterbox(rgb, o.input_size)
        else:
            img = cv2.resize(rgb, o.input_size, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
            tf = _Stretch(o.input_size[0] / rgb.shape[1], o.input_size[1] / rgb.shape[0])
        if o.channels == "bgr":
            img = img[:, :, ::-1]
        if self.input.type == "tensor(uint8)":
            x = np.round(img * 255.0).astype(np.uint8)
        else:
            x = ((img * 255.0 * o.scale - np.array(o.mean, np.float32)) / np.array(o.std, np.float32))
            x = x.astype(np.float32)
        x = x.transpose(2, 0, 1) if o.layout == "nchw" else x
        return np.ascontiguousarray(x[None]), tf

    def _outputs(self, outputs: list[np.ndarray]):
        o = self.options
        if o.output_format == "detections":
            det = outputs[0].reshape(-1, outputs[0].shape[-1])
            if det.shape[1] < 6:
                raise ValueError(f"{self.path}: 'detections' output needs 6 columns, got {det.shape}")
            boxes, scores, classes = det[:, :4], det[:, 4], det[:, 5]
        else:
            if len(outputs) < 3:
                raise ValueError(f"{self.path}: 'boxes-scores-classes' needs 3 outputs, the model has {len(outputs)}")
            boxes, scores, classes = (outputs[0].reshape(-1, 4), outputs[1].reshape(-1), outputs[2].reshape(-1))
        boxes = boxes.astype(np.float64)
        if o.normalized:
            boxes = boxes * np.array([*o.input_size, *o.input_size], np.float64)
        if o.box_format == "xywh":
            boxes = np.concatenate([boxes[:, :2], boxes[:, :2] + boxes[:, 2:]], axis=1)
        elif o.box_format == "cxcywh":
            boxes = np.concatenate([boxes[:, :2] - boxes[:, 2:] / 2, boxes[:, :2] + boxes[:, 2:] / 2], axis=1)
        return torch.from_numpy(boxes), torch.from_numpy(scores.astype(np.float64)), torch.from_numpy(
            np.round(classes).astype(np.int64))

    def predict(self, rgbs: list[np.ndarray]) -> list[Detections]:
        o = self.options
        names = list(o.output_names) if o.output_names else None
        table = None
        if o.class_map is not None:
            table = [o.class_map.get(i, -1) for i in range(max(o.class_map) + 1)] if o.class_map else []
        dets = []
        for rgb in rgbs:
            x, tf = self._prepare(rgb)
            boxes, scores, classes = self._outputs(self.session.run(names, {self.input.name: x}))
            dets.append(postprocess(boxes, scores, classes, tf, rgb.shape[1], rgb.shape[0],
                                    score_threshold=o.score_threshold, nms_iou=o.nms_iou,
                                    max_detections=o.max_detections, category_ids=table))
        return dets

