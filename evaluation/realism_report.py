"""``evaluation.evaluate_realism``: the realism gauge of a detector on a COCO export, written as a folder:
realism.md, metrics.json, one contact sheet of missed objects per class group (``missed_<group>.png``) and
recall_by_distance.png. Reads the ground truth (with its ``track_id`` and ``distance_m``), the results and the
images; the metrics are :mod:`evaluation.realism`'s."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

from evaluation.api import load_inputs
from evaluation.inputs import image_groups
from evaluation.realism import CLASS_GROUPS, missed_objects, realism_metrics
from evaluation.realism_images import contact_sheet, distance_plot, mean_luma, write_png
from evaluation.realism_markdown import realism_markdown
from evaluation.validate import InputError

log = logging.getLogger(__name__)
SHEET_LIMIT = 64


def sheet_name(class_group: str) -> str:
    return f"missed_{class_group.replace('-', '_')}.png"


def evaluate_realism(gt: str | Path, detections: str | Path, out: str | Path, *, images: str | Path | None = None,
                     score_threshold: float, group_by: str = "condition",
                     visibility_m: dict[str, float] | None = None, sheet_limit: int = SHEET_LIMIT,
                     group_order: list[str] | None = None, title: str | None = None) -> dict[str, Any]:
    """Score ``detections`` (COCO results) on ``gt`` (COCO instances) and write the realism folder into ``out``
    (not atomically: the CLI is). ``images``: the folder of the images' ``file_name`` (default: the ground
    truth's folder's ``images/``); ``group_order``: the rows' order (:func:`evaluation.realism.realism_metrics`);
    ``title``: realism.md's (default: names the detections file). Returns the metrics (metrics.json's content)."""
    gt, out = Path(gt), Path(out)
    images = Path(images) if images is not None else gt.parent / "images"
    g, d, kind, _ = load_inputs(gt, detections)
    if kind != "coco":
        raise InputError(f"{gt}: the realism gauge reads COCO ground truth (it needs the images and their track ids)")
    metrics, extra = realism_metrics(g, d, score_threshold=score_threshold, group_by=group_by,
                                     visibility_m=visibility_m, group_order=group_order)
    names, image_group = image_groups(g, group_by)
    metrics["luma"] = mean_luma(g, images, image_group, names)
    metrics["detections_not_scored"] = {str(k): v for k, v in sorted(d.not_in_gt.items())}
    out.mkdir(parents=True, exist_ok=True)
    missed = {}
    for group in CLASS_GROUPS:
        picked = missed_objects(g, extra["matches"][group], extra["objects"])
        sheet = contact_sheet(g, images, picked, group_by, sheet_limit)
        if sheet is not None:
            write_png(out / sheet_name(group), sheet)
        missed[group] = {"missed": len(picked), "shown": min(len(picked), sheet_limit),
                         "sheet": sheet_name(group) if sheet is not None else None}
    metrics["missed_objects"] = missed
    distance_plot(out / "recall_by_distance.png", metrics)
    title = title or f"Realism report: {Path(detections).stem} on {gt.name}"
    (out / "realism.md").write_text(realism_markdown(metrics, title))
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2, sort_keys=True, allow_nan=False) + "\n")
    log.info("wrote realism.md, metrics.json, contact sheets and recall_by_distance.png to %s", out)
    return metrics
