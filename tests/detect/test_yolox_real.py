"""The real YOLOX-nano (COCO-trained, ../shared/models, not part of the project) through ``detect --onnx``:
its README's sanity check, and the same boxes as the reference decoding script (../shared/hooks) on a
photo, a synthetic composite and rendered frames. Skipped where the model or the script is absent."""

from __future__ import annotations

import importlib.util
import json

import cv2
import numpy as np
import pytest

from pipeline.detect.classmap import COCO80_IDS
from tests.conftest import REPO

SHARED = REPO.parent / "shared"
MODEL = SHARED / "models" / "yolox_nano.onnx"
REFERENCE = SHARED / "hooks" / "lib" / "yolox_coco.py"
pytestmark = pytest.mark.skipif(not MODEL.is_file(), reason=f"{MODEL} not present (a development model)")


@pytest.fixture(scope="module")
def detector():
    from pipeline.detect.onnx import OnnxDetector

    return OnnxDetector(MODEL, score_threshold=0.05)


@pytest.fixture(scope="module")
def reference():
    """The reference script's ``detect`` and its session (the script is read-only: loaded, not copied)."""
    if not REFERENCE.is_file():
        pytest.skip(f"{REFERENCE} not present")
    import onnxruntime as ort

    spec = importlib.util.spec_from_file_location("yolox_coco_reference", REFERENCE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    session = ort.InferenceSession(str(MODEL), providers=["CPUExecutionProvider"])

    def detect(bgr: np.ndarray):
        found = module.detect(session, bgr, 416, 0.05)
        boxes = np.array([np.r_[b[:2], b[:2] + b[2:]] for b, _, _ in found]).reshape(-1, 4)
        return boxes, np.array([COCO80_IDS[c] for _, c, _ in found], int), np.array([s for _, _, s in found])

    return detect


def grace_hopper() -> np.ndarray:
    """(H, W, 3) BGR: matplotlib's sample photo."""
    from matplotlib import cbook

    return cv2.imread(str(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False)))


def composite() -> np.ndarray:
    """A wide synthetic image (so the letterbox pads, unlike 416-friendly photos): noise, the photo at two
    scales, one of them mirrored."""
    rng = np.random.default_rng(0)
    canvas = rng.normal(120, 25, (420, 1000, 3)).clip(0, 255).astype(np.uint8)
    photo = grace_hopper()
    canvas[20:20 + 390, 560:560 + 333] = cv2.resize(photo, (333, 390), interpolation=cv2.INTER_AREA)
    canvas[150:150 + 240, 80:80 + 205] = cv2.resize(photo, (205, 240), interpolation=cv2.INTER_AREA)[:, ::-1]
    return canvas


def iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    lt, rb = np.maximum(a[:, None, :2], b[None, :, :2]), np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = (rb - lt).clip(0).prod(-1)
    area = (a[:, 2:] - a[:, :2]).prod(-1)[:, None] + (b[:, 2:] - b[:, :2]).prod(-1)[None]
    return inter / (area - inter)


def agreement(ours, ref, threshold: float, image_shape) -> tuple[float, int]:
    """Fraction of the reference's detections scoring >= threshold that ours finds with the same class at
    IoU >= 0.8, and how many there were. The reference does not clip boxes to the image; ours does."""
    boxes, cats, scores = ref
    keep = scores >= threshold
    boxes, cats = boxes[keep].copy(), cats[keep]
    boxes[:, 0::2] = boxes[:, 0::2].clip(0, image_shape[1])
    boxes[:, 1::2] = boxes[:, 1::2].clip(0, image_shape[0])
    if not len(boxes):
        return 1.0, 0
    same = (cats[:, None] == ours.category_ids[None]) & (iou(boxes, ours.boxes) >= 0.8)
    return float(same.any(axis=1).mean()), len(boxes)


def test_readme_sanity_check(detector):
    (det,) = detector.predict([cv2.cvtColor(grace_hopper(), cv2.COLOR_BGR2RGB)])
    best = {int(c): float(s) for c, s in zip(det.category_ids[::-1], det.scores[::-1], strict=True)}
    assert detector.family == "yolox"
    assert best[1] == pytest.approx(0.94, abs=0.02) and best[32] == pytest.approx(0.88, abs=0.02)  # person, tie


@pytest.mark.parametrize("image", [grace_hopper, composite], ids=["photo", "composite"])
def test_same_boxes_as_the_reference_script(detector, reference, image):
    bgr = image()
    (det,) = detector.predict([cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)])
    ref = reference(bgr)
    for threshold in (0.3, 0.05):
        fraction, n = agreement(det, ref, threshold, bgr.shape)
        assert fraction >= 0.9, (threshold, fraction, n)
    assert agreement(det, ref, 0.3, bgr.shape)[1] >= 2  # not vacuous: the person and the tie at least
    # and the other way round: nothing of ours >= 0.3 that the reference lacks
    mine = (det.boxes, det.category_ids, det.scores)
    theirs = type(det)(ref[0].copy(), ref[2], ref[1])
    theirs.boxes[:, 0::2] = theirs.boxes[:, 0::2].clip(0, bgr.shape[1])
    theirs.boxes[:, 1::2] = theirs.boxes[:, 1::2].clip(0, bgr.shape[0])
    assert agreement(theirs, mine, 0.3, bgr.shape)[0] >= 0.9


@pytest.fixture(scope="module")
def rendered_coco(dense_highway_run, tmp_path_factory):
    """Two rendered 800x600 morning frames of traffic, exported to COCO."""
    from pipeline.core.config import ConditionConfig, RigConfig, load_config
    from pipeline.stages.cli import main as cli
    from pipeline.stages.render import render

    root = tmp_path_factory.mktemp("yolox")
    condition = load_config(ConditionConfig, "morning", "conditions")[0]
    rig = load_config(RigConfig, "default", "rigs")[0]
    render(dense_highway_run, condition, rig, root / "record", frames=2, workers=1, progress=False)
    assert cli(["export", "--dataset", str(root / "record"), "--format", "coco", "--out", str(root / "coco"),
                "--no-progress"]) == 0
    return root / "coco"


def test_rendered_frames_through_the_cli(rendered_coco, reference, tmp_path):
    from pipeline.stages.cli import main as cli

    out = tmp_path / "yolox.json"
    assert cli(["detect", "--onnx", str(MODEL), "--coco", str(rendered_coco), "--out", str(out), "--no-progress"]) == 0
    results = json.loads(out.read_text())
    gt = json.loads((rendered_coco / "annotations.json").read_text())
    assert {r["image_id"] for r in results} <= {im["id"] for im in gt["images"]}
    total = 0
    for im in gt["images"]:
        bgr = cv2.imread(str(rendered_coco / "images" / im["file_name"]))
        rows = [r for r in results if r["image_id"] == im["id"]]
        boxes = np.array([[x, y, x + w, y + h] for x, y, w, h in (r["bbox"] for r in rows)]).reshape(-1, 4)
        from pipeline.detect.infer import Detections

        ours = Detections(boxes, np.array([r["score"] for r in rows]), np.array([r["category_id"] for r in rows]))
        ref = reference(bgr)
        total += len(ref[2])
        for threshold in (0.3, 0.05):
            assert agreement(ours, ref, threshold, bgr.shape)[0] >= 0.9
    assert total > 0  # the reference finds something on these frames (at 0.05): the comparison is not vacuous
