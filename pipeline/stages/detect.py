"""``roadsynth detect``: run our detector (``--model DIR``) or any ONNX detector (``--onnx FILE``) over
the images of a COCO export and write a COCO results file that ``roadsynth evaluate`` scores.

Which annotations: ``--annotations FILE``, else ``--coco DIR`` with ``--split NAME``
(``annotations_NAME.json``), else ``DIR/annotations.json``. Every image of the file is processed (all
conditions). The results are validated against the annotations with the evaluation stage's own
reader before they are written (atomically: temporary sibling, then rename).

ONNX models: see :mod:`pipeline.detect.onnx` for the expected I/O. Raw heads of YOLOX, YOLOv5 and
YOLOv8 are recognised from their output shapes (or ``--family``) and decoded with the family's own
pre-processing and NMS; classes map to COCO ids by the standard 80-class table (or ``--names``,
``--class-map``), and every class is kept: ``roadsynth evaluate`` scores the ground truth's categories
and counts the rest. Options stored in the model by ``roadsynth train --export-onnx`` are the defaults,
the command-line options below override them. Detections of model classes with no COCO id are dropped
and counted in the log. A model whose graph contradicts the options (channels, input size, batch, a
family that does not read its outputs) is refused before the first image; output rows with a NaN or
infinite box or score are dropped and counted, and a run in which every row was is an error
(:mod:`pipeline.detect.onnx`).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
from pathlib import Path

from pipeline.core.outputs import OutputSpec, marked_sidecar, write_sidecar
from pipeline.stages.common import int_at_least
from pipeline.stages.train import annotations_path

INPUT_ARGS = ("model", "onnx", "coco", "annotations", "names")
DEFAULT_BATCH_SIZE = 4  # --model, and --onnx models with a dynamic batch axis (pipeline.detect.onnx's default)
HELP = "detect objects in a COCO export's images with our model or an ONNX model; write COCO results"
log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--model", type=Path, metavar="DIR", help="a `roadsynth train` output (or its model.pt)")
    src.add_argument("--onnx", type=Path, metavar="FILE", help="any ONNX detector (run with onnxruntime)")
    parser.add_argument("--coco", type=Path, metavar="DIR", help="a `roadsynth export --format coco` folder")
    parser.add_argument("--split", help="split file of --coco (annotations_SPLIT.json)")
    parser.add_argument("--annotations", type=Path, metavar="FILE", help="COCO instances file (instead of --coco)")
    parser.add_argument("--out", type=Path, required=True, metavar="FILE", help="COCO results JSON to write")
    parser.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                        help="auto: CUDA when torch (--model) or onnxruntime (--onnx) offers it")
    parser.add_argument("--score-threshold", type=float, metavar="S",
                        help="drop detections below S (default: the model's, 0.05)")
    parser.add_argument("--batch-size", type=int_at_least(1), metavar="N",
                        help=f"images per forward pass (default {DEFAULT_BATCH_SIZE}; --onnx: the model's fixed batch, "
                        "which N may not exceed, else N)")
    parser.add_argument("--threads", type=int_at_least(1), metavar="N",
                        help="(--onnx) onnxruntime threads (default: all cores)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    onnx = parser.add_argument_group("ONNX pre/post-processing (default: stored in the model, else the family's)")
    onnx.add_argument("--family", choices=("auto", "yolox", "yolov5", "yolov8", "decoded"),
                      help="head family (default auto: from the output shapes)")
    onnx.add_argument("--names", type=Path, metavar="FILE", help="model class names, one per line (or 'names' "
                      "in JSON/YAML), mapped to COCO ids by name (default: COCO's 80 classes)")
    onnx.add_argument("--placement", choices=("top-left", "centre"), help="letterbox placement (family's)")
    onnx.add_argument("--pad-value", type=float, metavar="V", help="letterbox grey, 0-255 (family's: YOLO 114)")
    onnx.add_argument("--strides", type=int, nargs="+", metavar="S", help="head strides (default: 8 16 32)")
    onnx.add_argument("--input-size", type=int, nargs=2, metavar=("W", "H"),
                      help="network input (default: static shape)")
    onnx.add_argument("--resize", choices=("letterbox", "stretch"), help="letterbox (default) or stretch")
    onnx.add_argument("--layout", choices=("nchw", "nhwc"), help="input layout (default: from the input shape)")
    onnx.add_argument("--channels", choices=("rgb", "bgr"), help="channel order (family's: YOLOX bgr, else rgb)")
    onnx.add_argument("--scale", type=float, help="pixel (0-255) multiplier before mean/std (family's: YOLOX 1, "
                      "else 1/255)")
    onnx.add_argument("--mean", type=float, nargs=3, metavar=("R", "G", "B"), help="subtracted (default: 0 0 0)")
    onnx.add_argument("--std", type=float, nargs=3, metavar=("R", "G", "B"), help="divided by (default: 1 1 1)")
    onnx.add_argument("--output-format", choices=("boxes-scores-classes", "detections"),
                      help="three outputs (boxes, scores, classes) or one (N, 6) tensor")
    onnx.add_argument("--output-names", nargs="+", metavar="NAME", help="outputs to read, in that order")
    onnx.add_argument("--box-format", choices=("xyxy", "xywh", "cxcywh"), help="box encoding (default: xyxy)")
    onnx.add_argument("--normalized", action="store_true", default=None, help="boxes are in [0, 1] of the input")
    onnx.add_argument("--class-map", metavar="JSON|FILE|coco80",
                      help='model class -> COCO category id, e.g. \'{"0": 3, "1": 8}\'; '
                      "coco80: contiguous COCO indices")
    onnx.add_argument("--nms-iou", type=float, help="class-wise NMS IoU (family's: YOLOX 0.65, YOLOv5 0.45, "
                      "YOLOv8 0.7, decoded none; 1 turns it off)")
    onnx.add_argument("--max-detections", type=int, help="per image (default: 100)")


def outputs(args: argparse.Namespace) -> list[OutputSpec]:
    return [OutputSpec(args.out, folder=False, recognise=marked_sidecar("detect"),
                       expected="a COCO results JSON file")]


def _onnx_detector(args: argparse.Namespace):
    from pipeline.detect.classmap import names_map, read_names
    from pipeline.detect.onnx import OnnxDetector, parse_class_map

    class_map = parse_class_map(args.class_map)
    if args.names is not None:
        if class_map is not None:
            raise ValueError("--names and --class-map both map classes; give one")
        class_map, missing = names_map(read_names(args.names))
        if missing:
            log.warning("%s: names without a COCO category (their detections are dropped and counted): %s",
                        args.names, ", ".join(missing))
    overrides = {
        "input_size": tuple(args.input_size) if args.input_size else None, "resize": args.resize,
        "layout": args.layout, "channels": args.channels, "scale": args.scale,
        "mean": tuple(args.mean) if args.mean else None, "std": tuple(args.std) if args.std else None,
        "output_format": args.output_format, "output_names": tuple(args.output_names) if args.output_names else None,
        "box_format": args.box_format, "normalized": args.normalized,
        "class_map": class_map, "nms_iou": args.nms_iou,
        "max_detections": args.max_detections, "score_threshold": args.score_threshold,
        "family": args.family, "placement": args.placement, "pad_value": args.pad_value,
        "strides": tuple(args.strides) if args.strides else None,
    }
    return OnnxDetector(args.onnx, batch_size=args.batch_size, device=args.device, threads=args.threads, **overrides)


def write_results(path: Path, results: list[dict], gt_path: Path) -> None:
    """Validate ``results`` with the evaluation stage's reader, then write them atomically."""
    from evaluation.io_coco import detections_from_list, read_coco_gt

    checked = detections_from_list(results, read_coco_gt(gt_path), str(path))
    if checked.not_in_gt:
        log.info("%d detections are of categories %s lacks (kept: evaluate counts them per id): %s",
                 sum(checked.not_in_gt.values()), gt_path, checked.not_in_gt)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(results, separators=(",", ":")) + "\n")
    tmp.replace(path)
    write_sidecar(path, "detect")  # a COCO results list has no room for our mark: a hidden file beside it


