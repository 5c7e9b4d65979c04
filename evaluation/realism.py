"""The realism gauge: how a detector trained on real photos sees road users, by class group, image group (the
condition) and box height, per frame and per object, and by distance beside the fog's transmittance.

Definitions (evaluation/README.md, "Realism"):

- **Class groups** (:data:`CLASS_GROUPS`) gather categories by their COCO name; a group is scored
  class-agnostically, so a van boxed as a truck is a vehicle found.
- **Matching** per (image, class group) at IoU >= 0.5, greedy by descending score (ties in file order), by
  pycocotools' rule (:func:`evaluation.matching.greedy_match`): a detection takes the free regular object of
  highest IoU, else an ignored one. *Ignored* objects: crowd regions, objects of the other groups (a rider boxed as
  a person is not a false person) and objects whose box height lies outside the height bin. A detection matched to
  an ignored object is neither TP nor FP; an unmatched one is ignored when its own height lies outside the bin
  (COCO's rule for area ranges), or when it overlaps (IoU >= 0.5) an object that a higher-ranked detection of
  another of the group's categories matched: the same road user boxed as a car and as a truck (the detector's NMS is
  class-wise) is one vehicle found, not a false one. A second box of the same category stays a false positive, as in
  COCO. Every detection of the group counts, with no limit per image.
- **Height bins** (:data:`HEIGHT_BINS_PX`) are ``[lo, hi)`` on the box height in pixels; ``all`` holds every
  object and every detection (the distance table uses it: far objects are small).
- **AP50**: COCO's 101-point interpolated precision over all the group's detections (whatever scores the results
  hold); **recall** and **precision** count the detections scoring >= the score threshold.
- **Objects**: an object is one ``track_id`` within one sequence, the images sharing the attributes
  :data:`SEQUENCE_KEYS` (a record's camera: scenario, seed, condition, camera); an annotation without a
  ``track_id`` is an object of its own. In a bin, an object's *frames* are the images where it is a regular
  object of that bin; it is **found (any)** when a detection >= the threshold matches it in at least one of them,
  **found (most)** in more than half of them; **mean share** is the mean over objects of the share of their frames
  found (so a car waiting ahead at a red light for 40 frames weighs as much as one passing in 3).
- **Distance bins** (:data:`DISTANCE_EDGES_M`, ``[lo, hi)`` metres on ``distance_m``, the last open) give the
  recall of every regular object with a distance; beside them, for an image group with a meteorological
  visibility V, Koschmieder's transmittance ``T = exp(-3.912 d / V)`` at the bin's centre (its lower edge for
  the last bin).
"""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import numpy as np

from evaluation.box_iou import box_iou
from evaluation.coco_ap import sort_detections
from evaluation.inputs import Detections, GroundTruth, image_groups
from evaluation.matching import greedy_match
from evaluation.validate import InputError

CLASS_GROUPS: dict[str, tuple[str, ...]] = {
    "vehicles": ("car", "bus", "truck"),
    "people": ("person",),
    "two-wheelers": ("bicycle", "motorcycle"),
}
HEIGHT_BINS_PX: dict[str, tuple[float, float]] = {
    "all": (0.0, np.inf), "30+": (30.0, np.inf), "30-60": (30.0, 60.0), "60+": (60.0, np.inf)}
REPORTED_HEIGHTS = ("30+", "30-60", "60+", "all")  # "all": every size, every false positive (small ones too)
DISTANCE_EDGES_M = (0.0, 10.0, 20.0, 30.0, 40.0, 60.0, 80.0, 120.0)
SEQUENCE_KEYS = ("scenario", "seed", "condition", "camera")
IOU_THRESHOLD = 0.5
KOSCHMIEDER = 3.912  # -ln(0.02): the 2 % contrast threshold that defines meteorological visibility
ALL = "all"


