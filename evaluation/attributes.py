"""Binning of per-object attributes for the table: distance bins and occlusion levels.

- Distance (``distance_m``, metres from the sensor): bins ``0-30``, ``30-50``, ``50+``, each closed
  on the left and open on the right (30.0 m falls in ``30-50``).
- Box height (``bbox`` height, pixels; every object has one): bins ``<30``, ``30-60``, ``60+``, closed
  on the left (a 30 px box is ``30-60``), the sizes where a detector's recall usually falls off.
- Occlusion (``occlusion``): when every given value is a JSON integer it is a KITTI-style level and kept
  as is (``0`` fully visible, ``1`` partly occluded, ``2`` largely occluded, ``3`` unknown); otherwise it
  is an occluded fraction in [0, 1] binned into ``none`` [0, 0.1), ``partial`` [0.1, 0.5) and
  ``heavy`` [0.5, 1].
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from evaluation.validate import InputError, is_number, where

DISTANCE_EDGES_M = (0.0, 30.0, 50.0)
DISTANCE_LABELS = ("0-30", "30-50", "50+")
OCCLUSION_FRACTION_EDGES = (0.0, 0.1, 0.5)
OCCLUSION_FRACTION_LABELS = ("none", "partial", "heavy")
KITTI_OCCLUSION_LABELS = {0: "0 visible", 1: "1 partly", 2: "2 largely", 3: "3 unknown"}
HEIGHT_EDGES_PX = (0.0, 30.0, 60.0)
HEIGHT_LABELS = ("<30", "30-60", "60+")


def height_bins(height_px: np.ndarray) -> np.ndarray:
    """(N,) object array of bin labels for (N,) float64 box heights (>= 0)."""
    idx = np.searchsorted(np.asarray(HEIGHT_EDGES_PX), height_px, side="right") - 1
    return np.asarray(HEIGHT_LABELS, dtype=object)[np.clip(idx, 0, len(HEIGHT_LABELS) - 1)]


def distance_bins(distance_m: np.ndarray) -> np.ndarray:
    """(N,) object array of bin labels for (N,) float64 distances (>= 0)."""
    idx = np.searchsorted(np.asarray(DISTANCE_EDGES_M), distance_m, side="right") - 1
    return np.asarray(DISTANCE_LABELS, dtype=object)[np.clip(idx, 0, len(DISTANCE_LABELS) - 1)]


def occlusion_levels(values: Sequence[Any], path: str, section: str) -> tuple[np.ndarray, np.ndarray]:
    """Occlusion labels (N,) object and presence mask (N,) bool from raw JSON values (``None`` = absent)."""
    present = np.array([v is not None for v in values], dtype=bool)
    labels = np.full(len(values), "", dtype=object)
    given = [(i, v) for i, v in enumerate(values) if v is not None]
    if not given:
        return labels, present
    for i, v in given:
        if not is_number(v):
            raise InputError(f"{where(path, section, i)}: field 'occlusion' is {v!r} (expected a number)")
    if all(type(v) is int for _, v in given):
        for i, v in given:
            if v not in KITTI_OCCLUSION_LABELS:
                raise InputError(f"{where(path, section, i)}: field 'occlusion' is {v} (expected a level 0-3)")
            labels[i] = KITTI_OCCLUSION_LABELS[v]
        return labels, present
    idx = np.array([i for i, _ in given])
    frac = np.array([float(v) for _, v in given])
    bad = (frac < 0) | (frac > 1)
    if bad.any():
        i = int(idx[np.argmax(bad)])
        raise InputError(f"{where(path, section, i)}: field 'occlusion' is {values[i]!r} (expected a fraction 0-1)")
    bins = np.searchsorted(np.asarray(OCCLUSION_FRACTION_EDGES), frac, side="right") - 1
    labels[idx] = np.asarray(OCCLUSION_FRACTION_LABELS, dtype=object)[bins]
    return labels, present
