"""The report stage: paper-style table and COCO AP per condition from a real evaluation, example strip."""

from __future__ import annotations

import json
import shutil

import cv2
import pytest

from pipeline.stages.cli import main as cli
from tests.evaluation.test_coco_vs_pycocotools import reference
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


def test_coco_ap_per_condition_is_pycocotools_on_that_conditions_images(scored):
    """The COCO AP and AP50 of each condition (from the evaluation's metrics.json, grouped there) are pycocotools'
    on a ground truth and results holding only that condition's images."""
    root, _ = scored
    gt = json.loads((root / "coco" / "annotations.json").read_text())
    dets = json.loads((root / "dets.json").read_text())
    metrics = json.loads((root / "report" / "metrics.json").read_text())
    text = (root / "report" / "report.md").read_text()
    for condition in ("morning", "night"):
        ids = {img["id"] for img in gt["images"] if img["condition"] == condition}
        alone = dict(gt, images=[img for img in gt["images"] if img["id"] in ids],
                     annotations=[a for a in gt["annotations"] if a["image_id"] in ids])
        stats = reference(alone, [d for d in dets if d["image_id"] in ids]).stats
        assert [metrics[condition]["coco_ap"], metrics[condition]["coco_ap50"]] == pytest.approx(stats[:2], abs=1e-12)
        row = f"| {condition} | " + " | ".join(f"{100 * stats[k]:.1f}" for k in (0, 1, 2, 8)) + " |"
        assert row in text.split("## COCO AP per condition")[1]


def test_report_needs_the_evaluations_coco_stats_per_group(scored, capsys, tmp_path):
    root, _ = scored
    fake = tmp_path / "eval"
    shutil.copytree(root / "eval", fake)
    metrics = json.loads((fake / "metrics.json").read_text())
    del metrics["coco"]["stats_by_group"]
    (fake / "metrics.json").write_text(json.dumps(metrics))
    code, first, written = _report(root, capsys, eval_dir=fake)
    assert (code, written) == (2, False)
    assert first.startswith(f"roadsynth report: error: {fake / 'metrics.json'}: coco.stats_by_group is missing")


def test_markdown_and_examples(scored):
    root, _ = scored
    text = (root / "report" / "report.md").read_text()
    assert "| condition | P@0.5 | R@0.5 | P@0.6 | R@0.6 | P@0.7 | R@0.7 | P@0.8 | R@0.8 |" in text
    assert "| morning | 100.0 | 100.0 |" in text
    strip = cv2.imread(str(root / "report" / "examples.png"))
    assert strip is not None and strip.shape[0] > 2 * 200  # one row per condition


