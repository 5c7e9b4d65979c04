"""Read and validate a COCO instances JSON (ground truth) and a COCO results JSON (detections).

Validation is strict: wrong types, missing fields, id 0, duplicate ids, unknown image ids (and, in the
ground truth, unknown category ids), negative or non-finite sizes and non-finite scores are errors
naming the file, the entry and the field. A result whose category the ground truth lacks (a COCO-80
detector on a dataset of 6 classes) is left out of scoring, as pycocotools does (it evaluates the
ground truth's categories), and counted per category id in :attr:`Detections.not_in_gt`; nothing else
is dropped. Deviations from pycocotools, all on inputs it mishandles or crashes on:

- a missing ``iscrowd`` reads as 0 (pycocotools raises ``KeyError``);
- an empty results list is zero detections (pycocotools raises ``IndexError``);
- an ``area`` is required on every annotation (pycocotools raises ``KeyError`` without it).

Like pycocotools, the ground truth's ``ignore`` field is not read (``iscrowd`` decides), and a result's
``area``/``id`` are not read (the area of a detection is ``w * h``).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.attributes import occlusion_levels
from evaluation.inputs import Detections, GroundTruth
from evaluation.validate import InputError, box_column, check_unique, int_column, lookup, number_column, where

log = logging.getLogger(__name__)

_IMAGE_STRUCTURAL_KEYS = {"id"}


def load_json(path: str | Path) -> Any:
    """Parse a JSON file (UTF-8, or the UTF-16/32 that JSON allows); syntax errors name the file, line and column."""
    path = Path(path)
    try:
        return json.loads(path.read_bytes())
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON: {exc}") from None
    except UnicodeDecodeError as exc:  # binary garbage, or text in another encoding
        raise InputError(f"{path}: not valid JSON: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except RecursionError:
        raise InputError(f"{path}: not valid JSON: nested too deeply") from None


def _section(data: Mapping[str, Any], key: str, path: str) -> list[Any]:
    if key not in data:
        raise InputError(f"{path}: missing top-level field '{key}' (a COCO instances file has images, "
                         "annotations and categories)")
    value = data[key]
    if not isinstance(value, list):
        raise InputError(f"{path}: top-level field '{key}' is a {type(value).__name__} (expected a list)")
    return value


def _image_attrs(images: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    scalar = (str, int, float, bool, type(None))
    return [{k: v for k, v in img.items() if k not in _IMAGE_STRUCTURAL_KEYS and isinstance(v, scalar)}
            for img in images]


def _categories(categories: list[Any], path: str) -> tuple[np.ndarray, list[str]]:
    cat_ids = int_column(categories, "id", path, "categories")
    check_unique(cat_ids, "id", path, "categories")
    names = []
    for i, cat in enumerate(categories):
        name = cat.get("name")
        if not isinstance(name, str) or not name:
            raise InputError(f"{where(path, 'categories', i)}: field 'name' is {name!r} (expected a non-empty string)")
        names.append(name)
    if len(set(names)) != len(names):
        seen: dict[str, int] = {}
        for i, name in enumerate(names):
            if name in seen:
                raise InputError(f"{where(path, 'categories', i)}: duplicate name {name!r} "
                                 f"(also at categories[{seen[name]}])")
            seen[name] = i
    order = np.argsort(cat_ids, kind="stable")
    return cat_ids[order], [names[i] for i in order]


def _crowd(annotations: list[Any], path: str) -> np.ndarray:
    values = [a.get("iscrowd", 0) for a in annotations]
    ok = [v in (0, 1) and type(v) in (int, bool) for v in values]
    if not all(ok):
        i = ok.index(False)
        raise InputError(f"{where(path, 'annotations', i)}: field 'iscrowd' is {values[i]!r} (expected 0 or 1)")
    return np.array(values, dtype=bool) if values else np.zeros(0, bool)


def _track_ids(annotations: list[Any], path: str) -> tuple[np.ndarray, np.ndarray]:
    """(N,) int64 optional ``track_id`` (an integer >= 0: one object across the frames of a sequence) and its mask."""
    values, present = number_column(annotations, "track_id", path, "annotations", default=None, minimum=0.0)
    fractional = present & ((values != np.floor(values)) | (values >= 2.0**63))
    if fractional.any():
        i = int(np.argmax(fractional))
        raise InputError(f"{where(path, 'annotations', i)}: field 'track_id' is {annotations[i]['track_id']!r} "
                         "(expected an integer >= 0)")
    return np.where(present, values, 0).astype(np.int64), present


def _persons(annotations: list[Any], path: str) -> np.ndarray:
    """(N,) object the optional ``person`` text of each annotation ("" where absent); "rider" for roadsynth's
    riders (``subclass`` rider: the person on a bicycle or motorcycle)."""
    out = np.full(len(annotations), "", object)
    for i, a in enumerate(annotations):
        value = a.get("person", "") if isinstance(a, dict) else ""
        if not isinstance(value, str):
            raise InputError(f"{where(path, 'annotations', i)}: field 'person' is {value!r} (expected text, e.g. "
                             "'adult' or 'child')")
        out[i] = "rider" if isinstance(a, dict) and a.get("subclass") == "rider" else value
    return out


def ground_truth_from_dict(data: Any, path: str = "<ground truth>") -> GroundTruth:
    """Validate a parsed COCO instances dict and convert it to a :class:`GroundTruth`."""
    if not isinstance(data, dict):
        raise InputError(f"{path}: expected a COCO instances object, got a JSON {type(data).__name__}"
                         + (" (is this a results file? pass it as the detections)" if isinstance(data, list) else ""))
    images = _section(data, "images", path)
    annotations = _section(data, "annotations", path)
    categories = _section(data, "categories", path)

    image_ids = int_column(images, "id", path, "images")
    check_unique(image_ids, "id", path, "images")
    img_order = np.argsort(image_ids, kind="stable")
    attrs = _image_attrs(images)
    cat_ids, cat_names = _categories(categories, path)

    ann_ids = int_column(annotations, "id", path, "annotations")
    check_unique(ann_ids, "id", path, "annotations")
    sorted_img_ids = image_ids[img_order]
    image_index = lookup(int_column(annotations, "image_id", path, "annotations"), sorted_img_ids,
                         "image_id", path, "annotations", "images")
    category_index = lookup(int_column(annotations, "category_id", path, "annotations"), cat_ids,
                            "category_id", path, "annotations", "categories")
    bbox = box_column(annotations, path, "annotations")
    area, _ = number_column(annotations, "area", path, "annotations", minimum=0.0)
    iscrowd = _crowd(annotations, path)
    distance, distance_valid = number_column(annotations, "distance_m", path, "annotations", default=None,
                                             minimum=0.0)
    occlusion, occlusion_valid = occlusion_levels([a.get("occlusion") for a in annotations], path, "annotations")
    track_id, track_valid = _track_ids(annotations, path)
    log.debug("%s: %d images, %d categories, %d annotations", path, len(image_ids), len(cat_ids), len(ann_ids))
    return GroundTruth(
        source=str(path),
        image_ids=sorted_img_ids,
        image_attrs=[attrs[i] for i in img_order],
        category_ids=cat_ids,
        category_names=cat_names,
        ann_ids=ann_ids,
        image_index=image_index,
        category_index=category_index,
        bbox=bbox,
        area=area,
        iscrowd=iscrowd,
        distance_m=distance,
        distance_valid=distance_valid,
        occlusion=occlusion,
        occlusion_valid=occlusion_valid,
        track_id=track_id,
        track_valid=track_valid,
        person=_persons(annotations, path),
    )


def detections_from_list(data: Any, gt: GroundTruth, path: str = "<detections>") -> Detections:
    """Validate a parsed COCO results list against ``gt`` and convert it to :class:`Detections`."""
    if not isinstance(data, list):
        hint = " (is this a ground-truth file? pass it as --gt)" if isinstance(data, dict) else ""
        raise InputError(f"{path}: expected a COCO results list of {{image_id, category_id, bbox, score}}, "
                         f"got a JSON {type(data).__name__}{hint}")
    image_index = lookup(int_column(data, "image_id", path, "results"), gt.image_ids, "image_id", path,
                         "results", "images")
    category_ids = int_column(data, "category_id", path, "results")
    bbox = box_column(data, path, "results")
    score, _ = number_column(data, "score", path, "results")
    known = np.isin(category_ids, gt.category_ids)
    not_in_gt: dict[int, int] = {}
    if not known.all():
        ids, counts = np.unique(category_ids[~known], return_counts=True)
        not_in_gt = {int(i): int(c) for i, c in zip(ids, counts, strict=True)}
        image_index, category_ids, bbox, score = image_index[known], category_ids[known], bbox[known], score[known]
    category_index = np.searchsorted(gt.category_ids, category_ids).astype(np.int64)
    log.debug("%s: %d detections", path, len(score))
    return Detections(source=str(path), image_index=image_index, category_index=category_index, bbox=bbox,
                      score=score, not_in_gt=not_in_gt)


def read_coco_gt(path: str | Path) -> GroundTruth:
    """Read and validate a COCO instances JSON file."""
    return ground_truth_from_dict(load_json(path), str(path))


def read_coco_results(path: str | Path, gt: GroundTruth) -> Detections:
    """Read and validate a COCO results JSON file against its ground truth."""
    return detections_from_list(load_json(path), gt, str(path))
