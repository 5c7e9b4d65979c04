"""Semantic segmentation metrics (IoU per class, mIoU, iIoU) on Cityscapes files, with cityscapesscripts as the engine.

cityscapesscripts (``cityscapesscripts`` on PyPI) is the tool of record: its ``evalPixelLevelSemanticLabeling``
computes everything here (``evaluateImgLists``: the confusion matrix over all images, IoU and instance-weighted iIoU
per class and per category, and their averages). This module is the adapter around it: it finds the ground truth
(``*_gtFine_labelIds.png`` with their ``*_gtFine_instanceIds.png``) and each one's prediction by cityscapesscripts'
own rule (a file ``<city>_<sequence>_<frame>*.png`` anywhere under the predictions folder, exactly one), checks every
image first (cityscapesscripts ends the process on bad input, or fails with an IndexError), and runs the evaluation
on its own copy of the script's settings: quiet, no JSON file written, nothing read from or written to
``CITYSCAPES_DATASET`` / ``CITYSCAPES_RESULTS`` (those are read when the module is imported, which happens with them
pointing into a temporary folder).

Semantics (cityscapesscripts'): pixels whose ground truth is a label Cityscapes does not evaluate (``ignoreInEval``:
unlabeled, ego vehicle, guard rail, ...) are not scored; a class's IoU = TP / (TP + FP + FN) is undefined (``null``)
when it is in neither the ground truth nor the prediction of any scored pixel, 0 when it is in only one of them; the
mean (mIoU) is over the defined classes. iIoU weighs each ground-truth instance's pixels by Cityscapes' average
instance size of its class over the instance's size (``args.avgClassSize``). numpy 2.4 removed ``np.in1d``, which
the iIoU code calls; the evaluation module is given ``np.isin(a, b).ravel()`` under that name (the same function).
"""

from __future__ import annotations

import contextlib
import copy
import io
import logging
import os
import tempfile
import types
from bisect import bisect_left
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.validate import InputError

log = logging.getLogger(__name__)

GT_SUFFIX = "_gtFine_labelIds.png"
INSTANCE_SUFFIX = "_gtFine_instanceIds.png"
PREDICTION_MODES = ("L", "P", "I;16")
"""Pillow modes of a prediction: 8-bit grey or palette (the index is the label id), 16-bit grey."""
_ENV = ("CITYSCAPES_DATASET", "CITYSCAPES_RESULTS", "CITYSCAPES_EXPORT_DIR")


def _cityscapes():
    """cityscapesscripts' pixel-level evaluation module, imported with its environment variables pointing into a
    temporary folder (it reads them on import); :class:`InputError` saying how to install it when missing."""
    try:
        with tempfile.TemporaryDirectory() as tmp:
            saved = {k: os.environ.get(k) for k in _ENV}
            os.environ.update(dict.fromkeys(_ENV, tmp))
            try:
                from cityscapesscripts.evaluation import evalPixelLevelSemanticLabeling as module
            finally:
                for key, value in saved.items():
                    if value is None:
                        os.environ.pop(key, None)
                    else:
                        os.environ[key] = value
    except ImportError as exc:
        raise InputError(f"segmentation evaluation needs cityscapesscripts ({exc}): pip install '.[cityscapes]' and "
                         "pip install --no-deps cityscapesscripts==2.3.0 (make setup-dev does both)") from None
    return module


class _NumpyWithIn1d(types.ModuleType):
    """numpy, plus ``in1d`` (removed in numpy 2.4) for cityscapesscripts' iIoU code."""

    def __init__(self) -> None:
        super().__init__("numpy")

    def __getattr__(self, name: str) -> Any:
        return getattr(np, name)

    @staticmethod
    def in1d(a: Any, b: Any, invert: bool = False) -> np.ndarray:
        return np.isin(np.ravel(a), b, invert=invert)


def labels() -> dict[int, Any]:
    """cityscapesscripts' labels by id (ids >= 0: those an image can hold)."""
    from cityscapesscripts.helpers.labels import id2label

    return {i: label for i, label in id2label.items() if i >= 0}


def find_ground_truth(gt: Path) -> list[Path]:
    """The ``*_gtFine_labelIds.png`` files under ``gt`` (a Cityscapes export or dataset root: its ``gtFine``; or any
    folder below it, e.g. ``gtFine/val``), sorted."""
    gt = Path(gt)
    if not gt.is_dir():
        raise InputError(f"{gt}: not a folder; --gt is a Cityscapes export (or its gtFine folder, or a split or city "
                         f"folder of it) holding *{GT_SUFFIX} files")
    root = gt / "gtFine" if (gt / "gtFine").is_dir() else gt
    files = sorted(root.rglob(f"*{GT_SUFFIX}"))
    if not files:
        raise InputError(f"{root}: no *{GT_SUFFIX} file in it or below (expected Cityscapes' "
                         f"gtFine/<split>/<city>/<city>_<sequence>_<frame>{GT_SUFFIX})")
    return files


