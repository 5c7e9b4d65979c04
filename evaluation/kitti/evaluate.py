"""KITTI object evaluation: 2D, BEV and 3D AP and AOS per class and difficulty (see README.md here).

``evaluate_kitti`` reads a ground-truth label directory and a detection label directory (16th
column = score), applies the devkit's class, difficulty and DontCare rules, and returns a
JSON-serialisable dict. AP values are fractions in [0, 1] (the devkit prints percent).
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from evaluation.kitti.ap import N_SAMPLE_PTS, exact_curve, official_curve
from evaluation.kitti.match import Problem
from evaluation.kitti.prepare import (
    DIFFICULTIES,
    NEIGHBOURS,
    Flat,
    OverlapRules,
    Pairs,
    det_flags,
    dontcare_overlap,
    flatten,
    gt_flags,
    pairs,
)
from evaluation.kitti.readers import KittiFormatError, KittiFrame, read_calib, read_label_dir

__all__ = ["METRICS", "MIN_OVERLAP_LOOSE", "MIN_OVERLAP_STRICT", "MODES", "RULES", "evaluate_kitti"]

log = logging.getLogger(__name__)

MODES = ("official", "port", "exact")
# official: the C++ devkit (double-precision polygons, its sentinel boxes, DontCare in every metric);
# port: the common Python port (float32 rotated IoU, DontCare in 2D only); both with the devkit's curve.
# exact: double precision, objects without a 3D box out of BEV/3D, the exact recall-indexed curve.
RULES: dict[str, OverlapRules] = {
    "official": OverlapRules(rotated="float64", sentinel_is_box=True, dontcare_metrics=("bbox", "bev", "3d")),
    "port": OverlapRules(rotated="port", sentinel_is_box=False, dontcare_metrics=("bbox",)),
    "exact": OverlapRules(rotated="float64", sentinel_is_box=False, dontcare_metrics=("bbox", "bev", "3d")),
}
METRICS = ("bbox", "bev", "3d", "aos")
# the devkit's overlap sets; "aos" always uses the bbox threshold
MIN_OVERLAP_STRICT: dict[str, float] = {
    "Car": 0.7, "Pedestrian": 0.5, "Cyclist": 0.5, "Van": 0.7, "Person_sitting": 0.5, "Truck": 0.7,
}  # fmt: skip
MIN_OVERLAP_LOOSE: dict[str, dict[str, float]] = {
    "Car": {"bbox": 0.7, "bev": 0.5, "3d": 0.5},
    "Pedestrian": {"bbox": 0.5, "bev": 0.25, "3d": 0.25},
    "Cyclist": {"bbox": 0.5, "bev": 0.25, "3d": 0.25},
    "Van": {"bbox": 0.7, "bev": 0.5, "3d": 0.5},
    "Person_sitting": {"bbox": 0.5, "bev": 0.25, "3d": 0.25},
    "Truck": {"bbox": 0.5, "bev": 0.5, "3d": 0.5},
}


def _overlaps(classes: Sequence[str], min_overlap: Mapping | None) -> dict[str, dict[str, float]]:
    """Per class and box metric, the overlap a detection must strictly exceed."""
    table = MIN_OVERLAP_STRICT if min_overlap is None else min_overlap
    out = {}
    for cls in classes:
        if cls not in table:
            raise ValueError(f"min_overlap has no entry for class {cls!r}; it has {sorted(table)}")
        entry = table[cls]
        per_metric = dict(entry) if isinstance(entry, Mapping) else {m: entry for m in ("bbox", "bev", "3d")}
        for metric in ("bbox", "bev", "3d"):
            value = per_metric.get(metric)
            if not isinstance(value, (int, float)) or not 0.0 <= float(value) < 1.0:
                raise ValueError(f"min_overlap[{cls!r}][{metric!r}] must be a number in [0, 1), got {value!r}")
        out[cls] = {m: float(per_metric[m]) for m in ("bbox", "bev", "3d")}
    return out


DEVKIT_CLASSES = ("car", "pedestrian", "cyclist")


def devkit_skipped(det: Flat, cls: str) -> list[str]:
    """The box metrics the devkit does not evaluate for ``cls``: it scores a class in 2D only if one of
    its detections has x1 >= 0, in BEV only if one has x, z != -1000 and w, l > 0, in 3D only if one
    has x, y, z != -1000 and h, w, l > 0 (loadDetections). Only its three classes are concerned."""
    if cls.lower() not in DEVKIT_CLASSES:
        return []
    mine = det.type == cls.lower()
    x, y, z, h, w, length = (det.box3d[mine, k] for k in range(6))
    ground = (x != -1000) & (z != -1000) & (w > 0) & (length > 0)
    evaluated = {
        "bbox": bool(np.any(det.bbox[mine, 0] >= 0)),
        "bev": bool(np.any(ground)),
        "3d": bool(np.any(ground & (y != -1000) & (h > 0))),
    }
    return [m for m, done in evaluated.items() if not done]


def _check_args(mode: str, classes: Sequence[str], metrics: Sequence[str]) -> None:
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; expected one of {MODES}")
    if isinstance(classes, str) or not classes or len(set(classes)) != len(classes):
        raise ValueError(f"classes must be a non-empty sequence of distinct names, got {classes!r}")
    unknown = [m for m in metrics if m not in METRICS]
    if unknown or not metrics or len(set(metrics)) != len(metrics):
        raise ValueError(f"metrics must be distinct names from {METRICS}, got {list(metrics)!r}")


def _load(gt_dir, det_dir, calib_dir) -> tuple[list[str], list[KittiFrame], list[KittiFrame], int]:
    gt = read_label_dir(gt_dir, with_score=False)
    det = read_label_dir(det_dir, with_score=True)
    unknown = sorted(set(det) - set(gt))
    if unknown:
        raise KittiFormatError(f"{det_dir}: detection files for frames without ground truth: {unknown[:10]}")
    frames = sorted(gt)
    missing = [f for f in frames if f not in det]
    if missing:
        log.warning("%d of %d frames have no detection file in %s; scored as empty", len(missing), len(frames), det_dir)
    if calib_dir is not None:
        for frame in frames:
            path = Path(calib_dir) / f"{frame}.txt"
            if not path.is_file():
                raise KittiFormatError(f"{path}: missing calibration file for frame {frame}")
            read_calib(path)
    empty = KittiFrame.empty(with_score=True)
    return frames, [gt[f] for f in frames], [det.get(f, empty) for f in frames], len(missing)


def _type_counts(frames: list[KittiFrame]) -> dict[str, int]:
    return dict(sorted(Counter(name for f in frames for name in f.type.tolist()).items()))


def _problem(gt: Flat, det: Flat, overlaps: Pairs, threshold: float, gt_flag, det_flag, in_dontcare) -> Problem:
    keep = (overlaps.overlap > threshold) & (gt_flag[overlaps.gt] != -1) & (det_flag[overlaps.det] != -1)
    return Problem(
        edge_gt=overlaps.gt[keep],
        edge_det=overlaps.det[keep],
        edge_overlap=overlaps.overlap[keep],
        gt_frame=gt.frame,
        gt_flag=gt_flag,
        det_flag=det_flag,
        det_score=det.score,
        gt_alpha=gt.alpha,
        det_alpha=det.alpha,
        det_in_dontcare=in_dontcare,
    )


def evaluate_kitti(
    gt_dir: str | Path,
    det_dir: str | Path,
    *,
    calib_dir: str | Path | None = None,
    mode: str = "official",
    classes: Sequence[str] = ("Car", "Pedestrian", "Cyclist"),
    min_overlap: Mapping[str, float] | Mapping[str, Mapping[str, float]] | None = None,
    metrics: Sequence[str] = METRICS,
) -> dict:
    """Score KITTI detections against KITTI ground truth.

    Args:
        gt_dir: label_2-style directory, one ``<frame>.txt`` per frame (15 columns).
        det_dir: detections in the same format plus a 16th column, the score. Frames without a file
            are scored as having no detections (and counted); files for unknown frames are an error.
        calib_dir: optional calib directory; when given every frame's calib file must exist and parse.
            Not needed for the metrics: labels are already in the rectified camera frame.
        mode: "official" (the C++ devkit evaluate_object.cpp, defects included: double-precision
            polygon overlaps, its score-threshold curve), "port" (the common Python port
            kitti_object_eval_python: its float32 rotated IoU, DontCare in 2D only) or "exact"
            (precision interpolated at exact recall points; see README.md here).
        classes: class names as written in the labels (matched case-insensitively, like the devkit).
        min_overlap: per class a float (all box metrics) or {"bbox", "bev", "3d"} -> float; a
            detection matches when its overlap is strictly greater. Default MIN_OVERLAP_STRICT
            (Car 0.7, Pedestrian 0.5, Cyclist 0.5); MIN_OVERLAP_LOOSE is the devkit's other set.
        metrics: subset of ("bbox", "bev", "3d", "aos"). AOS is skipped (None, with a note) when a
            detection has alpha = -10, as the devkit does.

    Returns:
        {"mode", "settings", "counts", "results": {class: {difficulty: {"num_gt", "num_gt_ignored",
        "num_det", metric: {"ap_r40", "ap_r11"}}}}, "notes"}; AP values are fractions in [0, 1] or
        None where undefined (exact mode, no ground truth) or, in official mode, where the devkit
        does not evaluate (see :func:`devkit_skipped`).

    Raises:
        KittiFormatError: malformed or inconsistent files.
        ValueError: invalid arguments.
    """
    _check_args(mode, classes, metrics)
    overlap_table = _overlaps(classes, min_overlap)
    frames, gt_frames, det_frames, n_missing = _load(gt_dir, det_dir, calib_dir)
    gt, det = flatten(gt_frames), flatten(det_frames)
    exact = mode == "exact"
    rules = RULES[mode]
    notes = []
    compute_aos = "aos" in metrics
    if compute_aos and np.any(det.alpha == -10):
        compute_aos = False
        notes.append("AOS skipped: some detections have alpha = -10 (unknown), as in the devkit")
    box_metrics = [m for m in ("bbox", "bev", "3d") if m in metrics or (m == "bbox" and compute_aos)]
    overlaps = {m: pairs(gt, det, len(frames), m, rules) for m in box_metrics}
    dontcare_share = {m: dontcare_overlap(gt, det, len(frames), m, rules) for m in box_metrics}
    curve_fn = exact_curve if exact else official_curve

    results: dict[str, dict] = {}
    for cls in classes:
        results[cls] = {}
        for diff in DIFFICULTIES:
            gt_flag, det_flag = gt_flags(gt, cls, diff), det_flags(det, cls, diff)
            entry: dict = {
                "num_gt": int(np.count_nonzero(gt_flag == 0)),
                "num_gt_ignored": int(np.count_nonzero(gt_flag == 1)),
                "num_det": int(np.count_nonzero(det_flag == 0)),
            }
            for metric in box_metrics:
                threshold = overlap_table[cls][metric]
                in_dc = dontcare_share[metric] > threshold
                problem = _problem(gt, det, overlaps[metric], threshold, gt_flag, det_flag, in_dc)
                summary = curve_fn(problem, compute_aos=compute_aos and metric == "bbox").summary(exact=exact)
                if metric in metrics:
                    entry[metric] = summary["ap"]
                if metric == "bbox" and compute_aos:
                    entry["aos"] = summary["aos"]
            if "aos" in metrics and not compute_aos:
                entry["aos"] = {"ap_r40": None, "ap_r11": None}
            counts = {k: entry[k] for k in ("num_gt", "num_gt_ignored", "num_det")}
            results[cls][diff.name] = counts | {m: entry[m] for m in metrics}
        if mode == "official":
            skipped = [m for m in devkit_skipped(det, cls) if m in metrics or (m == "bbox" and "aos" in metrics)]
            for metric in [*skipped, *(["aos"] if "bbox" in skipped and "aos" in metrics else [])]:
                for entry in results[cls].values():
                    if metric in entry:
                        entry[metric] = {"ap_r40": None, "ap_r11": None}
            if skipped:
                notes.append(f"{cls}: {', '.join(skipped)} not evaluated (None): no detection of the class qualifies, "
                             "and the devkit evaluates a class only when one does")
    log.info("KITTI %s evaluation of %d frames, %d GT, %d detections", mode, len(frames), len(gt), len(det))
    return {
        "mode": mode,
        "settings": {
            "classes": list(classes),
            "metrics": list(metrics),
            "min_overlap": overlap_table,
            "overlap_rule": "a detection matches when its overlap is strictly greater than min_overlap",
            "difficulties": {
                d.name: {
                    "min_height_px": d.min_height_px,
                    "max_occlusion": d.max_occlusion,
                    "max_truncation": d.max_truncation,
                }
                for d in DIFFICULTIES
            },
            "neighbour_classes": {k: v for k, v in NEIGHBOURS.items()},
            "recall_points": {"r40": [i / 40 for i in range(1, N_SAMPLE_PTS)], "r11": [i / 10 for i in range(11)]},
            "calib_checked": calib_dir is not None,
        },
        "counts": {
            "frames": len(frames),
            "frames_without_detection_file": n_missing,
            "gt": _type_counts(gt_frames),
            "detections": _type_counts(det_frames),
            "dontcare": int(np.count_nonzero(gt.type == "dontcare")),
        },
        "results": results,
        "notes": notes,
    }