@dataclasses.dataclass(frozen=True)
class GroupMatch:
    """One class group's matching at IoU 0.5 in every height bin.

    Attributes:
        bins: the height bin labels, in :data:`HEIGHT_BINS_PX` order (A of them).
        gt_counted: (Ng, A) bool, a regular object of the group in the bin (not ignored).
        gt_found: (Ng, A) bool, counted and matched by a detection scoring >= the threshold.
        dt_index: (Nd,) int64 the group's detections (indices into the detections), in matching order.
        dt_tp: (Nd, A) bool matched a counted object.
        dt_fp: (Nd, A) bool matched nothing and not ignored.
    """

    bins: tuple[str, ...]
    gt_counted: np.ndarray
    gt_found: np.ndarray
    dt_index: np.ndarray
    dt_tp: np.ndarray
    dt_fp: np.ndarray


def _in_bins(height_px: np.ndarray) -> np.ndarray:
    """(N, A) bool: the height lies in each bin of :data:`HEIGHT_BINS_PX`."""
    lo = np.array([b[0] for b in HEIGHT_BINS_PX.values()])
    hi = np.array([b[1] for b in HEIGHT_BINS_PX.values()])
    return (height_px[:, None] >= lo) & (height_px[:, None] < hi)


def group_categories(gt: GroundTruth, names: tuple[str, ...]) -> np.ndarray:
    """Indices into ``gt.category_ids`` of the categories named ``names`` (those the ground truth has)."""
    return np.array([i for i, n in enumerate(gt.category_names) if n in names], dtype=np.int64)


def _second_names(dt: Detections, didx: np.ndarray, matched_gt: np.ndarray, gt_boxes: np.ndarray) -> np.ndarray:
    """(Nd, A) bool: an unmatched detection overlapping (IoU >= 0.5) an object that a higher-ranked detection of
    another category of the group matched in its image: the same road user boxed under a second name of the group
    (car and truck), which the detector's class-wise NMS keeps. Only unmatched detections are looked at (a loop over
    them: a few per image)."""
    out = np.zeros(matched_gt.shape, bool)
    image, category = dt.image_index[didx], dt.category_index[didx]
    first = np.searchsorted(image, image, side="left")  # didx is in (image, rank) order
    for k, a in zip(*np.nonzero(matched_gt < 0), strict=True):
        before = np.arange(first[k], k)
        before = before[(matched_gt[before, a] >= 0) & (category[before] != category[k])]
        if len(before):
            out[k, a] = bool((box_iou(dt.bbox[didx[k]][None], gt_boxes[matched_gt[before, a]]) >= IOU_THRESHOLD).any())
    return out


def match_group(gt: GroundTruth, dt: Detections, categories: np.ndarray, score_threshold: float) -> GroupMatch:
    """Match the detections of the categories ``categories`` (indices) to the group's objects, every height bin."""
    in_group = np.isin(gt.category_index, categories) & ~gt.iscrowd
    counted = in_group[:, None] & _in_bins(gt.bbox[:, 3])
    sel = np.flatnonzero(np.isin(dt.category_index, categories))
    order, _ = sort_detections(dt.image_index[sel], dt.score[sel])
    didx = sel[order]
    n_bins = len(HEIGHT_BINS_PX)
    matched_gt = np.full((len(didx), n_bins), -1, np.int64)
    if len(gt) and len(didx):
        gorder = np.argsort(gt.image_index, kind="stable")
        m = greedy_match(dt.image_index[didx], dt.bbox[didx], gt.image_index[gorder], gt.bbox[gorder],
                         gt.iscrowd[gorder], ~counted[gorder], np.array([IOU_THRESHOLD]), gt.num_images)[:, :, 0]
        matched_gt = np.where(m >= 0, gorder[np.maximum(m, 0)], -1)
    matched = matched_gt >= 0
    bins = np.arange(n_bins)[None, :]
    hit_counted = counted[np.maximum(matched_gt, 0), bins] if len(gt) else np.zeros_like(matched)
    outside = ~_in_bins(dt.bbox[didx, 3])
    ignored = np.where(matched, ~hit_counted, outside)
    ignored |= ~matched & ~ignored & _second_names(dt, didx, matched_gt, gt.bbox)
    tp, fp = matched & ~ignored, ~matched & ~ignored
    found = np.zeros(counted.shape, bool)
    r, a = np.nonzero(tp & (dt.score[didx] >= score_threshold)[:, None])
    found[matched_gt[r, a], a] = True
    return GroupMatch(bins=tuple(HEIGHT_BINS_PX), gt_counted=counted, gt_found=found, dt_index=didx, dt_tp=tp,
                      dt_fp=fp)


