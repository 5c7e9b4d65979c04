"""``roadsynth evaluate``: score a detector's output against ground truth (COCO JSON or KITTI label dirs; tracks,
nuScenes detections and Cityscapes segmentations with their tools of record).

A thin adapter over :func:`evaluation.evaluate`; the output folder (metrics.json, plots/, report.md,
meta.json) is written atomically.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from pipeline.core.digests import path_sha256
from pipeline.stages.common import Flatten, atomic_output_dir, float_list, write_json, write_meta

INPUT_ARGS = ("gt", "detections", "calib", "images")
HELP = ("score detections against ground truth: precision/recall by IoU, COCO AP, KITTI AP, error breakdown; "
        "the realism gauge")
log = logging.getLogger(__name__)
TASKS = ("detection", "tracking", "nuscenes-detection", "segmentation", "realism")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from evaluation.api import METRICS
    from evaluation.table import DEFAULT_IOU_THRESHOLDS, DEFAULT_SCORE_THRESHOLD

    parser.add_argument("--task", choices=TASKS, default="detection",
                        help="what is scored: detections (default) or tracks (--task tracking: MOTChallenge files, "
                        "HOTA, MOTA, IDF1 by TrackEval), or 3D detections by the nuScenes devkit (--task "
                        "nuscenes-detection: --gt a nuScenes export, --detections a submission JSON; mAP, NDS), or "
                        "semantic segmentation by cityscapesscripts (--task segmentation: --gt a Cityscapes export or "
                        "gtFine folder, --detections a folder of label id PNGs; IoU, iIoU), or the realism gauge "
                        "(--task realism: a COCO export and results; AP50, recall, precision and recall per object "
                        "by class group, --group-by (default condition) and box height, recall by distance beside "
                        "the fog's transmittance, mean luma, contact sheets of missed objects)")
    parser.add_argument("--gt", type=Path, required=True, help="COCO instances JSON, or a KITTI label_2 directory "
                        "(tracking: a MOT gt.txt, a sequence folder or a folder of sequences; segmentation: a "
                        "Cityscapes export, its gtFine folder or a split of it)")
    parser.add_argument("--detections", type=Path, required=True,
                        help="COCO results JSON, or a KITTI label directory with a 16th column (score) (tracking: "
                        "MOT tracker results, a <sequence>.txt per sequence or one file; segmentation: a folder of "
                        "<city>_<sequence>_<frame>*.png of Cityscapes label ids)")
    parser.add_argument("--out", type=Path, required=True, help="output directory (replaced atomically)")
    parser.add_argument("--iou", type=float_list, nargs="+", action=Flatten, default=list(DEFAULT_IOU_THRESHOLDS),
                        metavar="T", help="IoU thresholds of the precision/recall table, separated by spaces or "
                        "commas (default: %(default)s)")
    parser.add_argument("--group-by", metavar="KEY", help="image attribute giving one table row per value, "
                        "e.g. condition")
    parser.add_argument("--metrics", default=",".join(METRICS),
                        help=f"comma-separated subset of {','.join(METRICS)} (default: all)")
    parser.add_argument("--score-threshold", type=float, default=DEFAULT_SCORE_THRESHOLD, metavar="S",
                        help="detections scoring below S are not counted in the table and errors "
                        "(default: %(default)s; the F1-optimal threshold is reported too)")
    parser.add_argument("--kitti-mode", choices=("official", "port", "exact"), default="official",
                        help="KITTI AP semantics: the C++ devkit's (official), the common Python port's "
                        "(port: float32 rotated IoU), or with the devkit's known defects fixed (exact)")
    parser.add_argument("--calib", type=Path, metavar="DIR", help="KITTI calib directory (optional)")
    parser.add_argument("--png", action="store_true", help="also render the plot data as PNG (imports matplotlib)")
    parser.add_argument("--images", type=Path, metavar="DIR",
                        help="--task realism: the folder of the ground truth's images (default: GT folder/images)")
    parser.add_argument("--group-order", nargs="+", metavar="VALUE",
                        help="--task realism: the --group-by values' order in the report, e.g. morning noon dusk night "
                        "(default: as the images come)")
    parser.add_argument("--eval-set", default="all", metavar="SPLIT",
                        help="--task nuscenes-detection: the split of the export's splits.json scored (default: "
                        "%(default)s, every scene)")


def refuse_detection_options(args: argparse.Namespace, allowed: tuple[str, ...] = ()) -> None:
    """Fail when an option of --task detection is given to another task (but ``allowed``): it would be ignored
    without a word."""
    from evaluation.api import METRICS
    from evaluation.table import DEFAULT_IOU_THRESHOLDS, DEFAULT_SCORE_THRESHOLD

    detection_only = {"--iou": args.iou != list(DEFAULT_IOU_THRESHOLDS), "--group-by": args.group_by is not None,
                      "--score-threshold": args.score_threshold != DEFAULT_SCORE_THRESHOLD,
                      "--kitti-mode": args.kitti_mode != "official", "--calib": args.calib is not None,
                      "--png": args.png, "--metrics": args.metrics != ",".join(METRICS)}
    given = [flag for flag, changed in detection_only.items() if changed and flag not in allowed]
    if given:
        raise ValueError(f"{', '.join(given)} apply to --task detection only, not {args.task}")


def write_task_output(args: argparse.Namespace, task: str, metrics: dict, report: str | None, **config) -> None:
    """The output folder of a task scored by its community's tool, written atomically: metrics.json, report.md
    (when given) and meta.json, whose config names the task, the inputs and ``config``."""
    config = {"task": task, "gt": str(args.gt), "detections": str(args.detections), **config}
    with atomic_output_dir(args.out) as tmp:
        write_json(tmp / "metrics.json", metrics)
        if report is not None:
            (tmp / "report.md").write_text(report)
        write_meta(tmp, stage="evaluate", config=config, seed=None)


def main_tracking(args: argparse.Namespace) -> int:
    """--task tracking: TrackEval's HOTA, CLEAR and identity metrics (evaluation.tracking) into metrics.json."""
    from evaluation.tracking import evaluate_tracking, markdown_summary

    refuse_detection_options(args)
    metrics = evaluate_tracking(args.gt, args.detections)
    write_task_output(args, "tracking", metrics, markdown_summary(metrics), gt_sha256=path_sha256(args.gt),
                      detections_sha256=path_sha256(args.detections))
    c = metrics["combined"]
    log.info("HOTA %.4f MOTA %.4f IDF1 %.4f (%d sequence(s))", c["HOTA"], c["MOTA"], c["IDF1"],
             len(metrics["sequences"]))
    return 0