def core_name(gt_file: Path) -> str:
    """``<city>_<sequence>_<frame>`` of a Cityscapes file name (cityscapesscripts' ``getCoreImageFileName``)."""
    parts = gt_file.name.split("_")
    if len(parts) != 5:
        raise InputError(f"{gt_file}: not a Cityscapes file name <city>_<sequence>_<frame>{GT_SUFFIX} (the city may "
                         "not contain '_')")
    return "_".join(parts[:3])


def find_predictions(predictions: Path, gt_files: list[Path]) -> list[Path]:
    """Each ground truth file's prediction, by cityscapesscripts' rule: the one file ``<city>_<sequence>_<frame>*.png``
    anywhere under ``predictions``. None, or more than one, is an :class:`InputError` naming the ground truth."""
    predictions = Path(predictions)
    if not predictions.is_dir():
        raise InputError(f"{predictions}: not a folder; --detections is a folder of predicted label id PNGs named "
                         "<city>_<sequence>_<frame>*.png (e.g. <city>_000000_000010_pred.png)")
    found = sorted((p.name, p) for p in predictions.rglob("*.png") if p.is_file())
    names = [n for n, _ in found]
    out = []
    for gt_file in gt_files:
        core = core_name(gt_file)
        lo = bisect_left(names, core)
        hits = []
        while lo < len(names) and names[lo].startswith(core):
            hits.append(found[lo][1])
            lo += 1
        if not hits:
            raise InputError(f"{predictions}: no prediction for {gt_file} (expected a file {core}*.png: label ids, "
                             "8-bit, the ground truth's size)")
        if len(hits) > 1:
            raise InputError(f"{predictions}: several predictions for {gt_file}: {', '.join(map(str, hits))} (exactly "
                             f"one {core}*.png)")
        out.append(hits[0])
    return out


def _read(path: Path, modes: tuple[str, ...], expected: str) -> np.ndarray:
    from PIL import Image

    try:
        with Image.open(path) as image:
            mode = image.mode
            array = np.array(image)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not a readable PNG ({exc}); expected {expected}") from None
    if mode not in modes:
        raise InputError(f"{path}: a {mode} image (Pillow mode, shape {array.shape}, {array.dtype}); expected "
                         f"{expected}")
    return array


def _unknown(values: np.ndarray, known: np.ndarray) -> list[int]:
    present = np.unique(values)
    return [int(v) for v in present[~np.isin(present, known)]]


def check_pair(gt_file: Path, prediction: Path, known_ids: np.ndarray, instance_ids: np.ndarray) -> None:
    """Refuse, naming the file, what cityscapesscripts would end the process on or crash over: an image that is not
    single-channel integers, sizes that differ, a label id Cityscapes does not have, a missing instance image."""
    gt = _read(gt_file, ("L",), "an 8-bit grey PNG of Cityscapes label ids")
    bad = _unknown(gt, known_ids)
    if bad:
        raise InputError(f"{gt_file}: label id(s) {bad[:10]} are not Cityscapes label ids (0-33)")
    instance_file = gt_file.with_name(gt_file.name[: -len(GT_SUFFIX)] + INSTANCE_SUFFIX)
    if not instance_file.is_file():
        raise InputError(f"{instance_file}: missing; the ground truth's instance image (for iIoU) is expected beside "
                         f"{gt_file.name}")
    inst = _read(instance_file, ("I;16", "I", "L"), "a 16-bit grey PNG of Cityscapes instance ids")
    if inst.shape != gt.shape:
        raise InputError(f"{instance_file}: {inst.shape[1]}x{inst.shape[0]} pixels; expected its labelIds image's "
                         f"{gt.shape[1]}x{gt.shape[0]}")
    bad = _unknown(inst, instance_ids)
    if bad:
        raise InputError(f"{instance_file}: instance id(s) {bad[:10]} are neither a label id (0-33) nor label id x "
                         "1000 + n of a label with instances")
    pred = _read(prediction, PREDICTION_MODES, "a single-channel PNG of Cityscapes label ids (8-bit grey or "
                       "palette; 16-bit grey): one id per pixel, not colours")
    if pred.shape != gt.shape:
        raise InputError(f"{prediction}: {pred.shape[1]}x{pred.shape[0]} pixels; expected the size of {gt_file} "
                         f"({gt.shape[1]}x{gt.shape[0]})")
    bad = _unknown(pred, known_ids)
    if bad:
        hint = " (255: Cityscapes wants label ids, not train ids)" if 255 in bad else ""
        raise InputError(f"{prediction}: label id(s) {bad[:10]} are not Cityscapes label ids (0-33){hint}")