def ap_101(tp: np.ndarray, fp: np.ndarray, score: np.ndarray, n_gt: int) -> float | None:
    """COCO's 101-point interpolated AP of (n,) bool TP and FP flags in matching order with their (n,) scores
    (sorted by descending score, ties in the given order, as pycocotools does); None without objects."""
    if n_gt == 0:
        return None
    order = np.argsort(-score, kind="mergesort")
    tpc = np.cumsum(tp[order], dtype=np.float64)
    fpc = np.cumsum(fp[order], dtype=np.float64)
    recall = tpc / n_gt
    precision = tpc / (tpc + fpc + np.spacing(1))
    envelope = np.maximum.accumulate(precision[::-1])[::-1]
    at = np.searchsorted(recall, np.linspace(0.0, 1.0, 101), side="left")
    q = np.zeros(101)
    q[at < len(recall)] = envelope[at[at < len(recall)]]
    return float(q.mean())


def object_index(gt: GroundTruth, keys: tuple[str, ...] = SEQUENCE_KEYS) -> np.ndarray:
    """(Ng,) int64 object of each annotation: its track within its image's sequence (the image attributes
    ``keys``), or the annotation alone when it has no track id."""
    seq_of: dict[tuple, int] = {}
    image_seq = np.array([seq_of.setdefault(tuple(str(a.get(k)) for k in keys), len(seq_of))
                          for a in gt.image_attrs], dtype=np.int64)
    ident = np.where(gt.track_valid, gt.track_id, gt.ann_ids)
    table = np.stack([image_seq[gt.image_index] if len(gt) else np.zeros(0, np.int64),
                      (~gt.track_valid).astype(np.int64), ident], axis=1)
    if not len(gt):
        return np.zeros(0, np.int64)
    return np.unique(table, axis=0, return_inverse=True)[1].ravel().astype(np.int64)


def _ratio(num: float, den: float) -> float | None:
    return None if den == 0 else float(num / den)


def object_recall(objects: np.ndarray, found: np.ndarray) -> dict[str, Any]:
    """Per-object recall of annotations ``objects`` ((n,) object index) found or not ((n,) bool)."""
    ids, inverse = np.unique(objects, return_inverse=True)
    frames = np.bincount(inverse, minlength=len(ids))
    hits = np.bincount(inverse, weights=found, minlength=len(ids))
    return {"objects": len(ids), "objects_found_any": int((hits > 0).sum()),
            "objects_found_most": int((2 * hits > frames).sum()),
            "object_recall_any": _ratio((hits > 0).sum(), len(ids)),
            "object_recall_most": _ratio((2 * hits > frames).sum(), len(ids)),
            "object_mean_share": float(np.mean(hits / frames)) if len(ids) else None}


def _row(gm: GroupMatch, a: int, gt_sel: np.ndarray, dt_sel: np.ndarray, score: np.ndarray, objects: np.ndarray,
         score_threshold: float) -> dict[str, Any]:
    """Frame and object figures of one (class group, image group, height bin)."""
    counted = gm.gt_counted[:, a] & gt_sel
    n_gt = int(counted.sum())
    tp, fp = gm.dt_tp[dt_sel, a], gm.dt_fp[dt_sel, a]
    above = score >= score_threshold
    n_tp, n_fp = int((tp & above).sum()), int((fp & above).sum())
    return {"gt": n_gt, "tp": n_tp, "fp": n_fp, "fn": n_gt - n_tp, "ap50": ap_101(tp, fp, score, n_gt),
            "recall": _ratio(n_tp, n_gt), "precision": _ratio(n_tp, n_tp + n_fp),
            **object_recall(objects[counted], gm.gt_found[counted, a])}


