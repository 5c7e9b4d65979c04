"""``roadsynth report``: the experiment's summary — the paper's table per condition, COCO AP per
condition, recall by distance and box height, and a strip of example frames with ground truth and
detections drawn.

Renders from the evaluate stage's ``metrics.json`` (its table rows and its COCO stats per group) with the
Markdown table helpers of :mod:`evaluation.markdown`; reads the COCO ground truth and the detections (COCO
results) only to draw the example frames. Writes OUT/report.md, OUT/examples.png and OUT/metrics.json
(flat, per condition, for ``dvc metrics``). The ground truth and detections must be the files that were
evaluated (their sha256 is in the evaluation's ``meta.json``) and the grouping the evaluation's
``--group-by``: the tables come from it.

Several detectors (``--eval NAME=DIR --detections NAME=FILE``, once per detector, e.g. the baseline and
a pretrained ONNX model) share one report: Table 1 puts their precision and recall side by side per
condition, with ``--paper`` the figures of Li, Kusari & LeBlanc's Table 1 (:data:`PAPER_TABLE1`) beside
them; metrics.json then nests the flat metrics by detector name; examples.png draws the first detector.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

import cv2
import numpy as np

from evaluation.inputs import MISSING_GROUP
from evaluation.markdown import md_table, percent, pr_table
from pipeline.stages.common import atomic_output_dir, int_at_least, write_json, write_meta
from pipeline.stages.evaluated_inputs import check_evaluated_inputs

log = logging.getLogger(__name__)

INPUT_ARGS = ("eval", "gt", "detections", "images")
HELP = "summarise an evaluation per condition: the paper's table, COCO AP, example frames"
GT_BGR, DET_BGR = (60, 220, 60), (40, 40, 255)
# Li, Kusari & LeBlanc, Table 1 (a detector trained on real photos, run on CARLA frames of SUMO traffic):
# precision and recall at IoU 0.5, 0.6, 0.7, 0.8 per condition.
PAPER_TABLE1 = {
    "morning": {"precision": (0.82, 0.81, 0.79, 0.47), "recall": (0.41, 0.40, 0.40, 0.28)},
    "night": {"precision": (0.81, 0.79, 0.70, 0.37), "recall": (0.23, 0.23, 0.21, 0.12)},
}
PAPER_IOUS = (0.5, 0.6, 0.7, 0.8)
PAPER_SOURCE = "paper (Li et al., Table 1)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--eval", action="append", required=True, metavar="[NAME=]DIR",
                        help="output folder of `roadsynth evaluate`; once per detector, as NAME=DIR, to compare")
    parser.add_argument("--gt", type=Path, required=True, help="COCO ground truth that was evaluated")
    parser.add_argument("--detections", action="append", required=True, metavar="[NAME=]FILE",
                        help="COCO results that were evaluated (the same NAMEs as --eval)")
    parser.add_argument("--paper", action="store_true",
                        help="put the paper's Table 1 figures beside ours (morning and night, IoU 0.5-0.8)")
    parser.add_argument("--images", type=Path, help="folder of the GT's images (default: GT folder/images)")
    parser.add_argument("--group-by", help="image attribute to report by; must be the evaluation's --group-by "
                        "(default: that one)")
    parser.add_argument("--examples", type=int_at_least(1), default=2, help="example frames per group (default 2)")
    parser.add_argument("--out", type=Path, required=True, help="report folder")


def _table(metrics: dict) -> tuple[list[float], dict[str, dict[float, dict]]]:
    """IoU thresholds and the table rows (all classes) by image group: "all" and each value of the group-by
    attribute (the ground-truth bins, ``distance_m:0-30``..., are left out)."""
    rows = [r for r in metrics["table"]["rows"] if r["class"] == "all"]
    ious = sorted({r["iou"] for r in rows})
    by_group: dict[str, dict[float, dict]] = {}
    for r in rows:
        if ":" not in str(r["group"]):
            by_group.setdefault(str(r["group"]), {})[r["iou"]] = r
    return ious, by_group


def _group(image: dict, group_by: str) -> str:
    """The image's group label, as the evaluation's table writes it."""
    value = image.get(group_by)
    return MISSING_GROUP if value is None else str(value)


def _coco_by_group(metrics: dict) -> dict[str, list[float]]:
    """COCO stats (12 numbers, pycocotools order) of all images, then of each group (the evaluation's)."""
    return {"all": metrics["coco"]["stats"], **metrics["coco"]["stats_by_group"]}


def _markdown(metrics: dict, ious: list[float], group_by: str, score_threshold: float) -> str:
    """report.md of one detector: its table per group, recall by bin and COCO AP per group (its metrics.json)."""
    rows = [r for r in metrics["table"]["rows"] if r["class"] == "all"]
    groups = [r for r in rows if ":" not in str(r["group"])]
    bins = [r for r in rows if ":" in str(r["group"])]
    lines = [
        "# Detection report", "",
        f"## Precision and recall (%) by IoU threshold, per {group_by} (score >= {score_threshold:g})", "",
        *pr_table(groups, "group", ious, label=group_by, undefined="-"),
    ]
    if bins:
        lines += ["", "## Recall (%) by ground-truth distance, box height (px) and occlusion", "",
                  *pr_table(bins, "group", ious, recall_only=True, label="bin", undefined="-")]
    coco = [[group, *(percent(stats[k], "n/a") for k in (0, 1, 2, 8))]
            for group, stats in _coco_by_group(metrics).items()]
    lines += ["", f"## COCO AP per {group_by}", "", *md_table([group_by, "AP", "AP50", "AP75", "AR100"], coco),
              "", "Example frames (green: ground truth, red: detections above the score threshold): examples.png", ""]
    return "\n".join(lines)


def examples_strip(gt_path: Path, det_path: Path, images: Path, group_by: str, per_group: int,
                   score_threshold: float) -> np.ndarray:
    """(H, W, 3) BGR: one row per group value, ``per_group`` frames each, boxes drawn."""
    gt = json.loads(gt_path.read_text())
    dets = json.loads(det_path.read_text())
    rows = []
    for value in sorted({_group(img, group_by) for img in gt["images"]}):
        imgs = sorted((i for i in gt["images"] if _group(i, group_by) == value), key=lambda i: i["id"])
        picks = [imgs[k] for k in np.unique(np.linspace(0, len(imgs) - 1, per_group).round().astype(int))]
        tiles = []
        for img in picks:
            path = images / img["file_name"]
            tile = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if tile is None:
                raise FileNotFoundError(f"{path}: image of {gt_path} (images[].file_name) not found")
            for a in gt["annotations"]:
                if a["image_id"] == img["id"] and not a.get("iscrowd", 0):
                    x, y, w, h = (round(v) for v in a["bbox"])
                    cv2.rectangle(tile, (x, y), (x + w - 1, y + h - 1), GT_BGR, 2)
            for d in dets:
                if d["image_id"] == img["id"] and d["score"] >= score_threshold:
                    x, y, w, h = (round(v) for v in d["bbox"])
                    cv2.rectangle(tile, (x, y), (x + w - 1, y + h - 1), DET_BGR, 1)
            cv2.putText(tile, f"{group_by}: {value}", (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2)
            tiles.append(cv2.resize(tile, (400, round(400 * tile.shape[0] / tile.shape[1]))))
        rows.append(np.concatenate(tiles, axis=1))
    width = max(r.shape[1] for r in rows)
    return np.concatenate([np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows], axis=0)


def named_paths(values: list[str], option: str) -> dict[str, Path]:
    """``[NAME=]PATH`` values of a repeated option by name; one unnamed value is named ``detector``."""
    out: dict[str, Path] = {}
    for value in values:
        name, sep, path = value.partition("=")
        if not sep:
            if len(values) > 1:
                raise ValueError(f"{option} {value!r}: several detectors are given, so each needs NAME=PATH")
            name, path = "detector", value
        if not name or name in out:
            raise ValueError(f"{option} {value!r}: {'empty' if not name else 'repeated'} detector name")
        out[name] = Path(path)
    return out


def paper_markdown(ious: list[float], per_detector: dict[str, dict[str, dict[float, dict]]], group_by: str,
                   paper: bool) -> str:
    """Table 1 laid out as in the paper (precision block, recall block), one row per (condition, source)."""
    header = [group_by, "source", *(f"P@{t:g}" for t in ious), *(f"R@{t:g}" for t in ious)]

    def cell(value) -> str:
        return "-" if value is None else f"{value:.2f}"

    rows = []
    for group in dict.fromkeys(g for table in per_detector.values() for g in table):
        if paper and group in PAPER_TABLE1:
            ref = PAPER_TABLE1[group]
            at = {t: i for i, t in enumerate(PAPER_IOUS)}
            rows.append([group, PAPER_SOURCE,
                         *(cell(ref[k][at[t]]) if t in at else "-" for k in ("precision", "recall") for t in ious)])
        for name, table in per_detector.items():
            if group in table:
                rows.append([group, name, *(cell(table[group][t][k]) for k in ("precision", "recall") for t in ious)])
    lines = [f"## Table 1: precision and recall by IoU threshold, per {group_by}", "", *md_table(header, rows)]
    return "\n".join(lines) + "\n"


def _detector_report(metrics: dict) -> tuple[list[float], dict[str, dict[float, dict]], dict]:
    """IoU thresholds, the table rows by group (Table 1) and the flat metrics.json entries of one detector."""
    ious, table = _table(metrics)
    coco = _coco_by_group(metrics)
    flat = {group: {**{f"precision@{t:g}": by_iou[t]["precision"] for t in ious},
                    **{f"recall@{t:g}": by_iou[t]["recall"] for t in ious},
                    "coco_ap": coco.get(group, [None])[0], "coco_ap50": coco.get(group, [None, None])[1]}
            for group, by_iou in table.items()}
    return ious, table, flat


def main(args: argparse.Namespace) -> int:
    evals = named_paths(args.eval, "--eval")
    dets = named_paths(args.detections, "--detections")
    if set(evals) != set(dets):
        raise ValueError(f"--eval names {sorted(evals)} and --detections names {sorted(dets)} differ")
    reports, score_threshold, group_by = {}, None, None
    for name, eval_dir in evals.items():
        metrics_path = eval_dir / "metrics.json"
        if not metrics_path.is_file():
            raise FileNotFoundError(f"{metrics_path}: not found (run `roadsynth evaluate --out {eval_dir}` first)")
        grouped = check_evaluated_inputs(eval_dir, args.gt, dets[name], args.group_by)
        if group_by is not None and grouped != group_by:
            raise ValueError(f"{eval_dir / 'meta.json'}: grouped by {grouped!r}, the other evaluations by "
                             f"{group_by!r}; evaluate every detector with the same --group-by")
        group_by = grouped
        metrics = json.loads(metrics_path.read_text())
        for section, key in (("table", "rows"), ("coco", "stats")):
            if key not in metrics.get(section, {}):
                raise ValueError(f"{metrics_path}: {section}.{key} is missing ({section}: {metrics.get(section)!r}); "
                                 f"run `roadsynth evaluate` with --metrics including {section}")
        if not isinstance(metrics["coco"].get("stats_by_group"), dict):
            raise ValueError(f"{metrics_path}: coco.stats_by_group is missing (an evaluation older than its COCO stats "
                             f"per group); re-run `roadsynth evaluate --group-by {group_by}`")
        score_threshold = float(metrics["table"]["score_threshold"]) if score_threshold is None else score_threshold
        reports[name] = (metrics, *_detector_report(metrics))
    images = args.images or args.gt.parent / "images"
    single = len(reports) == 1 and not args.paper
    with atomic_output_dir(args.out) as tmp:
        if single:
            metrics, ious, _, flat_metrics = next(iter(reports.values()))
            text = _markdown(metrics, ious, group_by, score_threshold)
        else:
            ious = next(iter(reports.values()))[1]
            text = "# Detection report\n\n" + paper_markdown(ious, {n: r[2] for n, r in reports.items()},
                                                               group_by, args.paper)
            text += (f"\nScore >= {score_threshold:g}. Paper figures as published (CARLA frames, the paper's "
                     "detector), for comparison, not recomputed.\n")
            for name, (metrics, d_ious, _, _) in reports.items():
                body = _markdown(metrics, d_ious, group_by, score_threshold)
                body = body.replace("\n## ", "\n### ").replace("# Detection report", f"## Detector: {name}", 1)
                text += "\n" + body
            flat_metrics = {name: r[3] for name, r in reports.items()}
        (tmp / "report.md").write_text(text)
        first = next(iter(dets.values()))
        strip = examples_strip(args.gt, first, images, group_by, args.examples, score_threshold)
        cv2.imwrite(str(tmp / "examples.png"), strip)
        write_json(tmp / "metrics.json", flat_metrics)
        shown = str(evals["detector"]) if single and "detector" in evals else {n: str(p) for n, p in evals.items()}
        write_meta(tmp, stage="report", config={"eval": shown,
                                                "group_by": group_by, "paper": args.paper}, seed=None)
    log.info("wrote %s", args.out)
    return 0
