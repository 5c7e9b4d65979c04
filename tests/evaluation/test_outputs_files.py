"""evaluation.evaluate writes metrics.json with the agreed keys, plot data, PNGs and report.md."""

from __future__ import annotations

import csv
import json

import pytest

from evaluation import evaluate
from evaluation.validate import InputError

GT = {
    "images": [{"id": 1, "condition": "morning"}, {"id": 2, "condition": "night"}],
    "categories": [{"id": 3, "name": "car"}],
    "annotations": [
        {"id": 1, "image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10], "area": 100.0, "iscrowd": 0,
         "distance_m": 12.0, "occlusion": 0.0},
        {"id": 2, "image_id": 2, "category_id": 3, "bbox": [0, 0, 10, 10], "area": 100.0, "iscrowd": 0,
         "distance_m": 40.0, "occlusion": 0.7},
    ],
}
RESULTS = [{"image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10], "score": 0.9},
           {"image_id": 2, "category_id": 3, "bbox": [0, 0, 6, 10], "score": 0.8},
           {"image_id": 2, "category_id": 3, "bbox": [50, 50, 10, 10], "score": 0.3}]


@pytest.fixture
def inputs(tmp_path):
    (tmp_path / "gt.json").write_text(json.dumps(GT))
    (tmp_path / "res.json").write_text(json.dumps(RESULTS))
    return tmp_path / "gt.json", tmp_path / "res.json"


def test_metrics_json_keys_plots_and_report(inputs, tmp_path):
    out = tmp_path / "out"
    result = evaluate(*inputs, out, group_by="condition")
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) == {"table", "coco", "kitti", "errors", "ignored"}
    assert metrics["kitti"]["skipped"].startswith("the ground truth is a COCO file")
    assert metrics["table"]["score_threshold"] == 0.5
    row = metrics["table"]["rows"][0]
    assert set(row) == {"group", "class", "iou", "precision", "recall", "f1", "tp", "fp", "fn"}
    assert len(metrics["coco"]["stats"]) == 12 and len(metrics["coco"]["names"]) == 12
    assert "car" in metrics["coco"]["per_class"]
    assert metrics["ignored"]["detections_below_score_threshold"] == 1
    night = [r for r in metrics["table"]["rows"] if r["group"] == "night" and r["class"] == "all"]
    assert [r["tp"] for r in night] == [1, 1, 0, 0]  # IoU exactly 0.6
    plots = out / "plots"
    for name in ("pr_iou0.50.json", "pr_iou0.50.png", "pr_iou0.50_night.csv", "table.csv", "table.png",
                 "coco_pr.csv", "coco_pr.png"):
        assert (plots / name).stat().st_size > 0, name
    with (plots / "pr_iou0.50_all.csv").open() as f:
        points = list(csv.DictReader(f))
    assert [float(p["score"]) for p in points] == [0.9, 0.8, 0.3]
    assert float(points[-1]["recall"]) == 1.0 and float(points[-1]["precision"]) == pytest.approx(2 / 3)
    report = (out / "report.md").read_text()
    assert "| morning |" in report and "| night |" in report and "AP50" in report
    assert result.metrics["table"]["f1_optimal"][0]["score_threshold"] == 0.8


def test_metric_selection_records_skips(inputs):
    metrics = evaluate(*inputs, metrics="coco").metrics
    assert metrics["table"] == {"skipped": "not requested"} and "stats" in metrics["coco"]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"metrics": "coco,bogus"}, "unknown metric"), ({"metrics": "coco,coco"}, "twice"),
     ({"iou_thresholds": [0.5, 1.5]}, "IoU thresholds"), ({"group_by": "weather"}, "no image has the attribute")],
)
def test_bad_options_fail_loudly(inputs, kwargs, message):
    with pytest.raises(InputError, match=message):
        evaluate(*inputs, **kwargs)


def test_coco_stats_per_group(inputs):
    """Per group, the COCO stats of its images alone: morning's exact box scores AP 1; night's detection has IoU
    0.6 with its object, a match at 3 of COCO's 10 thresholds (0.5, 0.55, 0.6), so AP 0.3, AP50 1, AP75 0."""
    coco = evaluate(*inputs, group_by="condition", metrics="coco").metrics["coco"]
    assert coco["group_by"] == "condition" and list(coco["stats_by_group"]) == ["morning", "night"]
    morning, night = coco["stats_by_group"]["morning"], coco["stats_by_group"]["night"]
    assert morning[:3] == pytest.approx([1.0, 1.0, 1.0], abs=1e-12)
    assert night[:3] == pytest.approx([0.3, 1.0, 0.0], abs=1e-12)
    assert "stats_by_group" not in evaluate(*inputs, metrics="coco").metrics["coco"]  # no --group-by, no groups
