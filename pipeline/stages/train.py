"""``roadsynth train``: train the baseline detector on a COCO export.

Which annotations: ``--annotations FILE``, else the ``--split`` (default ``train``) file of ``--coco
DIR`` -- ``annotations_train.json`` for an export with splits, ``annotations.json`` for one without
(see :func:`pipeline.detect.data.annotation_file`). Images are filtered by their ``condition``
attribute (``train.conditions`` of the config, default morning and noon; ``--conditions all`` keeps
every image).

Writes ``DIR/model.pt`` (weights, resolved config, class map, sha256 of the annotation file),
``DIR/loss.csv`` (step, loss, heatmap, size, offset, lr: for ``dvc plots``), ``DIR/train.json``
(time, steps/s, device, parameter count, final loss: for ``dvc metrics``), ``DIR/meta.json`` and with
``--export-onnx`` ``DIR/model.onnx``; atomically. Same config, data and seed give the same
``model.pt`` on the CPU (see :mod:`pipeline.detect.train`).
"""

from __future__ import annotations

import argparse
import csv
import logging
from pathlib import Path

from pipeline.core.config import DetectorConfig, load_config
from pipeline.core.config.loading import parse_config
from pipeline.stages.common import atomic_output_dir, int_at_least, write_json, write_meta

INPUT_ARGS = ("coco", "annotations", "config")
HELP = "train the baseline detector (CenterNet-style, torch) on a COCO export"
log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--coco", type=Path, metavar="DIR", help="a `roadsynth export --format coco` folder")
    parser.add_argument("--annotations", type=Path, metavar="FILE", help="COCO instances file (instead of --coco)")
    parser.add_argument("--split", default="train", help="split file of --coco to train on (default: %(default)s)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder (replaced atomically)")
    parser.add_argument("--config", default="default", metavar="NAME|PATH",
                        help="detector config NAME (configs/detector/) or YAML PATH (default: %(default)s)")
    parser.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                        help="training device (default: %(default)s; auto: CUDA when available)")
    parser.add_argument("--steps", type=int_at_least(1), metavar="N", help="override train.steps")
    parser.add_argument("--seed", type=int_at_least(0), default=0, help="run seed (default: %(default)s)")
    parser.add_argument("--conditions", metavar="A,B",
                        help="override train.conditions: comma-separated conditions, or 'all'")
    parser.add_argument("--export-onnx", action="store_true", help="also write model.onnx (network + decoding)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def resolve_config(name_or_path: str, *, steps: int | None = None, conditions: str | None = None
                   ) -> tuple[DetectorConfig, Path]:
    """Load the detector config and apply command-line overrides (validated like the file)."""
    config, path = load_config(DetectorConfig, name_or_path, "detector")
    data = config.model_dump(mode="json")
    if steps is not None:
        data["train"]["steps"] = steps
        data["train"]["warmup_steps"] = min(data["train"]["warmup_steps"], max(0, steps - 1))
    if conditions is not None:
        data["train"]["conditions"] = None if conditions == "all" else [c for c in conditions.split(",") if c]
    return parse_config(DetectorConfig, data, f"{path} (with command-line overrides)"), path


def annotations_path(args: argparse.Namespace) -> Path:
    from pipeline.detect.data import annotation_file

    if args.annotations is not None:
        if not args.annotations.is_file():
            raise FileNotFoundError(f"{args.annotations}: annotation file not found")
        return args.annotations
    if args.coco is None:
        raise ValueError("pass --coco DIR or --annotations FILE")
    return annotation_file(args.coco, args.split)


def write_loss_csv(path: Path, history: list[dict[str, float]]) -> None:
    from pipeline.detect.train import LOSS_COLUMNS

    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(LOSS_COLUMNS)
        for row in history:
            writer.writerow([row["step"], *(f"{row[k]:.6g}" for k in LOSS_COLUMNS[1:])])


def main(args: argparse.Namespace) -> int:
    from pipeline.detect.data import file_sha256, load_coco
    from pipeline.detect.infer import Detector, resolve_device
    from pipeline.detect.model import parameter_count
    from pipeline.detect.onnx import export_onnx
    from pipeline.detect.train import save_checkpoint, train

    config, config_path = resolve_config(args.config, steps=args.steps, conditions=args.conditions)
    ann = annotations_path(args)
    device = resolve_device(args.device)
    data = load_coco(ann, config.classes, config.train.conditions)
    n_boxes = sum(len(im.boxes) for im in data.images)
    log.info("training on %s: %d images, %d boxes (conditions %s), config %s, device %s", ann, len(data.images),
             n_boxes, config.train.conditions or "all", config_path, device)
    sha = file_sha256(ann)
    result = train(config, data, seed=args.seed, device=device, progress=not args.no_progress)
    with atomic_output_dir(args.out) as tmp:
        ckpt = save_checkpoint(tmp / "model.pt", result, config, data, seed=args.seed, annotations_sha256=sha)
        write_loss_csv(tmp / "loss.csv", result.history)
        summary = {
            "seconds": round(result.seconds, 2), "steps": len(result.history),
            "steps_per_s": round(len(result.history) / max(result.seconds, 1e-9), 3), "device": str(device),
            "parameters": parameter_count(result.model), "images": result.images, "boxes": n_boxes,
            "final_loss": round(sum(r["loss"] for r in result.history[-20:]) / len(result.history[-20:]), 5),
        }
        write_json(tmp / "train.json", summary)
        if args.export_onnx:
            detector = Detector(result.model, config, ckpt["category_ids"], device)
            export_onnx(detector, tmp / "model.onnx")
        meta_config = {"detector": config.model_dump(mode="json"), "annotations": ann.name,
                       "annotations_sha256": sha, "category_ids": ckpt["category_ids"]}
        write_meta(tmp, stage="train", config=meta_config, seed=args.seed)
    log.info("trained in %.1f s; final loss %.4f -> %s", result.seconds, summary["final_loss"], args.out)
    return 0
