"""``roadsynth report``: the experiment's summary — the paper's table per condition, COCO AP per
condition, and a strip of example frames with ground truth and detections drawn.

Reads the evaluate stage's ``metrics.json``, the COCO ground truth and the detections (COCO results);
writes OUT/report.md, OUT/examples.png and OUT/metrics.json (flat, per condition, for ``dvc metrics``).
"""

from __future__ import annotations

import argparse
import json
import logging
import tempfile
from pathlib import Path

import cv2
import numpy as np

from evaluation import evaluate
from pipeline.stages.common import atomic_output_dir, int_at_least, write_json, write_meta

log = logging.getLogger(__name__)

INPUT_ARGS = ("eval", "gt", "detections", "images")
HELP = "summarise an evaluation per condition: the paper's table, COCO AP, example frames"
GT_BGR, DET_BGR = (60, 220, 60), (40, 40, 255)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--eval", type=Path, required=True, help="output folder of `roadsynth evaluate`")
    parser.add_argument("--gt", type=Path, required=True, help="COCO ground truth that was evaluated")
    parser.add_argument("--detections", type=Path, required=True, help="COCO results that were evaluated")
    parser.add_argument("--images", type=Path, help="folder of the GT's images (default: GT folder/images)")
    parser.add_argument("--group-by", default="condition", help="image attribute to report by (default condition)")
    parser.add_argument("--examples", type=int_at_least(1), default=2, help="example frames per group (default 2)")
    parser.add_argument("--out", type=Path, required=True, help="report folder")


def _table(metrics: dict) -> tuple[list[float], dict[str, dict[float, dict]], dict[str, dict[float, dict]]]:
    """IoU thresholds, rows by image group ("all" and each value of the group-by attribute), and rows by
    ground-truth bin (``distance_m:0-30``, ``occlusion:partial``...: recall only)."""
    rows = [r for r in metrics["table"]["rows"] if r["class"] == "all"]
    ious = sorted({r["iou"] for r in rows})
    by_group: dict[str, dict[float, dict]] = {}
    by_bin: dict[str, dict[float, dict]] = {}
    for r in rows:
        target = by_bin if ":" in str(r["group"]) else by_group
        target.setdefault(str(r["group"]), {})[r["iou"]] = r
    return ious, by_group, by_bin


def coco_by_group(gt_path: Path, det_path: Path, group_by: str) -> dict[str, list[float]]:
    """COCO stats (12 numbers, pycocotools order) for each value of the image attribute ``group_by``."""
    gt = json.loads(gt_path.read_text())
    dets = json.loads(det_path.read_text())
    values = sorted({str(img.get(group_by)) for img in gt["images"]})
    out = {}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for value in values:
            ids = {img["id"] for img in gt["images"] if str(img.get(group_by)) == value}
            sub = dict(gt, images=[i for i in gt["images"] if i["id"] in ids],
                       annotations=[a for a in gt["annotations"] if a["image_id"] in ids])
            (tmp / "gt.json").write_text(json.dumps(sub))
            (tmp / "dt.json").write_text(json.dumps([d for d in dets if d["image_id"] in ids]))
            result = evaluate(tmp / "gt.json", tmp / "dt.json", metrics="coco")
            out[value] = [float(s) for s in result.metrics["coco"]["stats"]]
    return out


def _markdown(ious, table, bins, coco, group_by: str, score_threshold: float) -> str:
    head = " | ".join(f"P@{t:g} | R@{t:g}" for t in ious)
    lines = [
        "# Detection report", "",
        f"## Precision and recall (%) by IoU threshold, per {group_by} (score >= {score_threshold:g})", "",
        f"| {group_by} | {head} |", "|---" * (1 + 2 * len(ious)) + "|",
    ]
    for group, by_iou in table.items():
        cells = " | ".join(f"{100 * by_iou[t]['precision']:.1f} | {100 * by_iou[t]['recall']:.1f}"
                           if by_iou[t]["precision"] is not None else f"- | {100 * by_iou[t]['recall']:.1f}"
                           for t in ious)
        lines.append(f"| {group} | {cells} |")
    if bins:
        lines += ["", "## Recall (%) by ground-truth distance and occlusion", "",
                  "| bin | " + " | ".join(f"R@{t:g}" for t in ious) + " |", "|---" * (1 + len(ious)) + "|"]
        lines += [f"| {name} | " + " | ".join(f"{100 * by_iou[t]['recall']:.1f}" for t in ious) + " |"
                  for name, by_iou in bins.items()]
    lines += ["", f"## COCO AP per {group_by}", "", f"| {group_by} | AP | AP50 | AP75 | AR100 |",
              "|---|---|---|---|---|"]
    for group, stats in coco.items():
        fmt = [f"{100 * s:.1f}" if s >= 0 else "n/a" for s in (stats[0], stats[1], stats[2], stats[8])]
        lines.append(f"| {group} | " + " | ".join(fmt) + " |")
    lines += ["", "Example frames (green: ground truth, red: detections above the score threshold): "
              "examples.png", ""]
    return "\n".join(lines)


def examples_strip(gt_path: Path, det_path: Path, images: Path, group_by: str, per_group: int,
                   score_threshold: float) -> np.ndarray:
    """(H, W, 3) BGR: one row per group value, ``per_group`` frames each, boxes drawn."""
    gt = json.loads(gt_path.read_text())
    dets = json.loads(det_path.read_text())
    rows = []
    for value in sorted({str(img.get(group_by)) for img in gt["images"]}):
        imgs = sorted((i for i in gt["images"] if str(i.get(group_by)) == value), key=lambda i: i["id"])
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


def main(args: argparse.Namespace) -> int:
    metrics_path = args.eval / "metrics.json"
    if not metrics_path.is_file():
        raise FileNotFoundError(f"{metrics_path}: not found (run `roadsynth evaluate --out {args.eval}` first)")
    metrics = json.loads(metrics_path.read_text())
    score_threshold = float(metrics["table"]["score_threshold"])
    ious, table, bins = _table(metrics)
    coco = {"all": [float(s) for s in metrics["coco"]["stats"]], **coco_by_group(args.gt, args.detections,
                                                                                    args.group_by)}
    images = args.images or args.gt.parent / "images"
    with atomic_output_dir(args.out) as tmp:
        (tmp / "report.md").write_text(_markdown(ious, table, bins, coco, args.group_by, score_threshold))
        strip = examples_strip(args.gt, args.detections, images, args.group_by, args.examples, score_threshold)
        cv2.imwrite(str(tmp / "examples.png"), strip)
        flat = {group: {**{f"precision@{t:g}": by_iou[t]["precision"] for t in ious},
                        **{f"recall@{t:g}": by_iou[t]["recall"] for t in ious},
                        "coco_ap": coco.get(group, [None])[0], "coco_ap50": coco.get(group, [None, None])[1]}
                for group, by_iou in table.items()}
        write_json(tmp / "metrics.json", flat)
        write_meta(tmp, stage="report", config={"eval": str(args.eval), "group_by": args.group_by}, seed=None)
    log.info("wrote %s", args.out)
    return 0
