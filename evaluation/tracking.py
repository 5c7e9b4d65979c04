"""Multi-object tracking metrics (HOTA, CLEAR MOT, identity) on MOTChallenge files, with TrackEval as the engine.

TrackEval (``trackeval`` on PyPI) is the tool of record for these metrics; its metric classes (``HOTA``, ``CLEAR``,
``Identity``) compute everything here. This module is the adapter around them: it reads and validates the files
(:mod:`evaluation.io_mot`), prepares each sequence as TrackEval's ``MotChallenge2DBox`` dataset does, and combines
sequences as TrackEval's ``Evaluator`` does. The one generalisation: MOTChallenge evaluates the pedestrian class (1)
only; here ``classes`` (default :data:`DEFAULT_CLASSES`, every MOT object class roadsynth's MOT export writes) are
evaluated together as one class, since tracker output is class-agnostic. With ``classes=(1,)`` the results are
TrackEval's MOT17 results (tests/evaluation/test_tracking_eval.py runs TrackEval on the same files).

Preparation per frame (TrackEval's MOTChallenge rules):

1. IoU of every ground-truth box (all classes) with every tracker box;
2. a Hungarian matching at IoU >= 0.5; tracker boxes matched to a distractor class
   (:data:`evaluation.io_mot.DISTRACTOR_CLASSES`) are removed: covering a distractor is not an error;
3. ground-truth boxes with ``considered`` 0 or outside ``classes`` are removed;
4. ids are renumbered 0 .. n-1 over the sequence.

Values are fractions in [0, 1] (TrackEval's summaries print them x 100); HOTA's per-alpha arrays are averaged over
the 19 alphas 0.05 .. 0.95, as in TrackEval's summary, and also given per alpha.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.io_mot import DISTRACTOR_CLASSES, MOT_CLASSES, MotBoxes, read_gt, read_results
from evaluation.validate import InputError

log = logging.getLogger(__name__)

DEFAULT_CLASSES = (1, 3, 4, 5)
"""MOT classes evaluated by default: pedestrian, car, bicycle, motorbike (those roadsynth's MOT export writes)."""
IOU_THRESHOLD = 0.5
COUNTS = {"CLR_TP", "CLR_FN", "CLR_FP", "IDSW", "Frag", "MT", "PT", "ML"}
MAIN_METRICS = ("HOTA", "DetA", "AssA", "DetRe", "DetPr", "AssRe", "AssPr", "LocA", "MOTA", "MOTP", "IDF1", "IDR",
                "IDP", "CLR_TP", "CLR_FN", "CLR_FP", "IDSW", "Frag", "MT", "PT", "ML")


def _trackeval():
    try:
        import trackeval
    except ImportError:
        raise InputError("tracking evaluation needs TrackEval: pip install --no-deps 'trackeval>=1.3,<2' (--no-deps: "
                         "it declares opencv-python, whose cv2 would replace opencv-python-headless's)") from None
    return trackeval


def prepare_sequence(name: str, gt: MotBoxes, tracker: MotBoxes, classes: tuple[int, ...]) -> dict[str, Any]:
    """One sequence as TrackEval's metrics take it (``MotChallenge2DBox.get_preprocessed_seq_data``'s output)."""
    from scipy.optimize import linear_sum_assignment

    trackeval = _trackeval()
    ious = trackeval.datasets._base_dataset._BaseDataset._calculate_box_ious
    eps = np.finfo("float").eps
    data: dict[str, Any] = {k: [] for k in ("gt_ids", "tracker_ids", "gt_dets", "tracker_dets",
                                            "tracker_confidences", "similarity_scores")}
    for t in range(1, gt.length + 1):
        g, r = gt.frame == t, tracker.frame == t
        gt_ids, gt_dets, gt_cls = gt.ids[g], gt.boxes[g], gt.classes[g]
        tr_ids, tr_dets = tracker.ids[r], tracker.boxes[r]
        sim = ious(gt_dets, tr_dets, box_format="xywh")
        remove = np.array([], int)
        if len(gt_ids) and len(tr_ids):
            scores = sim.copy()
            scores[scores < IOU_THRESHOLD - eps] = 0
            rows, cols = linear_sum_assignment(-scores)
            matched = scores[rows, cols] > 0 + eps
            rows, cols = rows[matched], cols[matched]
            remove = cols[np.isin(gt_cls[rows], DISTRACTOR_CLASSES)]
        keep_gt = gt.considered[g] & np.isin(gt_cls, classes)
        data["gt_ids"].append(gt_ids[keep_gt])
        data["gt_dets"].append(gt_dets[keep_gt])
        data["tracker_ids"].append(np.delete(tr_ids, remove))
        data["tracker_dets"].append(np.delete(tr_dets, remove, axis=0))
        data["tracker_confidences"].append(np.ones(len(tr_ids) - len(remove)))
        data["similarity_scores"].append(np.delete(sim, remove, axis=1)[keep_gt])
    for kind in ("gt", "tracker"):
        ids = data[f"{kind}_ids"]
        unique = np.unique(np.concatenate(ids)) if ids else np.array([], int)
        data[f"{kind}_ids"] = [np.searchsorted(unique, x).astype(int) for x in ids]
        data[f"num_{kind}_ids"] = len(unique)
        data[f"num_{kind}_dets"] = int(sum(len(x) for x in ids))
    data["num_timesteps"] = gt.length
    data["seq"] = name
    return data


def _summary(results: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """metrics.json's entry for one sequence (or the combination): main values, counts, HOTA per alpha."""
    out: dict[str, Any] = {}
    for metric in results.values():
        for key, value in metric.items():
            array = np.asarray(value)
            out[key] = float(array.mean()) if array.ndim else (int(value) if isinstance(value, (int, np.integer))
                                                                else float(value))
    out["HOTA_per_alpha"] = {f"{a:.2f}": float(v) for a, v in zip(np.arange(0.05, 0.99, 0.05), results["HOTA"]["HOTA"],
                                                                   strict=True)}
    return out


def evaluate_tracking(gt_path: Path, results_path: Path, classes: tuple[int, ...] = DEFAULT_CLASSES
                      ) -> dict[str, Any]:
    """HOTA, CLEAR and identity metrics of the tracker results against MOT ground truth; the metrics.json dict:
    ``combined`` (all sequences, TrackEval's combination), ``sequences`` (each), ``classes``, ``counts``."""
    trackeval = _trackeval()
    gt = read_gt(Path(gt_path))
    tracker = read_results(Path(results_path), gt)
    metrics = {"HOTA": trackeval.metrics.HOTA(), "CLEAR": trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               "Identity": trackeval.metrics.Identity({"PRINT_CONFIG": False})}
    per_seq: dict[str, dict[str, Any]] = {}
    counts = {}
    for name in gt:
        data = prepare_sequence(name, gt[name], tracker[name], tuple(classes))
        per_seq[name] = {m: metric.eval_sequence(data) for m, metric in metrics.items()}
        counts[name] = {"frames": gt[name].length, "gt_boxes": data["num_gt_dets"], "gt_tracks": data["num_gt_ids"],
                        "tracker_boxes": data["num_tracker_dets"], "tracker_tracks": data["num_tracker_ids"],
                        "tracker_boxes_on_distractors": len(tracker[name].ids) - data["num_tracker_dets"]}
    combined = {m: metric.combine_sequences({s: r[m] for s, r in per_seq.items()}) for m, metric in metrics.items()}
    return {"task": "tracking", "engine": f"trackeval {getattr(trackeval, '__version__', '')}".strip(),
            "classes": {str(c): _class_name(c) for c in classes}, "iou_threshold": IOU_THRESHOLD,
            "combined": _summary(combined), "sequences": {s: _summary(r) for s, r in per_seq.items()},
            "counts": counts}


def _class_name(cls: int) -> str:
    return MOT_CLASSES.get(int(cls), "unknown")


def markdown_summary(metrics: dict[str, Any]) -> str:
    """report.md: the main metrics per sequence and combined, as a Markdown table."""
    rows = [("combined", metrics["combined"]), *metrics["sequences"].items()]
    head = "| sequence | " + " | ".join(MAIN_METRICS) + " |\n|---|" + "---:|" * len(MAIN_METRICS) + "\n"
    body = "".join(f"| {name} | " + " | ".join(_fmt(k, values[k]) for k in MAIN_METRICS) + " |\n"
                   for name, values in rows)
    return f"# Tracking evaluation\n\nTrackEval's metrics; fractions, not percentages.\n\n{head}{body}"


def _fmt(key: str, value: float | int) -> str:
    return str(round(value)) if key in COUNTS else f"{value:.4f}"