def _report(root, capsys, *extra, gt=None, dets=None, eval_dir=None):
    """Run the report CLI; (exit code, first stderr line, whether the output folder exists)."""
    out = root / "report-bad"
    code = cli(["report", "--eval", str(eval_dir or root / "eval"),
                "--gt", str(gt or root / "coco" / "annotations.json"),
                "--detections", str(dets or root / "dets.json"), "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err.splitlines()[0] if err else "", out.exists()


def test_report_rejects_a_group_by_the_evaluation_did_not_use(scored, capsys):
    root, _ = scored
    code, first, written = _report(root, capsys, "--group-by", "weather")
    meta = root / "eval" / "meta.json"
    assert (code, written) == (2, False)
    assert first.startswith(f"roadsynth report: error: {meta}: config.group_by is 'condition', not 'weather'")


def test_report_rejects_detections_that_were_not_evaluated(scored, capsys):
    root, _ = scored
    other = root / "other_dets.json"
    other.write_text(json.dumps(json.loads((root / "dets.json").read_text())[1:]))  # one detection less
    code, first, written = _report(root, capsys, dets=other)
    assert (code, written) == (2, False)
    assert first.startswith(f"roadsynth report: error: {other}: not the --detections that {root / 'eval'} evaluated")
    assert "config.detections_sha256" in first


def test_report_rejects_ground_truth_that_was_not_evaluated(scored, capsys):
    root, _ = scored
    gt = json.loads((root / "coco" / "annotations.json").read_text())
    gt["images"] = gt["images"][:-1]
    other = root / "other_gt.json"
    other.write_text(json.dumps(gt))
    code, first, written = _report(root, capsys, gt=other)
    assert (code, written) == (2, False)
    assert first.startswith(f"roadsynth report: error: {other}: not the --gt that {root / 'eval'} evaluated")


def test_report_needs_an_evaluation_meta_with_digests(scored, capsys, tmp_path):
    root, _ = scored
    fake = tmp_path / "eval"
    fake.mkdir()
    (fake / "metrics.json").write_text((root / "eval" / "metrics.json").read_text())
    code, first, written = _report(root, capsys, eval_dir=fake)
    assert (code, written) == (2, False)
    assert first == f"roadsynth report: error: {fake / 'meta.json'}: not found " \
                    "(--eval must be an output folder of `roadsynth evaluate`)"
    meta = json.loads((root / "eval" / "meta.json").read_text())
    del meta["config"]["gt_sha256"]
    (fake / "meta.json").write_text(json.dumps(meta))
    code, first, written = _report(root, capsys, eval_dir=fake)
    assert (code, written) == (2, False)
    assert first.startswith(f"roadsynth report: error: {fake / 'meta.json'}: config.gt_sha256 is missing")
    meta = json.loads((root / "eval" / "meta.json").read_text())
    meta["config"]["group_by"] = None
    (fake / "meta.json").write_text(json.dumps(meta))
    code, first, _ = _report(root, capsys, eval_dir=fake)
    assert code == 2 and first.startswith(f"roadsynth report: error: {fake / 'meta.json'}: config.group_by is null")


def test_two_detectors_side_by_side_with_the_papers_table(scored, tmp_path):
    root, night_seen = scored
    gt = root / "coco" / "annotations.json"
    # a second "detector": the first one's detections of the morning images only
    images = {img["id"]: img["condition"] for img in json.loads(gt.read_text())["images"]}
    morning = [d for d in json.loads((root / "dets.json").read_text()) if images[d["image_id"]] == "morning"]
    (tmp_path / "morning.json").write_text(json.dumps(morning))
    assert cli(["evaluate", "--gt", str(gt), "--detections", str(tmp_path / "morning.json"), "--group-by",
                "condition", "--metrics", "table,coco", "--out", str(tmp_path / "eval")]) == 0
    assert cli(["report", "--eval", f"base={root / 'eval'}", "--eval", f"onnx={tmp_path / 'eval'}", "--gt", str(gt),
                "--detections", f"base={root / 'dets.json'}", "--detections", f"onnx={tmp_path / 'morning.json'}",
                "--paper", "--out", str(tmp_path / "report")]) == 0
    text = (tmp_path / "report" / "report.md").read_text()
    assert "| condition | source | P@0.5 | P@0.6 | P@0.7 | P@0.8 | R@0.5 | R@0.6 | R@0.7 | R@0.8 |" in text
    assert "| morning | paper (Li et al., Table 1) | 0.82 | 0.81 | 0.79 | 0.47 | 0.41 | 0.40 | 0.40 | 0.28 |" in text
    assert "| night | paper (Li et al., Table 1) | 0.81 | 0.79 | 0.70 | 0.37 | 0.23 | 0.23 | 0.21 | 0.12 |" in text
    assert "| morning | base | 1.00 | 1.00 | 1.00 | 1.00 | 1.00 | 1.00 | 1.00 | 1.00 |" in text
    assert "| night | onnx | - | - | - | - | 0.00 | 0.00 | 0.00 | 0.00 |" in text  # no detections: precision null
    assert "## Detector: base" in text and "## Detector: onnx" in text and "height_px:" in text
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    assert set(metrics) == {"base", "onnx"}
    assert metrics["base"]["night"]["recall@0.5"] == pytest.approx(((night_seen + 1) // 2) / night_seen)
    assert metrics["onnx"]["night"]["recall@0.5"] == 0.0 and metrics["onnx"]["morning"]["recall@0.5"] == 1.0


def test_several_detectors_need_names(scored, tmp_path, capsys):
    root, _ = scored
    gt = root / "coco" / "annotations.json"
    assert cli(["report", "--eval", str(root / "eval"), "--eval", str(root / "eval"), "--gt", str(gt),
                "--detections", str(root / "dets.json"), "--out", str(tmp_path / "r")]) == 2
    assert "each needs NAME=PATH" in capsys.readouterr().err
