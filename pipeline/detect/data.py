"""COCO instances as detector samples: which file, which images, letterboxing and augmentation.

- **Which file** (:func:`annotation_file`): ``--coco DIR`` holds ``annotations.json`` (an export
  without splits) or ``annotations_<split>.json`` (one file per split). With a split, that split's
  file is used; ``annotations.json`` also serves the split ``train`` (an export without ``--splits``
  is all train). Images are ``<annotation file's folder>/images/<file_name>``, else
  ``<folder>/<file_name>``.
- **Classes** are matched by COCO category *name* to the config's ``classes`` (their order is the
  heatmap channel order); annotations of other categories are skipped and counted.
- **Crowd regions** (``iscrowd`` 1: tiny or heavily occluded objects) are ignore regions: the loss
  neither rewards nor punishes peaks inside them.
- **Letterbox**: the image is scaled by ``min(W/w, H/h)`` and placed at the top-left of a grey
  (0.5) canvas of the input size; input = scale * original. :class:`Letterbox` maps boxes back.
- **Augmentation** is one affine warp per sample (zoom + random crop/placement + horizontal flip)
  followed by colour jitter and, sometimes, a night-like darkening; the generator of sample ``i`` of
  step ``s`` is ``numpy.random.default_rng([seed, s, i])``, so a run is a function of its seed.
"""

from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from pipeline.core.classes import COCO_CATEGORIES
from pipeline.core.config import AugmentConfig

log = logging.getLogger(__name__)
PAD_VALUE = 0.5


def annotation_file(coco_dir: Path, split: str | None) -> Path:
    """The annotation file of ``split`` in a COCO export folder (see the module docstring)."""
    coco_dir = Path(coco_dir)
    if split is not None and (coco_dir / f"annotations_{split}.json").is_file():
        return coco_dir / f"annotations_{split}.json"
    if (split is None or split == "train") and (coco_dir / "annotations.json").is_file():
        return coco_dir / "annotations.json"
    found = sorted(p.name for p in coco_dir.glob("annotations*.json")) if coco_dir.is_dir() else []
    wanted = f"annotations_{split}.json" if split else "annotations.json"
    hint = "; pass --split NAME or --annotations FILE" if found and split is None else ""
    raise FileNotFoundError(f"{coco_dir}: no {wanted} (found: {', '.join(found) or 'nothing'}){hint}")


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@dataclass
class Image:
    """One image: its file, size and boxes (original pixels, x1 y1 x2 y2)."""

    id: int
    path: Path
    width: int
    height: int
    attributes: dict[str, Any]
    boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.float32))  # (N, 4) float32
    labels: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (N,) class index
    ignore: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.float32))  # (M, 4) crowd boxes


@dataclass
class CocoData:
    """The images of one annotation file with boxes mapped to class indices."""

    path: Path
    images: list[Image]
    category_ids: list[int]  # COCO category id of each class index
    skipped: dict[str, int]


def _image_path(root: Path, file_name: str) -> Path:
    candidate = root / "images" / file_name
    return candidate if candidate.is_file() else root / file_name