def main_nuscenes(args: argparse.Namespace) -> int:
    """--task nuscenes-detection: the nuScenes devkit's DetectionEval (evaluation.nuscenes_detection) on a nuScenes
    export (--gt: its dataroot) and a submission JSON (--detections) into metrics.json."""
    from evaluation.nuscenes_detection import evaluate_nuscenes_detection, find_version

    refuse_detection_options(args)
    metrics = evaluate_nuscenes_detection(args.gt, args.detections, eval_set=args.eval_set)
    write_task_output(args, "nuscenes-detection", metrics, None, eval_set=args.eval_set,
                      gt_sha256=path_sha256(args.gt / find_version(args.gt)),
                      detections_sha256=path_sha256(args.detections))
    log.info("mAP %.4f NDS %.4f (%s)", metrics["mean_ap"], metrics["nd_score"],
             ", ".join(f"{k} {v if v is None else round(v, 4)}" for k, v in metrics["tp_errors"].items()))
    return 0


def main_segmentation(args: argparse.Namespace) -> int:
    """--task segmentation: cityscapesscripts' pixel-level evaluation (evaluation.segmentation) of predicted label id
    PNGs (--detections) against a Cityscapes export (--gt) into metrics.json and report.md."""
    from evaluation.segmentation import evaluate_segmentation, markdown_summary

    refuse_detection_options(args)
    metrics = evaluate_segmentation(args.gt, args.detections)
    write_task_output(args, "segmentation", metrics, markdown_summary(metrics), gt_sha256=path_sha256(args.gt),
                      detections_sha256=path_sha256(args.detections))
    log.info("mIoU %s iIoU %s (%d image(s))", metrics["mIoU"], metrics["iIoU"], metrics["images"])
    return 0


def condition_visibility(values: list[str]) -> dict[str, float]:
    """Meteorological visibility (metres) of each of ``values`` that names a condition config with fog or rain (their
    extinctions together, as :attr:`pipeline.sensors.conditions.Condition.visibility_m` has it): the configs the
    records were rendered from (configs/conditions/)."""
    from pipeline.core.config import ConditionConfig
    from pipeline.core.config.loading import available_names, load_config
    from pipeline.sensors.weather import KOSCHMIEDER, fog_extinction_per_m, rain_extinction_per_m

    known = set(available_names("conditions"))
    out = {}
    for value in values:
        if value in known:
            config = load_config(ConditionConfig, value, "conditions")[0]
            beta = 0.0 if config.fog is None else fog_extinction_per_m(config.fog.visibility_m)
            beta += 0.0 if config.rain is None else rain_extinction_per_m(config.rain.rate_mm_h)
            if beta > 0:
                out[value] = KOSCHMIEDER / beta
    return out


