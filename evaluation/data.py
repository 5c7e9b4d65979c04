"""The one internal interchange format of the evaluation stage: struct-of-arrays ground truth and detections.

Readers (COCO JSON, KITTI label dirs) convert into these records; every metric reads only these.

Conventions:
- Boxes are COCO ``xywh``: ``(x1, y1, width, height)`` in pixels, float64. KITTI's ``x1, y1, x2, y2``
  is converted on reading (``w = x2 - x1``).
- Images and categories are referred to by *index* (``image_index``, ``category_index``) into the
  record's sorted ``image_ids`` / ``category_ids``; the original ids are kept for output.
- Optional per-annotation attributes (``distance_m``, ``occlusion``) come with an explicit validity mask,
  never a sentinel value.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np


@dataclasses.dataclass(frozen=True)
class GroundTruth:
    """Ground-truth images, categories and annotations.

    Attributes:
        source: where it was read from (for messages).
        image_ids: (I,) int64, sorted ascending, unique.
        image_attrs: I dicts of the images' scalar attributes (e.g. ``condition``), for ``group_by``.
        category_ids: (K,) int64, sorted ascending, unique, never 0.
        category_names: K names, in ``category_ids`` order.
        ann_ids: (N,) int64 annotation ids (unique, never 0).
        image_index: (N,) int64 index into ``image_ids``.
        category_index: (N,) int64 index into ``category_ids``.
        bbox: (N, 4) float64 ``x, y, w, h``.
        area: (N,) float64 area used for COCO area ranges (COCO's ``area`` field, not ``w*h``).
        iscrowd: (N,) bool crowd / ignore regions (KITTI DontCare becomes a crowd region of every class).
        distance_m: (N,) float64 distance of the object from the sensor; meaningful where ``distance_valid``.
        distance_valid: (N,) bool.
        occlusion: (N,) object array of occlusion bin labels (str); meaningful where ``occlusion_valid``.
        occlusion_valid: (N,) bool.
    """

    source: str
    image_ids: np.ndarray
    image_attrs: list[dict[str, Any]]
    category_ids: np.ndarray
    category_names: list[str]
    ann_ids: np.ndarray
    image_index: np.ndarray
    category_index: np.ndarray
    bbox: np.ndarray
    area: np.ndarray
    iscrowd: np.ndarray
    distance_m: np.ndarray
    distance_valid: np.ndarray
    occlusion: np.ndarray
    occlusion_valid: np.ndarray

    @property
    def num_images(self) -> int:
        return len(self.image_ids)

    @property
    def num_categories(self) -> int:
        return len(self.category_ids)

    def __len__(self) -> int:
        return len(self.ann_ids)


@dataclasses.dataclass(frozen=True)
class Detections:
    """Detections of one detector on the images of a :class:`GroundTruth`.

    Attributes:
        source: where it was read from (for messages).
        image_index: (N,) int64 index into the ground truth's ``image_ids``.
        category_index: (N,) int64 index into the ground truth's ``category_ids``.
        bbox: (N, 4) float64 ``x, y, w, h``.
        score: (N,) float64 confidence, finite.
        not_in_gt: detections left out because the ground truth lacks their category, by category id
            (pycocotools evaluates the ground truth's categories only).

    Entries keep their file order: ties in score are broken by it, as pycocotools does.
    """

    source: str
    image_index: np.ndarray
    category_index: np.ndarray
    bbox: np.ndarray
    score: np.ndarray
    not_in_gt: dict[int, int] = dataclasses.field(default_factory=dict)

    @property
    def area(self) -> np.ndarray:
        """(N,) float64 ``w * h`` (what pycocotools uses for detections, whatever the file says)."""
        return self.bbox[:, 2] * self.bbox[:, 3]

    def __len__(self) -> int:
        return len(self.score)


def empty_attrs(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Invalid distance and occlusion columns for ``n`` annotations: (distance, valid, occlusion, valid)."""
    return np.zeros(n), np.zeros(n, bool), np.full(n, "", dtype=object), np.zeros(n, bool)