def missed_objects(gt: GroundTruth, gm: GroupMatch, objects: np.ndarray, height: str = "30+") -> np.ndarray:
    """Annotation indices, one per object of the bin found in none of its frames: its tallest box (ties: the first
    annotation), ordered tallest first (the most glaring misses), then by annotation order."""
    a = gm.bins.index(height)
    counted = np.flatnonzero(gm.gt_counted[:, a])
    hit = np.zeros(len(objects), bool)
    hit[np.unique(objects[counted[gm.gt_found[counted, a]]])] = True
    missed = counted[~hit[objects[counted]]]
    order = np.lexsort((missed, -gt.bbox[missed, 3], objects[missed]))  # per object, tallest first
    missed = missed[order]
    first = np.r_[True, objects[missed][1:] != objects[missed][:-1]] if len(missed) else np.zeros(0, bool)
    picked = missed[first]
    return picked[np.lexsort((picked, -gt.bbox[picked, 3]))]


PERSON_ORDER = ("adult", "teen", "child", "wheelchair_user", "rider")
"""The order of the people-by-person rows (others after, alphabetically)."""


def person_rows(gt: GroundTruth, gm: GroupMatch, image_sets: dict[str, np.ndarray],
                objects: np.ndarray) -> list[dict[str, Any]]:
    """The people group's recall by who the person is (the annotations' ``person``), per image group and height bin
    of :data:`REPORTED_HEIGHTS` but ``all``: objects, found in frames and as objects. Precision has no place here (a
    false detection is nobody). Empty where no counted annotation says who it is."""
    said = gm.gt_counted.any(axis=1) & (gt.person != "")
    if not said.any():
        return []
    kinds = sorted(set(gt.person[said].tolist()), key=lambda k: (k not in PERSON_ORDER, PERSON_ORDER.index(k)
                                                                 if k in PERSON_ORDER else 0, k))
    rows = []
    for value, images in image_sets.items():
        for height in REPORTED_HEIGHTS[:-1]:
            a = gm.bins.index(height)
            for kind in kinds:
                counted = gm.gt_counted[:, a] & images[gt.image_index] & (gt.person == kind)
                n, k = int(counted.sum()), int((gm.gt_found[:, a] & counted).sum())
                if n:
                    rows.append({"group": value, "height_px": height, "person": kind, "gt": n, "found": k,
                                 "recall": _ratio(k, n), **object_recall(objects[counted], gm.gt_found[counted, a])})
    return rows


def distance_labels(edges: tuple[float, ...] = DISTANCE_EDGES_M) -> list[str]:
    return [f"{lo:g}-{hi:g}" for lo, hi in itertools.pairwise(edges)] + [f"{edges[-1]:g}+"]


def transmittance(distance_m: float, visibility_m: float) -> float:
    """Koschmieder's transmittance of clear air over ``distance_m`` in fog of meteorological visibility."""
    return float(np.exp(-KOSCHMIEDER * distance_m / visibility_m))


def _distance_rows(gt: GroundTruth, gm: GroupMatch, gt_sel: np.ndarray, visibility_m: float | None,
                   edges: tuple[float, ...]) -> list[dict[str, Any]]:
    a = gm.bins.index(ALL)
    counted = gm.gt_counted[:, a] & gt_sel & gt.distance_valid
    which = np.searchsorted(np.asarray(edges), gt.distance_m, side="right") - 1
    rows = []
    for b, label in enumerate(distance_labels(edges)):
        lo = edges[b]
        hi = edges[b + 1] if b + 1 < len(edges) else None
        inside = counted & (which == b)
        n, n_tp = int(inside.sum()), int((inside & gm.gt_found[:, a]).sum())
        centre = lo if hi is None else (lo + hi) / 2
        rows.append({"bin": label, "lo_m": lo, "hi_m": hi, "gt": n, "tp": n_tp, "recall": _ratio(n_tp, n),
                     "transmittance": None if visibility_m is None else transmittance(centre, visibility_m)})
    return rows