def main_realism(args: argparse.Namespace) -> int:
    """--task realism: the realism gauge (evaluation.realism_report) into realism.md, metrics.json, contact sheets
    of missed objects and the plot of recall by distance."""
    import json

    from evaluation.realism_report import evaluate_realism

    refuse_detection_options(args, allowed=("--score-threshold", "--group-by"))
    group_by = args.group_by or "condition"
    values = sorted({str(img.get(group_by)) for img in json.loads(args.gt.read_text()).get("images", [])}) \
        if group_by == "condition" and args.gt.is_file() else []
    visibility = condition_visibility(values)
    with atomic_output_dir(args.out) as tmp:
        metrics = evaluate_realism(args.gt, args.detections, tmp, images=args.images,
                                   score_threshold=args.score_threshold, group_by=group_by, visibility_m=visibility,
                                   group_order=args.group_order)
        write_meta(tmp, stage="evaluate", config={
            "task": "realism", "gt": str(args.gt), "detections": str(args.detections),
            "gt_sha256": path_sha256(args.gt), "detections_sha256": path_sha256(args.detections),
            "images": None if args.images is None else str(args.images), "group_by": group_by,
            "score_threshold": args.score_threshold, "visibility_m": visibility, "group_order": args.group_order},
            seed=None)
    for row in metrics["rows"]:
        if row["group"] == "all" and row["height_px"] == "30+":
            log.info("%s >= 30 px: AP50 %s recall %s precision %s (%d boxes, %d objects)", row["class_group"],
                     row["ap50"], row["recall"], row["precision"], row["gt"], row["objects"])
    return 0


def main(args: argparse.Namespace) -> int:
    for flag in ("images", "group_order"):
        if getattr(args, flag, None) is not None and getattr(args, "task", "detection") != "realism":
            raise ValueError(f"--{flag.replace('_', '-')} applies to --task realism only, not {args.task}")
    if getattr(args, "task", "detection") == "realism":
        return main_realism(args)
    if getattr(args, "eval_set", "all") != "all" and getattr(args, "task", "detection") != "nuscenes-detection":
        raise ValueError(f"--eval-set applies to --task nuscenes-detection only, not {args.task}")
    if getattr(args, "task", "detection") == "tracking":
        return main_tracking(args)
    if getattr(args, "task", "detection") == "nuscenes-detection":
        return main_nuscenes(args)
    if getattr(args, "task", "detection") == "segmentation":
        return main_segmentation(args)
    from evaluation import evaluate, parse_metrics

    metrics = parse_metrics(args.metrics)
    kitti_options = {"mode": args.kitti_mode}
    if args.calib is not None:
        kitti_options["calib_dir"] = args.calib
    result = evaluate(args.gt, args.detections, iou_thresholds=args.iou, group_by=args.group_by, metrics=metrics,
                      score_threshold=args.score_threshold, kitti_options=kitti_options)
    # the digests let `roadsynth report` check that it is given the inputs that were evaluated
    config = {"gt": str(args.gt), "detections": str(args.detections),
              "gt_sha256": path_sha256(args.gt), "detections_sha256": path_sha256(args.detections),
              "iou": list(args.iou),
              "group_by": args.group_by, "metrics": list(metrics), "score_threshold": args.score_threshold,
              "kitti_mode": args.kitti_mode, "calib": None if args.calib is None else str(args.calib)}
    with atomic_output_dir(args.out) as tmp:
        result.write(tmp, png=args.png)
        write_meta(tmp, stage="evaluate", config=config, seed=None)
    table = result.metrics["table"]
    for row in table.get("rows", []):
        if row["group"] == "all" and row["class"] == "all":
            log.info("IoU %.2f: precision %s recall %s", row["iou"], row["precision"], row["recall"])
    if "stats" in result.metrics["coco"]:
        log.info("COCO AP %.4f AP50 %.4f", *result.metrics["coco"]["stats"][:2])
        if result.metrics["coco"]["stats"][0] == -1:
            log.warning("%s: no ground-truth objects to score (in the evaluated categories): COCO AP is undefined, "
                        "written as -1 in metrics.json, and recall as null", args.gt)
    return 0