def load_coco(path: Path, classes: tuple[str, ...], conditions: tuple[str, ...] | None = None) -> CocoData:
    """Read a COCO instances file; keep images whose ``condition`` is in ``conditions`` (None: all)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: cannot read COCO annotations: {exc}") from None
    for key in ("images", "annotations", "categories"):
        if not isinstance(data.get(key), list):
            raise ValueError(f"{path}: missing list '{key}' (expected COCO instances)")
    by_name = {c["name"]: c["id"] for c in data["categories"]}
    index_of_cat = {by_name[name]: i for i, name in enumerate(classes) if name in by_name}
    coco_ids = {name: cid for cid, (name, _) in COCO_CATEGORIES.items()}
    category_ids = [by_name.get(name, coco_ids[name]) for name in classes]
    skipped = {"condition": 0, "category": 0, "degenerate": 0}
    images: dict[int, Image] = {}
    for im in data["images"]:
        if conditions is not None and im.get("condition") not in conditions:
            skipped["condition"] += 1
            continue
        attrs = {k: v for k, v in im.items() if k not in ("id", "file_name", "width", "height")}
        images[im["id"]] = Image(im["id"], _image_path(path.parent, im["file_name"]), im["width"], im["height"], attrs)
    boxes: dict[int, list] = {i: [] for i in images}
    labels: dict[int, list] = {i: [] for i in images}
    ignore: dict[int, list] = {i: [] for i in images}
    for ann in data["annotations"]:
        if ann["image_id"] not in images:
            continue
        x, y, w, h = ann["bbox"]
        if ann.get("iscrowd", 0):
            ignore[ann["image_id"]].append([x, y, x + w, y + h])
        elif ann["category_id"] not in index_of_cat:
            skipped["category"] += 1
        elif w <= 0 or h <= 0:
            skipped["degenerate"] += 1
        else:
            boxes[ann["image_id"]].append([x, y, x + w, y + h])
            labels[ann["image_id"]].append(index_of_cat[ann["category_id"]])
    for i, im in images.items():
        im.boxes = np.array(boxes[i], np.float32).reshape(-1, 4)
        im.labels = np.array(labels[i], np.int64)
        im.ignore = np.array(ignore[i], np.float32).reshape(-1, 4)
    if any(skipped.values()):
        log.info("%s: skipped %s", path, ", ".join(f"{v} by {k}" for k, v in skipped.items() if v))
    return CocoData(path, sorted(images.values(), key=lambda im: im.id), category_ids, skipped)


def read_rgb(path: Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise FileNotFoundError(f"{path}: cannot read image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


@dataclass(frozen=True)
class Letterbox:
    """Original -> input pixels: ``x_in = scale * x`` (top-left placement, no offset)."""

    scale: float

    @classmethod
    def fit(cls, width: int, height: int, input_size: tuple[int, int]) -> Letterbox:
        return cls(min(input_size[0] / width, input_size[1] / height))

    def to_original(self, boxes: np.ndarray, width: int, height: int) -> np.ndarray:
        """(N, 4) input-pixel boxes to original pixels, clipped to the image."""
        out = boxes / self.scale
        out[:, 0::2] = out[:, 0::2].clip(0, width)
        out[:, 1::2] = out[:, 1::2].clip(0, height)
        return out


def letterbox(rgb: np.ndarray, input_size: tuple[int, int]) -> tuple[np.ndarray, Letterbox]:
    """(H_in, W_in, 3) float32 in [0, 1] and the transform."""
    h, w = rgb.shape[:2]
    lb = Letterbox.fit(w, h, input_size)
    nw, nh = min(round(w * lb.scale), input_size[0]), min(round(h * lb.scale), input_size[1])
    canvas = np.full((input_size[1], input_size[0], 3), PAD_VALUE, np.float32)
    canvas[:nh, :nw] = cv2.resize(rgb, (nw, nh), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    return canvas, lb


def _transform_boxes(boxes: np.ndarray, a: float, tx: float, ty: float, flip: bool, size: tuple[int, int]):
    out = boxes * a + np.array([tx, ty, tx, ty], np.float32)
    if flip:
        out[:, [0, 2]] = size[0] - out[:, [2, 0]]
    out[:, 0::2] = out[:, 0::2].clip(0, size[0])
    out[:, 1::2] = out[:, 1::2].clip(0, size[1])
    return out


def colour_jitter(img: np.ndarray, cfg: AugmentConfig, rng: np.random.Generator) -> np.ndarray:
    """Brightness, contrast, saturation, then (with probability ``cfg.dark``) gamma + gain darkening."""
    img = img * rng.uniform(1 - cfg.brightness, 1 + cfg.brightness)
    mean = img.mean()
    img = (img - mean) * rng.uniform(1 - cfg.contrast, 1 + cfg.contrast) + mean
    gray = img.mean(axis=2, keepdims=True)
    img = (img - gray) * rng.uniform(1 - cfg.saturation, 1 + cfg.saturation) + gray
    if rng.random() < cfg.dark:
        img = np.clip(img, 0, 1) ** rng.uniform(1.5, 2.5) * rng.uniform(0.3, 0.8)
    return np.clip(img, 0.0, 1.0).astype(np.float32)


def augment(rgb: np.ndarray, image: Image, input_size: tuple[int, int], cfg: AugmentConfig,
            rng: np.random.Generator, pre_scale: float = 1.0):
    """Input image (H_in, W_in, 3) float32, boxes (N, 4), labels (N,), ignore boxes (M, 4).

    ``rgb`` may be a copy of the original resized by ``pre_scale`` (the training image cache).
    """
    base = Letterbox.fit(image.width, image.height, input_size).scale
    a = base * rng.uniform(*cfg.scale)
    zw, zh = image.width * a, image.height * a
    tx = rng.uniform(min(0.0, input_size[0] - zw), max(0.0, input_size[0] - zw))
    ty = rng.uniform(min(0.0, input_size[1] - zh), max(0.0, input_size[1] - zh))
    flip = bool(rng.random() < cfg.hflip)
    m = np.array([[a / pre_scale, 0.0, tx], [0.0, a / pre_scale, ty]])
    if flip:
        m[0] = [-m[0, 0], 0.0, input_size[0] - tx]
    out = cv2.warpAffine(rgb.astype(np.float32) / 255.0, m, input_size, flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=(PAD_VALUE,) * 3)
    boxes = _transform_boxes(image.boxes, a, tx, ty, flip, input_size)
    keep = ((boxes[:, 2] - boxes[:, 0]) >= cfg.min_box_px) & ((boxes[:, 3] - boxes[:, 1]) >= cfg.min_box_px)
    ignore = _transform_boxes(image.ignore, a, tx, ty, flip, input_size)
    # A box cut below min_box_px by the crop is still an object: ignore it rather than call it background.
    ignore = np.concatenate([ignore, boxes[~keep]])
    return colour_jitter(out, cfg, rng), boxes[keep], image.labels[keep], ignore
