"""evaluation.nuscenes_detection against the nuScenes devkit's DetectionEval run directly, on a nuScenes export of the
hand-built records (tests/exporters/synthetic_record.py): ground truth as predictions, boxes shifted by a known
amount, a missed object and a false positive."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from evaluation.nuscenes_detection import evaluate_nuscenes_detection, ground_truth_submission
from evaluation.validate import InputError
from exporters.base import get_exporter
from exporters.nuscenes_tables import VERSION
from tests.exporters.synthetic_record import build_record

pytest.importorskip("nuscenes")


@pytest.fixture(scope="module")
def export(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("nus-eval")
    records = [build_record(root / f"highway-{seed}", seed=seed, frames=4) for seed in (1, 2)]
    out = root / "export"
    get_exporter("nuscenes").export(records, out)
    return out


@pytest.fixture(scope="module")
def gt(export) -> dict:
    return ground_truth_submission(export)


def _write(tmp_path: Path, submission: dict) -> Path:
    path = tmp_path / "results.json"
    path.write_text(json.dumps(submission))
    return path


def devkit_direct(export: Path, results: Path, classes: list[str]) -> dict:
    """DetectionEval as its documentation runs it, on the custom split 'all', scoring ``classes``."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.detection.evaluate import DetectionEval
    from nuscenes.nuscenes import NuScenes

    nusc = NuScenes(version=VERSION, dataroot=str(export), verbose=False)
    cfg = config_factory("detection_cvpr_2019")
    evaluator = DetectionEval(nusc, cfg, str(results), "all", output_dir=str(results.parent / "devkit"), verbose=False)
    evaluator.cfg.class_names = classes
    metrics, _ = evaluator.evaluate()
    return metrics.serialize()


def test_ground_truth_scores_one(export, gt, tmp_path):
    metrics = evaluate_nuscenes_detection(export, _write(tmp_path, gt))
    assert metrics["classes"] == ["car", "truck"]  # the pedestrian at 95 m is beyond its class range (40 m)
    assert metrics["mean_ap"] == pytest.approx(1.0)
    assert metrics["nd_score"] == pytest.approx(1.0)
    assert metrics["tp_errors"] == pytest.approx(dict.fromkeys(metrics["tp_errors"], 0.0), abs=1e-9)


def test_shifted_boxes_give_their_shift_as_ate(export, gt, tmp_path):
    shifted = copy.deepcopy(gt)
    for boxes in shifted["results"].values():
        for box in boxes:
            box["translation"][0] += 0.3
    metrics = evaluate_nuscenes_detection(export, _write(tmp_path, shifted))
    assert metrics["mean_ap"] == pytest.approx(1.0)  # 0.3 m is within every distance threshold
    assert metrics["tp_errors"]["trans_err"] == pytest.approx(0.3, abs=1e-9)
    assert metrics["nd_score"] == pytest.approx((5 + 0.7 + 4) / 10)


def test_misses_and_false_positives_as_the_devkit_scores_them(export, gt, tmp_path):
    sub = copy.deepcopy(gt)
    tokens = sorted(sub["results"])
    cars = [b for b in sub["results"][tokens[0]] if b["detection_name"] == "car"]
    sub["results"][tokens[0]].remove(cars[0])  # a missed car
    fp = dict(copy.deepcopy(cars[1]), detection_score=0.9, sample_token=tokens[1])
    fp["translation"] = [fp["translation"][0] + 20.0, fp["translation"][1], fp["translation"][2]]
    sub["results"][tokens[1]].append(fp)  # a false positive outscoring nothing: all gt boxes score 1
    for box in sub["results"][tokens[2]]:
        box["size"] = [s * 1.2 for s in box["size"]]
        box["velocity"] = [box["velocity"][0] + 1.0, box["velocity"][1]]
        box["detection_score"] = 0.5
    sub["results"][tokens[3]][0]["attribute_name"] = "vehicle.parked"
    path = _write(tmp_path, sub)
    ours = evaluate_nuscenes_detection(export, path)
    ref = devkit_direct(export, path, ours["classes"])
    assert ours["mean_ap"] == ref["mean_ap"] and ours["nd_score"] == ref["nd_score"]
    assert ours["tp_errors"] == ref["tp_errors"] and ours["label_tp_errors"] == ref["label_tp_errors"]
    assert ours["mean_dist_aps"] == ref["mean_dist_aps"]
    assert ours["mean_ap"] < 1 and ours["nd_score"] < 1
    for name in ("scale_err", "vel_err", "attr_err"):
        assert 0 < ours["tp_errors"][name] < 1
    assert np.isfinite(ours["tp_errors"]["orient_err"])


