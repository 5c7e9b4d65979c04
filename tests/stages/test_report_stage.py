"""The report stage: paper-style table and COCO AP per condition from a real evaluation, example strip."""

from __future__ import annotations

import json

import cv2
import pytest

from pipeline.stages.cli import main as cli
from tests.exporters.synthetic_record import build_record


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    """A COCO export of two conditions, and detections: every GT box of the morning images and half of the
    night ones (the rest missed), scores 0.9."""
    root = tmp_path_factory.mktemp("report")
    for condition in ("morning", "night"):
        build_record(root / "records" / f"highway-1-{condition}", condition=condition)
    assert cli(["export", "--dataset", str(root / "records"), "--format", "coco", "--out", str(root / "coco"),
                "--no-progress"]) == 0
    gt = json.loads((root / "coco" / "annotations.json").read_text())
    condition = {img["id"]: img["condition"] for img in gt["images"]}
    dets, night_seen = [], 0
    for ann in sorted(gt["annotations"], key=lambda a: a["id"]):
        if ann["iscrowd"]:
            continue
        if condition[ann["image_id"]] == "night":
            night_seen += 1
            if night_seen % 2 == 0:
                continue
        dets.append({"image_id": ann["image_id"], "category_id": ann["category_id"], "bbox": ann["bbox"],
                     "score": 0.9})
    (root / "dets.json").write_text(json.dumps(dets))
    assert cli(["evaluate", "--gt", str(root / "coco" / "annotations.json"), "--detections", str(root / "dets.json"),
                "--group-by", "condition", "--metrics", "table,coco", "--out", str(root / "eval")]) == 0
    assert cli(["report", "--eval", str(root / "eval"), "--gt", str(root / "coco" / "annotations.json"),
                "--detections", str(root / "dets.json"), "--out", str(root / "report")]) == 0
    return root, night_seen


def test_flat_metrics_per_condition(scored):
    root, night_seen = scored
    metrics = json.loads((root / "report" / "metrics.json").read_text())
    assert set(metrics) == {"all", "morning", "night"}
    assert metrics["morning"]["recall@0.5"] == pytest.approx(1.0)
    assert metrics["morning"]["precision@0.8"] == pytest.approx(1.0)
    assert metrics["night"]["recall@0.5"] == pytest.approx(((night_seen + 1) // 2) / night_seen)
    assert metrics["morning"]["coco_ap"] == pytest.approx(1.0)
    assert metrics["night"]["coco_ap"] < metrics["morning"]["coco_ap"]


def test_markdown_and_examples(scored):
    root, _ = scored
    text = (root / "report" / "report.md").read_text()
    assert "| condition | P@0.5 | R@0.5 | P@0.6 | R@0.6 | P@0.7 | R@0.7 | P@0.8 | R@0.8 |" in text
    assert "| morning | 100.0 | 100.0 |" in text
    strip = cv2.imread(str(root / "report" / "examples.png"))
    assert strip is not None and strip.shape[0] > 2 * 200  # one row per condition