def main(args: argparse.Namespace) -> int:
    from pipeline.core.config.detector import DETECTOR_CLASSES
    from pipeline.detect.data import load_coco
    from pipeline.detect.infer import Detector, detect_coco, resolve_device

    ann = annotations_path(args)
    if args.model is not None:
        detector = Detector.load(args.model, resolve_device(args.device))
        data = load_coco(ann, detector.config.classes)

        def predict(rgbs):
            return detector.predict(rgbs, score_threshold=args.score_threshold)

        batch = args.batch_size or DEFAULT_BATCH_SIZE
    else:
        onnx_detector = _onnx_detector(args)
        data = load_coco(ann, DETECTOR_CLASSES)  # only the image list is used
        predict, batch = onnx_detector.predict, onnx_detector.batch
    results = detect_coco(predict, data, batch_size=batch, progress=not args.no_progress)
    if args.onnx is not None:
        onnx_detector.check_finite()  # all non-finite: fails before anything is written; some: a warning
    if args.onnx is not None and onnx_detector.unmapped:
        log.warning("%s: dropped %d detections of model classes without a COCO id (by class index: %s)", args.onnx,
                    sum(onnx_detector.unmapped.values()), dict(sorted(onnx_detector.unmapped.items())))
    write_results(args.out, results, ann)
    log.info("%d detections on %d images of %s -> %s", len(results), len(data.images), ann, args.out)
    return 0
