"""KITTI label directories through evaluation.evaluate: table/errors on converted boxes, KITTI AP delegated."""

from __future__ import annotations

import json

import pytest

from evaluation import evaluate
from evaluation.io_kitti import read_kitti
from evaluation.validate import InputError

GT_000 = """Car 0.00 0 -1.58 100.00 100.00 200.00 150.00 1.65 1.67 3.64 -0.65 1.71 26.70 -1.59
Pedestrian 0.00 1 0.21 400.00 100.00 420.00 160.00 1.87 0.50 0.90 -5.83 1.71 47.96 0.00
DontCare -1 -1 -10 600.00 100.00 700.00 150.00 -1 -1 -1 -1000 -1000 -1000 -10
"""
DET_000 = """Car -1 -1 -1.50 100.00 100.00 200.00 150.00 1.60 1.60 3.60 -0.60 1.70 26.60 -1.55 0.95
Car -1 -1 -1.50 610.00 110.00 640.00 140.00 1.60 1.60 3.60 -0.60 1.70 26.60 -1.55 0.90
Car -1 -1 -1.50 800.00 100.00 840.00 150.00 1.60 1.60 3.60 9.60 1.70 26.60 -1.55 0.80
"""


@pytest.fixture
def kitti_dirs(tmp_path):
    gt, det = tmp_path / "label_2", tmp_path / "det"
    gt.mkdir()
    det.mkdir()
    (gt / "000000.txt").write_text(GT_000)
    (gt / "000001.txt").write_text("")
    (det / "000000.txt").write_text(DET_000)
    return gt, det


def test_conversion(kitti_dirs):
    gt, dt, ignored = read_kitti(*kitti_dirs)
    assert gt.category_names == ["Car", "Pedestrian"]
    assert gt.iscrowd.tolist() == [False, False, True, True]  # DontCare: one crowd region per class
    assert gt.bbox[0].tolist() == [100.0, 100.0, 100.0, 50.0]
    assert gt.distance_valid[:2].all() and gt.occlusion[:2].tolist() == ["0 visible", "1 partly"]
    assert len(dt) == 3 and ignored["kitti_frames_without_detection_file"] == 1


def test_evaluate_on_kitti_dirs(kitti_dirs, tmp_path):
    result = evaluate(*kitti_dirs, tmp_path / "out", metrics="table,errors,kitti")
    rows = {(r["group"], r["class"], r["iou"]): r for r in result.metrics["table"]["rows"]}
    car = rows[("all", "Car", 0.5)]
    assert (car["tp"], car["fp"], car["fn"]) == (1, 1, 0)  # the DontCare detection is neither
    assert rows[("all", "Pedestrian", 0.5)]["fn"] == 1
    assert "results" in result.metrics["kitti"] and "skipped" not in result.metrics["kitti"]
    assert "## KITTI" in (tmp_path / "out" / "report.md").read_text()
    assert set(json.loads((tmp_path / "out" / "metrics.json").read_text())) == {
        "table", "coco", "kitti", "errors", "ignored"}


def test_detection_file_for_unknown_frame_is_an_error(kitti_dirs):
    gt, det = kitti_dirs
    (det / "000009.txt").write_text(DET_000)
    with pytest.raises(InputError, match="000009.txt: frame '000009' has no ground truth"):
        read_kitti(gt, det)


def test_coco_gt_with_kitti_detections_is_refused(kitti_dirs, tmp_path):
    (tmp_path / "gt.json").write_text(json.dumps({"images": [], "annotations": [], "categories": []}))
    with pytest.raises(InputError, match="a directory, but the ground truth"):
        evaluate(tmp_path / "gt.json", kitti_dirs[1])
