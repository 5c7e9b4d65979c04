"""Offline detector scoring on standard formats (COCO JSON, KITTI label dirs); see README.md here.

Public API:
    evaluate(gt, detections, out=None, *, iou_thresholds, group_by, metrics, score_threshold, kitti_options)
        -> Evaluation (metrics dict, curve data; ``.write(dir)``)
    METRICS: the metric registry (table, coco, kitti, errors)
    read_coco_gt / read_coco_results, accumulate_coco / summarize_coco: the COCO pieces on their own.

Imports nothing from ``pipeline`` or ``exporters``.
"""

from evaluation.api import METRICS, evaluate, parse_metrics
from evaluation.coco_ap import CocoParams, accumulate_coco, summarize_coco
from evaluation.io_coco import detections_from_list, ground_truth_from_dict, read_coco_gt, read_coco_results
from evaluation.results import Evaluation
from evaluation.validate import InputError

__all__ = [
    "METRICS",
    "CocoParams",
    "Evaluation",
    "InputError",
    "accumulate_coco",
    "detections_from_list",
    "evaluate",
    "ground_truth_from_dict",
    "parse_metrics",
    "read_coco_gt",
    "read_coco_results",
    "summarize_coco",
]
