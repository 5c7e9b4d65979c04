"""Which camera labels become annotations, which become ignore regions, which are dropped; and the counts.

Each camera label row is exactly one of:

- ``hidden``: no visible pixel (``visible`` false). Nothing of it is in the image, so no format can
  annotate it; dropped.
- ``tiny``: visible, but fewer than ``min_visible_px`` visible pixels.
- ``occluded``: visible, but more than ``max_occlusion`` of its unoccluded pixels hidden by other objects.
- ``kept``: everything else: a normal annotation.
- ``no_category``: visible, but of a class the format has no category for (a stroller in COCO and YOLO, whose
  categories are COCO's); left out of those formats, counted (their category_id is 0 in the labels).
- ``in_cycle``: visible, but a rider (class ``rider``) in a format whose cycle box holds its rider (KITTI's
  Cyclist); left out, counted.

``tiny`` and ``occluded`` objects are real and visible, so a detector that finds them must not be
punished: COCO writes them as crowd regions (``iscrowd`` 1, which COCO evaluation ignores), KITTI as
``DontCare`` regions; YOLO has no ignore concept and drops them. Every count is reported.

Defaults (see exporters/README.md):

- ``min_visible_px = 20``: about a 4x5 pixel patch. Below it an object is a few pixels at the
  resolution of the finest feature map of common detectors (stride 4-8), which cannot localise it; the
  KITTI benchmark likewise ignores objects under 25 px of box *height*. COCO's "small" objects start far
  higher (area < 32^2), so 20 px keeps every object COCO-style evaluation would score as small.
- ``max_occlusion = 0.9``: with more than 90 % hidden, what is left (a roof edge, one wheel) does not
  identify the object; KITTI's "largely occluded" level (2) is still evaluated in its hard setting, so
  we keep objects up to 90 % occluded and mark only the rest as ignore regions.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
import pandas as pd

KEPT, HIDDEN, TINY, OCCLUDED, NO_CATEGORY, IN_CYCLE = "kept", "hidden", "tiny", "occluded", "no_category", "in_cycle"
REASONS = (KEPT, HIDDEN, TINY, OCCLUDED, NO_CATEGORY, IN_CYCLE)

DEFAULT_MIN_VISIBLE_PX = 20
DEFAULT_MAX_OCCLUSION = 0.9


@dataclass(frozen=True)
class ObjectFilter:
    """Thresholds on visible pixel count and occlusion fraction (occlusion = 1 - visible / unoccluded)."""

    min_visible_px: int = DEFAULT_MIN_VISIBLE_PX
    max_occlusion: float = DEFAULT_MAX_OCCLUSION

    def __post_init__(self) -> None:
        if self.min_visible_px < 1:
            raise ValueError(f"min_visible_px must be >= 1 (an object with no visible pixel is never kept), "
                             f"got {self.min_visible_px}")
        if not 0.0 <= self.max_occlusion <= 1.0:
            raise ValueError(f"max_occlusion must be a fraction in [0, 1], got {self.max_occlusion}")

    def classify(self, labels: pd.DataFrame) -> np.ndarray:
        """(N,) object array of :data:`REASONS`, one per camera label row."""
        visible = labels["visible"].to_numpy(dtype=bool)
        px = labels["visible_px"].fillna(0).to_numpy(dtype=np.int64)
        occlusion = labels["occlusion"].fillna(1.0).to_numpy(dtype=np.float64)
        out = np.full(len(labels), KEPT, dtype=object)
        out[occlusion > self.max_occlusion] = OCCLUDED
        out[px < self.min_visible_px] = TINY
        out[~visible | (px == 0)] = HIDDEN
        return out

    def to_dict(self) -> dict:
        return {"min_visible_px": int(self.min_visible_px), "max_occlusion": float(self.max_occlusion)}


class FilterSummary:
    """Counts of label rows by reason, overall and by category name."""

    def __init__(self) -> None:
        self.total: Counter[str] = Counter()
        self.by_class: dict[str, Counter[str]] = {}

    def add(self, reasons: np.ndarray, classes: np.ndarray) -> None:
        for reason, cls in zip(reasons, classes, strict=True):
            self.total[reason] += 1
            self.by_class.setdefault(str(cls), Counter())[reason] += 1

    def to_dict(self) -> dict:
        return {
            "total": {r: int(self.total[r]) for r in REASONS},
            "by_class": {c: {r: int(n[r]) for r in REASONS} for c, n in sorted(self.by_class.items())},
        }