def _settings(module: Any, tmp: str) -> Any:
    """A copy of the script's settings (its global ``args``) for one quiet run that writes no file."""
    args = copy.copy(module.args)
    args.quiet, args.JSONOutput, args.colorized, args.bold, args.nocol = True, False, False, "", ""
    args.evalInstLevelScore, args.evalPixelAccuracy, args.normalized = True, False, True
    args.evalLabels, args.predictionPath, args.predictionWalk = [], None, None
    args.avgClassSize = dict(module.args.avgClassSize)
    args.exportFile = os.path.join(tmp, "resultPixelLevelSemanticLabeling.json")
    return args


def run_cityscapes(predictions: list[Path], gt_files: list[Path]) -> dict[str, Any]:
    """cityscapesscripts' ``evaluateImgLists`` on checked pairs: its result dict (``classScores``,
    ``classInstScores``, ``categoryScores``, ``averageScoreClasses``, ..., ``confMatrix``)."""
    module = _cityscapes()
    output = io.StringIO()
    saved_np = module.np
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(output):
        module.np = _NumpyWithIn1d()
        try:
            return module.evaluateImgLists([str(p) for p in predictions], [str(g) for g in gt_files],
                                           _settings(module, tmp))
        except SystemExit:  # printError: every case it reports is checked first; still say what it said
            raise InputError(f"cityscapesscripts refused the input: {output.getvalue().strip()}") from None
        finally:
            module.np = saved_np


def _finite(value: Any) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def evaluate_segmentation(gt: Path, predictions: Path) -> dict[str, Any]:
    """IoU and iIoU per class and category, mIoU and iIoU averages, of the predicted label id images under
    ``predictions`` against the Cityscapes ground truth under ``gt``; the metrics.json dict (undefined values null)."""
    from importlib.metadata import PackageNotFoundError, version

    gt_files = find_ground_truth(Path(gt))
    prediction_files = find_predictions(Path(predictions), gt_files)
    by_id = labels()
    known = np.array(sorted(by_id))
    instances = np.concatenate([known, *[np.arange(i * 1000, i * 1000 + 1000) for i, lab in by_id.items()
                                         if lab.hasInstances]])
    for gt_file, prediction in zip(gt_files, prediction_files, strict=True):
        check_pair(gt_file, prediction, known, instances)
    result = run_cityscapes(prediction_files, gt_files)
    matrix = np.asarray(result["confMatrix"], np.int64)
    scored = [i for i, lab in by_id.items() if not lab.ignoreInEval]
    classes = {by_id[i].name: {"id": i, "IoU": _finite(result["classScores"][by_id[i].name]),
                               "iIoU": _finite(result["classInstScores"][by_id[i].name]),
                               "gt_pixels": int(matrix[i].sum()), "predicted_pixels": int(matrix[scored, i].sum())}
               for i in scored}
    categories = {c: {"IoU": _finite(v), "iIoU": _finite(result["categoryInstScores"][c])}
                  for c, v in result["categoryScores"].items() if _finite(v) is not None
                  or _finite(result["categoryInstScores"][c]) is not None}
    try:
        engine = f"cityscapesscripts {version('cityscapesscripts')}"
    except PackageNotFoundError:
        engine = "cityscapesscripts"
    return {"task": "segmentation", "engine": engine, "images": len(gt_files),
            "mIoU": _finite(result["averageScoreClasses"]), "iIoU": _finite(result["averageScoreInstClasses"]),
            "mIoU_categories": _finite(result["averageScoreCategories"]),
            "iIoU_categories": _finite(result["averageScoreInstCategories"]),
            "classes": classes, "categories": categories,
            "ignored_pixels": int(matrix.sum() - matrix[scored].sum()),
            "confusion_matrix": {"label_ids": [int(i) for i in known], "gt_by_predicted": matrix.tolist()}}


def markdown_summary(metrics: dict[str, Any]) -> str:
    """report.md: IoU and iIoU per evaluated class, and the means, as a Markdown table."""
    def fmt(value: float | None) -> str:
        return "n/a" if value is None else f"{value:.4f}"

    rows = [("**mean**", metrics["mIoU"], metrics["iIoU"], "", ""), *(
        (name, c["IoU"], c["iIoU"], str(c["gt_pixels"]), str(c["predicted_pixels"]))
        for name, c in metrics["classes"].items())]
    body = "".join(f"| {name} | {fmt(iou)} | {fmt(iiou)} | {gt} | {pred} |\n" for name, iou, iiou, gt, pred in rows)
    return (f"# Segmentation evaluation\n\n{metrics['engine']}'s pixel-level evaluation of {metrics['images']} "
            "image(s); fractions, not percentages. n/a: the class is in neither the ground truth nor the prediction "
            "(IoU), or has no instances (iIoU); means are over the defined values. "
            f"{metrics['ignored_pixels']} ground-truth pixels of labels Cityscapes does not evaluate were not scored."
            "\n\n| class | IoU | iIoU | gt pixels | predicted pixels |\n|---|---:|---:|---:|---:|\n" + body)
