"""The segmentation metrics (evaluation.segmentation) against cityscapesscripts' own entry point on the same files.

The reference is ``evalPixelLevelSemanticLabeling.main()`` as a user runs it, in a separate process: the ground truth
found through ``CITYSCAPES_DATASET`` (``gtFine/val``), each prediction through ``CITYSCAPES_RESULTS`` by its file-name
rule, results read from the JSON it writes to ``CITYSCAPES_EXPORT_DIR``. Cases where the metrics could differ:
classes absent from the ground truth or from the prediction, void (not evaluated) pixels predicted as anything, an
image with nothing but void, several images and instances of different sizes (iIoU's weights). Every IoU and iIoU
per class and category, the means and the confusion matrix must agree within 1e-6 (undefined: NaN there, null
here). One case is also worked out by hand.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from evaluation.segmentation import evaluate_segmentation
from evaluation.validate import InputError

pytest.importorskip("cityscapesscripts.evaluation.evalPixelLevelSemanticLabeling")

TOL = 1e-6
CAR_AVG_SIZE = 12794.0202738185  # Cityscapes' average car instance size, cityscapesscripts' iIoU weight
REFERENCE = """
import importlib, json, os, sys
import numpy
numpy.in1d = lambda a, b, invert=False: numpy.isin(numpy.ravel(a), b, invert=invert)  # gone in numpy 2.4
from cityscapesscripts.evaluation import evalPixelLevelSemanticLabeling as ev
for dataset, results, export in json.loads(sys.argv[1]):
    os.environ.update(CITYSCAPES_DATASET=dataset, CITYSCAPES_RESULTS=results, CITYSCAPES_EXPORT_DIR=export)
    ev = importlib.reload(ev)  # it reads the environment when imported
    sys.argv = ["evalPixelLevelSemanticLabeling"]
    ev.main()