@pytest.mark.parametrize(("mutate", "message"), [
    (lambda s, t: s["results"].pop(t), "sample\\(s\\) of the evaluated set missing"),
    (lambda s, t: s["results"][t][0].update(size=[1.0, -2.0, 1.0]), r"\]\[0\]: field 'size' is \[1.0, -2.0, 1.0\]"),
    (lambda s, t: s["results"][t][0].update(detection_name="tram"), r"field 'detection_name' is 'tram'"),
    (lambda s, t: s["results"][t][0].pop("velocity"), r"missing field 'velocity'"),
    (lambda s, t: s["results"].update(nope=[]), r"results\['nope'\]: not a sample"),
    (lambda s, t: s.pop("meta"), r"field 'meta' missing"),
    (lambda s, t: s["results"][t][0].update(detection_score=1e308), r"field 'detection_score' is 1e\+308"),
])
def test_bad_submissions_name_the_file_and_field(export, gt, tmp_path, mutate, message):
    sub = copy.deepcopy(gt)
    mutate(sub, sorted(sub["results"])[0])
    path = _write(tmp_path, sub)
    with pytest.raises(InputError, match=message) as info:
        evaluate_nuscenes_detection(export, path)
    assert str(path) in str(info.value)


def test_eval_set_names(export, gt, tmp_path):
    with pytest.raises(InputError, match="reserves this name"):
        evaluate_nuscenes_detection(export, _write(tmp_path, gt), eval_set="val")
    with pytest.raises(InputError, match=r"no split 'nope'.*\['all', 'train'\]"):
        evaluate_nuscenes_detection(export, _write(tmp_path, gt), eval_set="nope")


def test_cli_task_nuscenes_detection(export, gt, tmp_path, capsys):
    from pipeline.stages.cli import main

    results = _write(tmp_path, gt)
    out = tmp_path / "eval"
    assert main(["evaluate", "--task", "nuscenes-detection", "--gt", str(export), "--detections", str(results),
                 "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["mean_ap"] == pytest.approx(1.0) and metrics["nd_score"] == pytest.approx(1.0)
    assert metrics["eval_set"] == "all" and metrics["classes"] == ["car", "truck"]
    assert json.loads((out / "meta.json").read_text())["config"]["task"] == "nuscenes-detection"
    bad = copy.deepcopy(gt)
    bad["results"][sorted(bad["results"])[0]][0]["rotation"] = [0, 0, 0, 0]
    assert main(["evaluate", "--task", "nuscenes-detection", "--gt", str(export), "--detections",
                 str(_write(tmp_path, bad)), "--out", str(tmp_path / "eval2")]) == 2
    assert "field 'rotation' is [0, 0, 0, 0]" in capsys.readouterr().err
    assert not (tmp_path / "eval2").exists()


def test_cli_refuses_options_of_other_tasks(export, gt, tmp_path, capsys):
    from pipeline.stages.cli import main

    results = str(_write(tmp_path, gt))
    assert main(["evaluate", "--task", "nuscenes-detection", "--gt", str(export), "--detections", results,
                 "--out", str(tmp_path / "a"), "--iou", "0.7"]) == 2
    assert "--iou apply to --task detection only, not nuscenes-detection" in capsys.readouterr().err
    assert main(["evaluate", "--gt", str(export), "--detections", results, "--out", str(tmp_path / "b"),
                 "--eval-set", "train"]) == 2
    assert "--eval-set applies to --task nuscenes-detection only, not detection" in capsys.readouterr().err


_VALUES = [None, True, "x", "", [], [1.0], [1.0, 2.0], [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0], [1e308] * 4,
           [-1.0, 2.0, 3.0], [1e308, 1e308, 1e308], {}, 0, -1, 1.5, 1e308, 2**70, "car", "vehicle.moving"]
_FIELDS = ["sample_token", "translation", "size", "rotation", "velocity", "detection_name", "detection_score",
           "attribute_name"]


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(_FIELDS), value=st.sampled_from(_VALUES), box=st.integers(0, 3))
def test_any_mutated_box_is_scored_or_refused(export, gt, tmp_path, field, value, box):
    sub = copy.deepcopy(gt)
    boxes = sub["results"][sorted(sub["results"])[1]]
    boxes[box % len(boxes)][field] = value
    try:
        metrics = evaluate_nuscenes_detection(export, _write(tmp_path, sub))
    except InputError:
        return
    assert 0 <= metrics["mean_ap"] <= 1 + 1e-9 and 0 <= metrics["nd_score"] <= 1 + 1e-9
