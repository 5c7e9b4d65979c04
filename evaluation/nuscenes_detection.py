"""nuScenes detection scores (mAP, NDS, mATE, mASE, mAOE, mAVE, mAAE) by the nuScenes devkit's ``DetectionEval``.

The devkit is the tool of record, so this module only checks the inputs (errors naming the file, the entry and the
field, where the devkit would stop at an ``assert``), picks the samples, and runs ``DetectionEval``'s own loading,
filtering, accumulation and metrics. Two choices adapt it to a dataset that is not nuScenes:

- **Which samples.** The devkit's splits (train, val, test, mini_*) are hard-coded lists of real nuScenes scenes.
  Devkit 1.2 also reads custom splits from ``<dataroot>/<version>/splits.json`` (split -> scene names), as the
  roadsynth nuScenes export writes it, with ``all`` listing every scene. The evaluated set is one of those custom
  splits (default ``all``: every sample of the version). A predefined devkit name is refused, since the devkit would
  look for real nuScenes scenes under it.
- **Which classes.** ``detection_cvpr_2019`` (class ranges, distance thresholds, TP threshold) with its
  ``class_names`` (the classes ``evaluate()`` scores and the metrics average over) restricted to the detection
  classes that have ground truth in the evaluated set after the devkit's range and point filtering, as
  pycocotools scores only the ground truth's categories: the devkit counts a class without ground truth as AP 0
  and would cap mAP at the share of nuScenes' ten classes a synthetic dataset happens to contain. Predictions of
  the other classes are counted (``ignored_predictions_by_class``) and not scored.

Like ``DetectionEval``, every sample of the set must appear in ``results`` (an empty list where nothing was
detected). Undefined values (NaN) are None; ``eval_time`` is left out of the metrics (wall clock: the output would
differ from run to run).
Imports nothing from ``pipeline`` or ``exporters``; the devkit is imported when used (``.[nuscenes]`` extra).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
from collections import Counter
from pathlib import Path
from typing import Any

from evaluation.validate import InputError, is_number

ALL_SET = "all"
CONFIG = "detection_cvpr_2019"
MAX_BOXES_PER_SAMPLE = 500
DETECTION_NAMES = ("car", "truck", "bus", "trailer", "construction_vehicle", "pedestrian", "motorcycle", "bicycle",
                   "traffic_cone", "barrier")
ATTRIBUTE_NAMES = ("pedestrian.moving", "pedestrian.sitting_lying_down", "pedestrian.standing", "cycle.with_rider",
                   "cycle.without_rider", "vehicle.moving", "vehicle.parked", "vehicle.stopped")


def find_version(dataroot: Path) -> str:
    """The one version folder (holding sample.json) under ``dataroot``."""
    dataroot = Path(dataroot)
    if not dataroot.is_dir():
        raise InputError(f"{dataroot}: not a folder (expected a nuScenes export: roadsynth export --format nuscenes)")
    versions = sorted(p.name for p in dataroot.iterdir() if (p / "sample.json").is_file())
    if len(versions) != 1:
        raise InputError(f"{dataroot}: expected one nuScenes version folder with sample.json, found "
                         f"{versions or 'none'}")
    return versions[0]


def scenes_of(dataroot: Path, version: str, eval_set: str) -> list[str]:
    """Scene names of ``eval_set`` in ``<dataroot>/<version>/splits.json``."""
    from nuscenes.utils.splits import is_predefined_split

    path = Path(dataroot) / version / "splits.json"
    if is_predefined_split(split_name=eval_set):
        raise InputError(f"--eval-set {eval_set}: the nuScenes devkit reserves this name for real nuScenes scenes; "
                         f"evaluate '{ALL_SET}' or a split named otherwise in {path}")
    try:
        splits = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the splits ({exc})") from None
    if not isinstance(splits, dict) or eval_set not in splits or not isinstance(splits[eval_set], list):
        known = sorted(splits) if isinstance(splits, dict) else []
        raise InputError(f"{path}: no split {eval_set!r} (a list of scene names); splits: {known}")
    return splits[eval_set]


def _check_box(box: Any, where: str, token: str) -> None:
    if not isinstance(box, dict):
        raise InputError(f"{where}: expected a JSON object, got {type(box).__name__}")
    checks = {
        "sample_token": (lambda v: v == token, f"the sample token it is listed under ({token!r})"),
        "translation": (lambda v: isinstance(v, list) and len(v) == 3 and all(map(is_number, v)), "3 numbers"),
        "size": (lambda v: isinstance(v, list) and len(v) == 3 and all(is_number(x) and x > 0 for x in v),
                 "3 numbers > 0 (width, length, height)"),
        "rotation": (lambda v: isinstance(v, list) and len(v) == 4 and all(map(is_number, v))
                     and 0 < math.fsum(x * x for x in v) < math.inf, "4 numbers w, x, y, z (a non-zero quaternion)"),
        "velocity": (lambda v: isinstance(v, list) and len(v) == 2 and all(map(is_number, v)), "2 numbers vx, vy"),
        "detection_name": (lambda v: v in DETECTION_NAMES, f"one of {', '.join(DETECTION_NAMES)}"),
        "detection_score": (lambda v: is_number(v) and 0 <= v <= 1, "a number in [0, 1]"),
        "attribute_name": (lambda v: v in ATTRIBUTE_NAMES or v == "", f"'' or one of {', '.join(ATTRIBUTE_NAMES)}"),
    }
    for field, (check, expected) in checks.items():
        if field not in box:
            raise InputError(f"{where}: missing field '{field}' (expected {expected})")
        if not check(box[field]):
            raise InputError(f"{where}: field '{field}' is {box[field]!r} (expected {expected})")


def check_submission(path: Path, sample_tokens: list[str]) -> dict:
    """The submission at ``path`` (``{"meta": {...}, "results": {sample_token: [box, ...]}}``), checked: every box's
    fields, at most :data:`MAX_BOXES_PER_SAMPLE` per sample, every token one of ``sample_tokens`` and every one of them
    present, as ``DetectionEval`` requires."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{path}: not a readable JSON file ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("results"), dict):
        raise InputError(f"{path}: field 'results' missing or not an object (expected the nuScenes detection "
                         "submission format: {\"meta\": {...}, \"results\": {sample_token: [box, ...]}})")
    if not isinstance(data.get("meta"), dict):
        raise InputError(f"{path}: field 'meta' missing or not an object (e.g. {{\"use_lidar\": true, ...}})")
    known = set(sample_tokens)
    for token, boxes in data["results"].items():
        if token not in known:
            raise InputError(f"{path}: results[{token!r}]: not a sample of the evaluated set")
        if not isinstance(boxes, list) or len(boxes) > MAX_BOXES_PER_SAMPLE:
            raise InputError(f"{path}: results[{token!r}]: expected a list of at most {MAX_BOXES_PER_SAMPLE} boxes")
        for i, box in enumerate(boxes):
            _check_box(box, f"{path}: results[{token!r}][{i}]", token)
    missing = [t for t in sample_tokens if t not in data["results"]]
    if missing:
        raise InputError(f"{path}: results: {len(missing)} sample(s) of the evaluated set missing, e.g. {missing[0]!r} "
                         "(list every sample, with [] where nothing was detected)")
    return data


