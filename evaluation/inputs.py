"""The one internal interchange format of the evaluation stage: struct-of-arrays ground truth and detections.

Readers (COCO JSON, KITTI label dirs) convert into these records; every metric reads only these.

Conventions:
- Boxes are COCO ``xywh``: ``(x1, y1, width, height)`` in pixels, float64. KITTI's ``x1, y1, x2, y2``
  is converted on reading (``w = x2 - x1``).
- Images and categories are referred to by *index* (``image_index``, ``category_index``) into the
  record's sorted ``image_ids`` / ``category_ids``; the original ids are kept for output.
- Optional per-annotation attributes (``distance_m``, ``occlusion``, ``track_id``) come with an explicit
  validity mask, never a sentinel value; ``person`` (text) is "" where absent.
- ``--group-by KEY`` groups images by their attribute ``KEY`` (:func:`image_groups`): one group per
  distinct value as text, :data:`MISSING_GROUP` for images without it. The table, the PR curves and the
  COCO stats per group all group this way.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from evaluation.validate import InputError

MISSING_GROUP = "(none)"


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
        track_id: (N,) int64 the object's identity across the images of one sequence (COCO's optional
            ``track_id``, as roadsynth's export writes it); meaningful where ``track_valid``.
        track_valid: (N,) bool.
        person: (N,) object who a person is (roadsynth's COCO field ``person``: adult, teen, child,
            wheelchair_user; rider for its riders), "" where the annotation does not say (every non-person, and
            other datasets).
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
    track_id: np.ndarray
    track_valid: np.ndarray
    person: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.person is None:
            object.__setattr__(self, "person", np.full(len(self.ann_ids), "", object))

    @property
    def num_images(self) -> int:
        return len(self.image_ids)

    @property
    def num_categories(self) -> int:
        return len(self.category_ids)

    def __len__(self) -> int:
        return len(self.ann_ids)

    def select_images(self, keep: np.ndarray) -> GroundTruth:
        """The ground truth of the images where ``keep`` ((I,) bool) holds, as if the file listed only those:
        images and annotations keep their order, categories stay all."""
        ann = keep[self.image_index]
        new_index = np.cumsum(keep) - 1
        attrs = [a for a, k in zip(self.image_attrs, keep, strict=True) if k]
        return dataclasses.replace(
            self, image_ids=self.image_ids[keep], image_attrs=attrs, ann_ids=self.ann_ids[ann],
            image_index=new_index[self.image_index[ann]], category_index=self.category_index[ann],
            bbox=self.bbox[ann], area=self.area[ann], iscrowd=self.iscrowd[ann], distance_m=self.distance_m[ann],
            distance_valid=self.distance_valid[ann], occlusion=self.occlusion[ann],
            occlusion_valid=self.occlusion_valid[ann], track_id=self.track_id[ann], track_valid=self.track_valid[ann],
            person=self.person[ann])


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

    def select_images(self, keep: np.ndarray) -> Detections:
        """The detections on the images where ``keep`` ((I,) bool over the ground truth's images) holds, in file
        order, with image indices into :meth:`GroundTruth.select_images` of the same ``keep``."""
        sel = keep[self.image_index]
        new_index = np.cumsum(keep) - 1
        return dataclasses.replace(self, image_index=new_index[self.image_index[sel]],
                                   category_index=self.category_index[sel], bbox=self.bbox[sel], score=self.score[sel])


def empty_attrs(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Invalid distance and occlusion columns for ``n`` annotations: (distance, valid, occlusion, valid)."""
    return np.zeros(n), np.zeros(n, bool), np.full(n, "", dtype=object), np.zeros(n, bool)


def image_groups(gt: GroundTruth, key: str | None) -> tuple[list[str], np.ndarray]:
    """Group labels (sorted) and the (I,) int64 group index of each image for ``--group-by key``."""
    if key is None:
        return [], np.zeros(gt.num_images, dtype=np.int64)
    values = [attrs.get(key) for attrs in gt.image_attrs]
    if gt.num_images and all(v is None for v in values):
        known = sorted({k for attrs in gt.image_attrs for k in attrs})
        raise InputError(f"{gt.source}: no image has the attribute '{key}' to group by (image attributes: "
                         f"{', '.join(known) or 'none'})")
    labels = [MISSING_GROUP if v is None else str(v) for v in values]
    names = sorted(set(labels))
    lookup = {name: i for i, name in enumerate(names)}
    return names, np.array([lookup[v] for v in labels], dtype=np.int64)