def realism_metrics(gt: GroundTruth, dt: Detections, *, score_threshold: float, group_by: str = "condition",
                    visibility_m: dict[str, float] | None = None, group_order: list[str] | None = None,
                    distance_edges_m: tuple[float, ...] = DISTANCE_EDGES_M) -> tuple[dict[str, Any], dict]:
    """The realism metrics (metrics.json's content) and, per class group, its :class:`GroupMatch` and the
    object index of each annotation (for the contact sheets of missed objects).

    Args:
        score_threshold: the detector's operating threshold (recall, precision, objects found).
        group_by: image attribute of the image groups (rows); ``all`` is every image.
        group_order: the image groups' order (e.g. morning, noon, dusk, night, fog, rain); groups it does not list
            come after, in the order of their first image in the ground truth (values it lists that no image has are
            left out).
        visibility_m: meteorological visibility by image group value (fog, rain), for the transmittance.
        distance_edges_m: lower edges of the distance bins, ascending from 0.
    """
    if not np.isfinite(score_threshold):
        raise InputError(f"score threshold must be finite, got {score_threshold}")
    if list(distance_edges_m) != sorted(set(distance_edges_m)) or distance_edges_m[0] != 0:
        raise InputError(f"distance edges must ascend from 0 without repeats, got {list(distance_edges_m)}")
    visibility_m = dict(visibility_m or {})
    names, image_group = image_groups(gt, group_by)
    first_seen = np.unique(image_group, return_index=True)[1] if gt.num_images else np.zeros(0, np.int64)
    rank = {v: k for k, v in enumerate(group_order or ())}
    order = sorted(range(len(names)), key=lambda i: (rank.get(names[i], len(rank)), first_seen[i]))
    image_sets = {ALL: np.ones(gt.num_images, bool), **{names[i]: image_group == i for i in order}}
    objects = object_index(gt)
    rows, distance, matches = [], [], {}
    for group, categories in CLASS_GROUPS.items():
        gm = match_group(gt, dt, group_categories(gt, categories), score_threshold)
        matches[group] = gm
        score = dt.score[gm.dt_index]
        for value, images in image_sets.items():
            gt_sel, dt_sel = images[gt.image_index], images[dt.image_index[gm.dt_index]]
            for height in REPORTED_HEIGHTS:
                a = gm.bins.index(height)
                rows.append({"class_group": group, "group": value, "height_px": height, "images": int(images.sum()),
                             **_row(gm, a, gt_sel, dt_sel, score[dt_sel], objects, score_threshold)})
            distance += [{"class_group": group, "group": value, **r}
                         for r in _distance_rows(gt, gm, gt_sel, visibility_m.get(value), distance_edges_m)]
    a30 = tuple(HEIGHT_BINS_PX).index("30+")
    per_frame = {value: {group: _ratio(int((matches[group].gt_counted[:, a30] & images[gt.image_index]).sum()),
                                       int(images.sum())) for group in CLASS_GROUPS}
                 for value, images in image_sets.items()}
    metrics = {
        "score_threshold": float(score_threshold), "iou_threshold": IOU_THRESHOLD, "group_by": group_by,
        "class_groups": {g: list(c) for g, c in CLASS_GROUPS.items()},
        "height_bins_px": {k: [lo, None if np.isinf(hi) else hi] for k, (lo, hi) in HEIGHT_BINS_PX.items()},
        "sequence_keys": list(SEQUENCE_KEYS), "rows": rows,
        "distance": {"edges_m": list(distance_edges_m), "height_px": ALL, "visibility_m": visibility_m,
                     "rows": distance},
        "objects_per_frame": {"height_px": "30+", "by_group": per_frame},
        "people_by_person": person_rows(gt, matches["people"], image_sets, objects),
    }
    return metrics, {"matches": matches, "objects": objects}
