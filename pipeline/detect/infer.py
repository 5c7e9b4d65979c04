"""Inference: class-wise NMS, the checkpoint-backed :class:`Detector`, and COCO results.

Every detector (ours in torch, ours or anyone's in ONNX) ends in :func:`postprocess`: boxes in
network-input pixels -> score threshold -> class-wise NMS -> top ``max_detections`` -> boxes in
original pixels, clipped to the image. :func:`results_for` turns that into COCO results entries
``{image_id, category_id, bbox [x, y, w, h], score}`` (boxes of zero area after clipping are dropped).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from pipeline.core.config import DetectorConfig
from pipeline.detect.data import CocoData, Letterbox, letterbox, read_rgb
from pipeline.detect.model import CenterNet, decode

log = logging.getLogger(__name__)
CHECKPOINT_FORMAT = "roadsynth-centernet-1"


def box_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(N, M) IoU of x1 y1 x2 y2 boxes ``a`` (N, 4) and ``b`` (M, 4); 0 where the union is empty."""
    lt = torch.maximum(a[:, None, :2], b[None, :, :2])
    rb = torch.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = (rb - lt).clamp(min=0).prod(-1)
    area_a = (a[:, 2:] - a[:, :2]).clamp(min=0).prod(-1)
    area_b = (b[:, 2:] - b[:, :2]).clamp(min=0).prod(-1)
    union = area_a[:, None] + area_b[None, :] - inter
    return torch.where(union > 0, inter / union.clamp(min=1e-12), torch.zeros_like(inter))


def nms(boxes: torch.Tensor, scores: torch.Tensor, iou_threshold: float,
        classes: torch.Tensor | None = None) -> torch.Tensor:
    """Greedy NMS, exactly, without a Python loop over boxes. Returns kept indices by descending score.

    A box is dropped when a *kept* higher-scoring box of its class overlaps it with IoU >
    ``iou_threshold`` (ties in score keep the earlier index first). The kept set solves a triangular
    system (box i depends on boxes before it); Jacobi iteration fixes one more box per pass and stops
    at the first pass that changes nothing, which is the unique solution -- in practice 2-4 passes.
    """
    if boxes.numel() == 0:
        return torch.zeros(0, dtype=torch.int64, device=boxes.device)
    order = torch.sort(scores, descending=True, stable=True).indices
    b = boxes[order]
    suppresses = (box_iou(b, b) > iou_threshold).triu(diagonal=1)  # [j, i]: j (higher) suppresses i
    if classes is not None:
        c = classes[order]
        suppresses &= c[:, None] == c[None, :]
    keep = torch.ones(len(b), dtype=torch.bool, device=b.device)
    for _ in range(len(b)):
        new = ~(suppresses & keep[:, None]).any(dim=0)
        if torch.equal(new, keep):
            break
        keep = new
    return order[keep]


@dataclass(frozen=True)
class Detections:
    """One image's detections in original pixels: boxes (N, 4) x1 y1 x2 y2, scores (N,), category ids (N,)."""

    boxes: np.ndarray
    scores: np.ndarray
    category_ids: np.ndarray


def postprocess(boxes: torch.Tensor, scores: torch.Tensor, classes: torch.Tensor, lb: Letterbox,
                width: int, height: int, *, score_threshold: float, nms_iou: float | None,
                max_detections: int, category_ids: Sequence[int] | None = None) -> Detections:
    """One image: boxes (K, 4) input pixels, scores (K,), classes (K,) -> :class:`Detections`.

    ``category_ids[c]`` is the COCO id of class index c (None: classes are ids already); classes
    outside the map (-1 entries, or indices past its end) are dropped.
    """
    keep = scores >= score_threshold
    boxes, scores, classes = boxes[keep].float(), scores[keep].float(), classes[keep].long()
    if category_ids is not None:
        table = torch.tensor(list(category_ids), dtype=torch.int64, device=classes.device)
        valid = (classes >= 0) & (classes < len(table))
        boxes, scores, classes = boxes[valid], scores[valid], table[classes[valid]]
        valid = classes > 0
        boxes, scores, classes = boxes[valid], scores[valid], classes[valid]
    if nms_iou is not None and nms_iou < 1.0:
        idx = nms(boxes, scores, nms_iou, classes)
    else:
        idx = torch.sort(scores, descending=True, stable=True).indices
    idx = idx[:max_detections]
    out = lb.to_original(boxes[idx].cpu().numpy().astype(np.float64), width, height)
    return Detections(out, scores[idx].cpu().numpy().astype(np.float64), classes[idx].cpu().numpy())