def _open(dataroot: Path, version: str | None, eval_set: str):
    from nuscenes.eval.common.loaders import get_samples_of_scenes
    from nuscenes.nuscenes import NuScenes

    version = version or find_version(dataroot)
    scenes = scenes_of(dataroot, version, eval_set)
    with contextlib.redirect_stdout(io.StringIO()):
        nusc = NuScenes(version=version, dataroot=str(dataroot), verbose=False)
    return nusc, version, get_samples_of_scenes(scene_names=scenes, nusc=nusc)


def evaluate_nuscenes_detection(dataroot: Path, results: Path, *, eval_set: str = ALL_SET,
                                version: str | None = None) -> dict[str, Any]:
    """Score the submission ``results`` on the export at ``dataroot``: the devkit's metrics summary (``mean_ap``,
    ``nd_score``, ``tp_errors``, per class ``mean_dist_aps`` and ``label_tp_errors``, ``cfg``) and what was chosen."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.detection.evaluate import DetectionEval

    nusc, version, tokens = _open(Path(dataroot), version, eval_set)
    submission = check_submission(Path(results), tokens)
    cfg = config_factory(CONFIG)
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()), \
            contextlib.redirect_stderr(io.StringIO()):  # the devkit prints and draws progress bars
        evaluator = DetectionEval(nusc, cfg, str(results), eval_set, output_dir=tmp, verbose=False)
        classes = [c for c in cfg.class_names if any(b.detection_name == c for b in evaluator.gt_boxes.all)]
        if not classes:
            raise InputError(f"{dataroot}: no ground-truth box of set {eval_set!r} passes the devkit's filters "
                             "(class range, at least one LiDAR or radar point): nothing to score")
        # DetectionConfig insists on all ten class ranges; evaluate() and the metrics iterate cfg.class_names.
        evaluator.cfg.class_names = classes
        metrics, _ = evaluator.evaluate()
    summary = _finite_or_none(metrics.serialize())
    summary.pop("eval_time", None)
    ignored = Counter(b["detection_name"] for boxes in submission["results"].values() for b in boxes
                      if b["detection_name"] not in classes)
    return {**summary, "version": version, "eval_set": eval_set, "samples": len(tokens), "classes": classes,
            "config": CONFIG, "ignored_predictions_by_class": dict(sorted(ignored.items())),
            "meta": submission["meta"]}


def _finite_or_none(value: Any) -> Any:
    """``value`` with NaN (the devkit's "undefined", e.g. a velocity error where no ground truth has a velocity) as
    None, numpy numbers as Python ones: JSON without NaN."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float):
        return float(value) if math.isfinite(value) else None
    return value


def ground_truth_submission(dataroot: Path, *, eval_set: str = ALL_SET, version: str | None = None) -> dict:
    """The ground truth of ``eval_set`` as a submission (score 1, the devkit's velocity estimate or 0 where it has
    none): the reference that scores mAP 1 and NDS 1."""
    import numpy as np
    from nuscenes.eval.common.loaders import load_gt_of_sample_tokens
    from nuscenes.eval.detection.data_classes import DetectionBox

    nusc, _, tokens = _open(Path(dataroot), version, eval_set)
    with contextlib.redirect_stderr(io.StringIO()):
        gt = load_gt_of_sample_tokens(nusc, tokens, DetectionBox, verbose=False)
    results = {t: [{"sample_token": t, "translation": list(b.translation), "size": list(b.size),
                    "rotation": list(b.rotation), "velocity": np.nan_to_num(np.asarray(b.velocity)).tolist(),
                    "detection_name": b.detection_name, "detection_score": 1.0, "attribute_name": b.attribute_name}
                   for b in gt[t]] for t in tokens}
    meta = {"use_camera": False, "use_lidar": False, "use_radar": False, "use_map": False, "use_external": True}
    return {"meta": meta, "results": results}