"""


def write_case(root: Path, images: list[tuple[np.ndarray, np.ndarray, np.ndarray]], city: str = "town") -> Path:
    """gtFine/val/<city>/ and pred/ from (label ids, instance ids, predicted ids) per image (Pillow writes them)."""
    gt_dir, pred = root / "gtFine" / "val" / city, root / "pred"
    gt_dir.mkdir(parents=True)
    pred.mkdir()
    for frame, (labels, instances, predicted) in enumerate(images):
        name = f"{city}_000000_{frame:06d}"
        Image.fromarray(labels.astype(np.uint8)).save(gt_dir / f"{name}_gtFine_labelIds.png")
        Image.fromarray(instances.astype(np.uint16)).save(gt_dir / f"{name}_gtFine_instanceIds.png")
        Image.fromarray(predicted.astype(np.uint8)).save(pred / f"{name}_pred.png")
    return root


def closed_form() -> list:
    """2 x 4: road road car car / sky sky void void; one car instance (2 px)."""
    labels = np.array([[7, 7, 26, 26], [23, 23, 0, 0]])
    instances = np.array([[7, 7, 26000, 26000], [23, 23, 0, 0]])
    predicted = np.array([[7, 26, 26, 26], [23, 7, 23, 26]])
    return [(labels, instances, predicted)]


def absent_classes() -> list:
    """sidewalk never predicted, building never in the ground truth, two persons of different sizes, an all-void
    image whose prediction is anything."""
    labels = np.full((6, 8), 7)
    labels[0, :] = 8
    labels[3:5, 1:3] = 24
    labels[4:6, 5] = 24
    labels[5, 0] = 0
    instances = labels.copy()
    instances[3:5, 1:3] = 24000
    instances[4:6, 5] = 24001
    predicted = np.full((6, 8), 7)
    predicted[0, :] = 11  # sidewalk predicted as building
    predicted[3:5, 1] = 24  # half of the first person
    predicted[5, 5] = 24
    predicted[2, 6] = 24  # a false positive
    void = np.zeros((6, 8), int)
    return [(labels, instances, predicted), (void, void, predicted)]


def random_images(seed: int = 4, n: int = 3) -> list:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        labels = rng.choice([0, 1, 4, 7, 8, 11, 14, 17, 21, 23, 24, 26, 27, 33], size=(12, 16))
        instances = labels.copy()
        things = np.isin(labels, [24, 26, 27, 33])
        instances[things] = labels[things] * 1000 + rng.integers(0, 3, things.sum())
        predicted = np.where(rng.random((12, 16)) < 0.6, labels, rng.integers(0, 34, (12, 16)))
        out.append((labels, instances, predicted))
    return out


CASES = {"closed_form": closed_form, "absent_classes": absent_classes, "random": random_images,
         "all_void": lambda: [(np.zeros((3, 5), int), np.zeros((3, 5), int), np.full((3, 5), 7))]}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, tuple[Path, dict]]:
    """case -> (its folder, cityscapesscripts' result JSON), one process for all cases."""
    base = tmp_path_factory.mktemp("seg")
    roots = {name: write_case(base / name, make()) for name, make in CASES.items()}
    for root in roots.values():
        (root / "export").mkdir()
    runs = [(str(r), str(r / "pred"), str(r / "export")) for r in roots.values()]
    subprocess.run([sys.executable, "-c", REFERENCE, json.dumps(runs)], check=True, capture_output=True, cwd=base)
    return {name: (root, json.loads((root / "export" / "resultPixelLevelSemanticLabeling.json").read_text()))
            for name, root in roots.items()}


def _same(ours: float | None, theirs: float) -> bool:
    return math.isnan(theirs) if ours is None else abs(ours - theirs) <= TOL


@pytest.mark.parametrize("case", list(CASES))
def test_metrics_equal_cityscapesscripts(reference, case):
    root, theirs = reference[case]
    ours = evaluate_segmentation(root, root / "pred")
    assert ours["images"] == len(CASES[case]())
    for name, values in ours["classes"].items():
        assert _same(values["IoU"], theirs["classScores"][name]), name
        assert _same(values["iIoU"], theirs["classInstScores"][name]), name
    for name, score in theirs["categoryScores"].items():
        got = ours["categories"].get(name, {"IoU": None, "iIoU": None})
        assert _same(got["IoU"], score) and _same(got["iIoU"], theirs["categoryInstScores"][name]), name
    for key, field in (("mIoU", "averageScoreClasses"), ("iIoU", "averageScoreInstClasses"),
                       ("mIoU_categories", "averageScoreCategories"),
                       ("iIoU_categories", "averageScoreInstCategories")):
        assert _same(ours[key], theirs[field]), key
    matrix = np.array(theirs["confMatrix"])
    assert ours["confusion_matrix"]["gt_by_predicted"] == matrix.tolist()


def test_closed_form(reference):
    root, _ = reference["closed_form"]
    m = evaluate_segmentation(root / "gtFine", root / "pred")
    c = m["classes"]
    # road: TP 1, FN 1 (as car), FP 1 (sky as road); car: TP 2, FP 1 (road as car; void as car is not counted);
    # sky: TP 1, FN 1 (as road), the void pixel predicted sky not counted
    assert (c["road"]["IoU"], c["car"]["IoU"], c["sky"]["IoU"]) == pytest.approx((1 / 3, 2 / 3, 1 / 2))
    assert m["mIoU"] == pytest.approx(0.5) and c["person"]["IoU"] is None and m["ignored_pixels"] == 2
    # iIoU: the car's 2 pixels weigh CAR_AVG_SIZE / 2 each, all found; the false positive counts 1
    assert c["car"]["iIoU"] == pytest.approx(CAR_AVG_SIZE / (CAR_AVG_SIZE + 1)) and m["iIoU"] == c["car"]["iIoU"]
    assert (c["car"]["gt_pixels"], c["car"]["predicted_pixels"]) == (2, 3)


@pytest.fixture
def case(tmp_path) -> Path:
    return write_case(tmp_path / "case", closed_form() * 2)


def _save(path: Path, array: np.ndarray, mode: str | None = None) -> None:
    Image.fromarray(array, mode).save(path) if mode else Image.fromarray(array).save(path)


def test_bad_input_is_named(case):
    gt = case / "gtFine" / "val" / "town"
    pred = case / "pred"
    first = gt / "town_000000_000000_gtFine_labelIds.png"
    target = pred / "town_000000_000000_pred.png"
    good = target.read_bytes()

    target.unlink()
    with pytest.raises(InputError, match=rf"no prediction for {first} \(expected a file town_000000_000000\*\.png"):
        evaluate_segmentation(case, pred)
    target.write_bytes(good)
    (pred / "town_000000_000000_other.png").write_bytes(good)
    with pytest.raises(InputError, match=f"several predictions for {first}"):
        evaluate_segmentation(case, pred)
    (pred / "town_000000_000000_other.png").unlink()

    for array, match in ((np.zeros((3, 4), np.uint8), r"3x3 pixels|4x3 pixels; expected the size"),
                         (np.zeros((2, 4, 3), np.uint8), "a RGB image"),
                         (np.full((2, 4), 255, np.uint8), r"\[255\] are not Cityscapes label ids \(0-33\) \(255: "
                                                          "Cityscapes wants label ids, not train ids"),
                         (np.full((2, 4), 40, np.uint8), r"\[40\] are not Cityscapes label ids")):
        _save(target, array)
        with pytest.raises(InputError, match=f"{target}: .*{match}"):
            evaluate_segmentation(case, pred)
    target.write_bytes(good)

    instances = gt / "town_000000_000000_gtFine_instanceIds.png"
    kept = instances.read_bytes()
    instances.unlink()
    with pytest.raises(InputError, match=f"{instances}: missing"):
        evaluate_segmentation(case, pred)
    instances.write_bytes(kept)
    _save(first, np.full((2, 4), 99, np.uint8))
    with pytest.raises(InputError, match=rf"{first}: label id\(s\) \[99\]"):
        evaluate_segmentation(case, pred)
    with pytest.raises(InputError, match="no \\*_gtFine_labelIds.png file"):
        evaluate_segmentation(pred, pred)
    with pytest.raises(InputError, match="not a folder; --detections"):
        evaluate_segmentation(case, target)


def test_cli(case, tmp_path, capsys):
    from pipeline.stages.cli import main

    out = tmp_path / "eval"
    assert main(["evaluate", "--task", "segmentation", "--gt", str(case), "--detections", str(case / "pred"),
                 "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["meta.json", "metrics.json", "report.md"]
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mIoU"] == pytest.approx(0.5) and metrics["images"] == 2
    assert "| car | 0.6667 |" in (out / "report.md").read_text()
    assert json.loads((out / "meta.json").read_text())["config"]["task"] == "segmentation"
    assert main(["evaluate", "--task", "segmentation", "--gt", str(case), "--detections", str(case / "pred"),
                 "--iou", "0.5", "--out", str(tmp_path / "x")]) == 2
    assert "--iou apply to --task detection only, not segmentation" in capsys.readouterr().err
    (case / "pred" / "town_000000_000001_pred.png").unlink()
    assert main(["evaluate", "--task", "segmentation", "--gt", str(case), "--detections", str(case / "pred"),
                 "--out", str(tmp_path / "y")]) == 2
    assert "no prediction for" in capsys.readouterr().err and not (tmp_path / "y").exists()