def results_for(image_id: int, det: Detections) -> list[dict[str, Any]]:
    """COCO results entries of one image (bbox rounded to 0.01 px, score to 1e-5)."""
    wh = det.boxes[:, 2:] - det.boxes[:, :2]
    valid = (wh > 0).all(axis=1)
    return [
        {"image_id": int(image_id), "category_id": int(c),
         "bbox": [round(float(b[0]), 2), round(float(b[1]), 2), round(float(s[0]), 2), round(float(s[1]), 2)],
         "score": round(float(sc), 5)}
        for b, s, sc, c in zip(det.boxes[valid], wh[valid], det.scores[valid], det.category_ids[valid], strict=True)
        if round(float(s[0]), 2) > 0 and round(float(s[1]), 2) > 0
    ]


def resolve_device(name: str) -> torch.device:
    """``auto``: CUDA when available, else CPU; ``cuda`` without a GPU is an error."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise RuntimeError("--device cuda: no CUDA device available (torch.cuda.is_available() is False)")
    return torch.device(name)


class Detector:
    """Our CenterNet from a checkpoint; :meth:`predict` maps RGB images to :class:`Detections`."""

    def __init__(self, model: CenterNet, config: DetectorConfig, category_ids: Sequence[int],
                 device: torch.device, checkpoint: dict[str, Any] | None = None):
        self.model = model.to(device).eval()
        self.config = config
        self.category_ids = list(category_ids)
        self.device = device
        self.checkpoint = checkpoint or {}

    @classmethod
    def load(cls, path: Path, device: torch.device | None = None) -> Detector:
        path = Path(path)
        device = torch.device("cpu") if device is None else device
        if path.is_dir():
            path = path / "model.pt"
        try:
            ckpt = torch.load(path, map_location="cpu", weights_only=True)
        except (OSError, RuntimeError) as exc:
            raise ValueError(f"{path}: cannot read the detector checkpoint: {exc}") from None
        if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"{path}: not a roadsynth detector checkpoint (expected format {CHECKPOINT_FORMAT})")
        config = DetectorConfig.model_validate(ckpt["config"])
        model = CenterNet(len(config.classes), config.backbone)
        model.load_state_dict(ckpt["state_dict"])
        return cls(model, config, ckpt["category_ids"], device, ckpt)

    @torch.no_grad()
    def predict(self, rgbs: Sequence[np.ndarray], *, score_threshold: float | None = None) -> list[Detections]:
        inf = self.config.infer
        batch, boxes_lb = [], []
        for rgb in rgbs:
            img, lb = letterbox(rgb, self.config.input_size)
            batch.append(torch.from_numpy(img).permute(2, 0, 1))
            boxes_lb.append(lb)
        outputs = self.model(torch.stack(batch).to(self.device))
        boxes, scores, classes = decode(outputs, inf.candidates)
        threshold = inf.score_threshold if score_threshold is None else score_threshold
        return [
            postprocess(boxes[i], scores[i], classes[i], boxes_lb[i], rgb.shape[1], rgb.shape[0],
                        score_threshold=threshold, nms_iou=inf.nms_iou, max_detections=inf.max_detections,
                        category_ids=self.category_ids)
            for i, rgb in enumerate(rgbs)
        ]


def detect_coco(predict: Callable[[list[np.ndarray]], list[Detections]], data: CocoData, batch_size: int = 4,
                progress: bool = True) -> list[dict[str, Any]]:
    """COCO results for every image of ``data``, in image-id order.

    A background thread reads (decodes) the next batch's images while ``predict`` runs on this one:
    PNG decoding releases the GIL, so it overlaps the model's run.
    """
    results: list[dict[str, Any]] = []
    images = data.images
    chunks = [images[start:start + batch_size] for start in range(0, len(images), batch_size)]

    def read(chunk):
        return [read_rgb(im.path) for im in chunk]

    with tqdm(total=len(images), desc="detect", unit="img", disable=not progress) as bar, \
            ThreadPoolExecutor(max_workers=1) as pool:
        pending = pool.submit(read, chunks[0]) if chunks else None
        for k, chunk in enumerate(chunks):
            rgbs = pending.result()
            pending = pool.submit(read, chunks[k + 1]) if k + 1 < len(chunks) else None
            for image, det in zip(chunk, predict(rgbs), strict=True):
                results.extend(results_for(image.id, det))
            bar.update(len(chunk))
    return results
