"""``evaluation.evaluate``: read inputs, run the chosen metrics, return (and optionally write) the results.

Metrics are chosen by name from :data:`METRICS`, a registry that refuses duplicate registrations,
unknown names and repeated names. Every key of metrics.json is always present: a metric that was not
requested or does not apply records ``{"skipped": reason}`` instead of disappearing. The results are an
:class:`evaluation.results.Evaluation`, which writes itself.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.coco_ap import accumulate_coco, coco_stats_by_group, summarize_coco
from evaluation.curves import sweeps
from evaluation.error_breakdown import FG_IOU, error_breakdown
from evaluation.inputs import Detections, GroundTruth, image_groups
from evaluation.io_coco import read_coco_gt, read_coco_results
from evaluation.io_kitti import _kitti, read_kitti
from evaluation.results import Evaluation
from evaluation.table import DEFAULT_IOU_THRESHOLDS, DEFAULT_SCORE_THRESHOLD, TableMatches, match_table, table_rows
from evaluation.validate import InputError

log = logging.getLogger(__name__)
METRICS: dict[str, Callable[[_Context], dict[str, Any]]] = {}


def register_metric(name: str):
    """Register a metric function under ``name``; a second registration of the same name is an error."""

    def wrap(fn):
        if name in METRICS:
            raise ValueError(f"metric '{name}' is already registered")
        METRICS[name] = fn
        return fn

    return wrap


def parse_metrics(names: Sequence[str] | str) -> tuple[str, ...]:
    """Validate metric names (a sequence or ``"a,b"``); unknown or repeated names are errors."""
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    unknown = [n for n in names if n not in METRICS]
    if unknown:
        raise InputError(f"unknown metric(s) {', '.join(unknown)} (known: {', '.join(METRICS)})")
    if len(set(names)) != len(names):
        raise InputError(f"metric listed twice in {','.join(names)}")
    if not names:
        raise InputError(f"no metric chosen (known: {', '.join(METRICS)})")
    return tuple(names)


@dataclasses.dataclass
class _Context:
    gt: GroundTruth
    dt: Detections
    kind: str  # "coco" | "kitti"
    gt_path: Path
    det_path: Path
    iou_thresholds: tuple[float, ...]
    score_threshold: float
    group_by: str | None
    kitti_options: dict[str, Any]
    ignored: dict[str, Any]
    artifacts: dict[str, Any] = dataclasses.field(default_factory=dict)
    _matches: dict[tuple[float, ...], TableMatches] = dataclasses.field(default_factory=dict)

    def matches(self, thresholds: tuple[float, ...]) -> TableMatches:
        if thresholds not in self._matches:
            self._matches[thresholds] = match_table(self.gt, self.dt, thresholds)
        return self._matches[thresholds]


@register_metric("table")
def _table(ctx: _Context) -> dict[str, Any]:
    m = ctx.matches(ctx.iou_thresholds)
    best, curves = sweeps(ctx.gt, ctx.dt, m, ctx.group_by)
    ctx.artifacts["curves"] = curves
    return {"score_threshold": ctx.score_threshold, "iou_thresholds": list(ctx.iou_thresholds),
            "group_by": ctx.group_by, "rows": table_rows(ctx.gt, ctx.dt, m, ctx.score_threshold, ctx.group_by),
            "f1_optimal": best}


@register_metric("coco")
def _coco(ctx: _Context) -> dict[str, Any]:
    acc = accumulate_coco(ctx.gt, ctx.dt)
    ctx.artifacts["coco_accumulation"] = acc
    ctx.ignored["coco_detections_beyond_max_dets"] = acc.dropped_beyond_max_dets
    result = summarize_coco(acc, ctx.gt.category_names)
    if ctx.group_by is not None:
        names, index = image_groups(ctx.gt, ctx.group_by)
        result["group_by"] = ctx.group_by
        result["stats_by_group"] = coco_stats_by_group(ctx.gt, ctx.dt, index, names)
    if ctx.kind == "kitti":
        result["note"] = "computed on KITTI labels converted to COCO boxes (DontCare as crowd regions)"
    return result


@register_metric("kitti")
def _kitti_metric(ctx: _Context) -> dict[str, Any]:
    if ctx.kind != "kitti":
        return {"skipped": "the ground truth is a COCO file; KITTI AP needs KITTI label directories"}
    kitti = _kitti()
    result = kitti.evaluate_kitti(ctx.gt_path, ctx.det_path, **ctx.kitti_options)
    ctx.artifacts["kitti_markdown"] = kitti.kitti_summary_markdown(result)
    return result


@register_metric("errors")
def _errors(ctx: _Context) -> dict[str, Any]:
    thresholds = ctx.iou_thresholds if FG_IOU in ctx.iou_thresholds else (FG_IOU,)
    return error_breakdown(ctx.gt, ctx.dt, ctx.matches(thresholds), ctx.score_threshold)


def load_inputs(gt: str | Path, detections: str | Path) -> tuple[GroundTruth, Detections, str, dict[str, int]]:
    """Read ground truth and detections: a COCO JSON pair, or KITTI label directories."""
    gt, detections = Path(gt), Path(detections)
    if not gt.exists():
        raise FileNotFoundError(f"{gt}: ground truth not found")
    if not detections.exists():
        raise FileNotFoundError(f"{detections}: detections not found")
    if gt.is_dir():
        g, d, ignored = read_kitti(gt, detections)
        return g, d, "kitti", ignored
    if detections.is_dir():
        raise InputError(f"{detections}: a directory, but the ground truth {gt} is a COCO file (give a COCO "
                         "results JSON)")
    g = read_coco_gt(gt)
    return g, read_coco_results(detections, g), "coco", {}


def evaluate(
    gt: str | Path,
    detections: str | Path,
    out: str | Path | None = None,
    *,
    iou_thresholds: Sequence[float] = DEFAULT_IOU_THRESHOLDS,
    group_by: str | None = None,
    metrics: Sequence[str] | str = tuple(METRICS),
    score_threshold: float = DEFAULT_SCORE_THRESHOLD,
    kitti_options: dict[str, Any] | None = None,
) -> Evaluation:
    """Score detections against ground truth.

    Args:
        gt: COCO instances JSON, or a KITTI label_2 directory.
        detections: COCO results JSON, or a KITTI label directory with a 16th column (score).
        out: if given, write metrics.json, plots/ and report.md there (not atomically: the CLI is).
        iou_thresholds: IoU thresholds of the table, each in (0, 1].
        group_by: an image attribute (COCO ``images[].KEY``) giving one table row per value.
        metrics: names from :data:`METRICS`.
        score_threshold: detections with a lower score are not counted in the table and errors.
        kitti_options: keyword arguments of ``evaluation.kitti.evaluate_kitti`` (calib_dir, mode, ...).
    """
    chosen = parse_metrics(metrics)
    thresholds = tuple(float(t) for t in iou_thresholds)
    if not thresholds or any(not 0 < t <= 1 for t in thresholds) or len(set(thresholds)) != len(thresholds):
        raise InputError(f"IoU thresholds must be distinct values in (0, 1], got {list(iou_thresholds)}")
    if not np.isfinite(score_threshold):
        raise InputError(f"score threshold must be finite, got {score_threshold}")
    g, d, kind, ignored = load_inputs(gt, detections)
    if d.not_in_gt:
        log.info("%s: %d detections of categories the ground truth lacks are not scored (by category id: %s)",
                 detections, sum(d.not_in_gt.values()), d.not_in_gt)
    ignored.update({"detections_of_categories_not_in_gt": sum(d.not_in_gt.values()),
                    "detections_by_category_not_in_gt": {str(k): v for k, v in sorted(d.not_in_gt.items())},
                    "crowd_gt": int(g.iscrowd.sum()),
                    "detections_below_score_threshold": int((d.score < score_threshold).sum())})
    ctx = _Context(gt=g, dt=d, kind=kind, gt_path=Path(gt), det_path=Path(detections), iou_thresholds=thresholds,
                   score_threshold=float(score_threshold), group_by=group_by, kitti_options=dict(kitti_options or {}),
                   ignored=ignored)
    result: dict[str, Any] = {}
    for name in METRICS:
        result[name] = METRICS[name](ctx) if name in chosen else {"skipped": "not requested"}
        log.info("%s: %s", name, "skipped" if "skipped" in result[name] else "done")
    result["ignored"] = ctx.ignored
    acc = ctx.artifacts.get("coco_accumulation")
    evaluation = Evaluation(metrics=result, curves=ctx.artifacts.get("curves", []),
                            coco_precision=None if acc is None else acc.precision,
                            kitti_markdown=ctx.artifacts.get("kitti_markdown"))
    if out is not None:
        evaluation.write(out)
    return evaluation
