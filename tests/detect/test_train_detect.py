"""Training lowers the loss, is reproducible on the CPU, and detect writes results evaluation accepts;
the ONNX export gives the torch path's boxes."""

from __future__ import annotations

import csv
import hashlib
import json

import numpy as np
import pytest
import torch

from evaluation.io_coco import read_coco_gt, read_coco_results
from pipeline.core.config import DetectorConfig
from pipeline.detect.data import load_coco
from pipeline.detect.infer import Detector
from pipeline.detect.train import train
from pipeline.stages.cli import main as cli
from tests.detect.conftest import TINY_CONFIG

CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def config() -> DetectorConfig:
    return DetectorConfig.model_validate(TINY_CONFIG)


def test_training_lowers_the_loss(tiny_coco, config):
    data = load_coco(tiny_coco / "annotations.json", config.classes, config.train.conditions)
    history = train(config, data, seed=1, device=CPU, steps=25, progress=False).history
    losses = [row["loss"] for row in history]
    assert np.mean(losses[-5:]) < 0.5 * np.mean(losses[:5])


def test_same_seed_same_weights_and_detections(tiny_coco, config):
    data = load_coco(tiny_coco / "annotations.json", config.classes)
    runs = [train(config, data, seed=seed, device=CPU, steps=4, progress=False).model for seed in (3, 3, 4)]
    a, b, c = (m.state_dict() for m in runs)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a if a[k].is_floating_point())
    rgb = np.full((150, 200, 3), 100, np.uint8)
    d1, d2 = (Detector(m, config, data.category_ids, CPU).predict([rgb])[0] for m in runs[:2])
    assert np.array_equal(d1.boxes, d2.boxes) and np.array_equal(d1.scores, d2.scores)


@pytest.fixture(scope="module")
def trained(tiny_coco, tiny_config_path, tmp_path_factory):
    out = tmp_path_factory.mktemp("train") / "model"
    argv = ["train", "--coco", str(tiny_coco), "--out", str(out), "--config", str(tiny_config_path),
            "--seed", "5", "--export-onnx", "--no-progress"]
    assert cli(argv) == 0
    return out


def test_train_outputs(trained, tiny_coco):
    assert {p.name for p in trained.iterdir()} == {"model.pt", "loss.csv", "train.json", "meta.json", "model.onnx"}
    rows = list(csv.DictReader((trained / "loss.csv").open()))
    assert len(rows) == TINY_CONFIG["train"]["steps"] and list(rows[0]) == ["step", "loss", "heatmap", "size",
                                                                             "offset", "lr"]
    ckpt = torch.load(trained / "model.pt", weights_only=True)
    sha = hashlib.sha256((tiny_coco / "annotations.json").read_bytes()).hexdigest()
    assert ckpt["annotations_sha256"] == sha and ckpt["category_ids"] == [3, 8] and ckpt["seed"] == 5
    meta = json.loads((trained / "meta.json").read_text())
    assert meta["seed"] == 5 and meta["config"]["annotations_sha256"] == sha


@pytest.fixture(scope="module")
def torch_results(trained, tiny_coco, tmp_path_factory):
    out = tmp_path_factory.mktemp("detect") / "results.json"
    assert cli(["detect", "--model", str(trained), "--coco", str(tiny_coco), "--out", str(out), "--no-progress"]) == 0
    return out


def test_results_pass_the_evaluation_validation(torch_results, tiny_coco):
    gt = read_coco_gt(tiny_coco / "annotations.json")
    dets = read_coco_results(torch_results, gt)
    assert len(dets.score) > 0 and dets.score.max() > 0.3
    results = json.loads(torch_results.read_text())
    assert {r["category_id"] for r in results} <= {3, 8}
    assert all(r["score"] >= TINY_CONFIG["infer"]["score_threshold"] for r in results)


def _sorted(results):
    rows = sorted(results, key=lambda r: (r["image_id"], -r["score"], r["bbox"]))
    return (np.array([[r["image_id"], r["category_id"]] for r in rows]), np.array([r["bbox"] for r in rows]),
            np.array([r["score"] for r in rows]))


def test_onnx_gives_the_torch_boxes(trained, tiny_coco, torch_results, tmp_path):
    out = tmp_path / "onnx.json"
    assert cli(["detect", "--onnx", str(trained / "model.onnx"), "--coco", str(tiny_coco), "--out", str(out),
                "--no-progress"]) == 0
    ids_t, boxes_t, scores_t = _sorted(json.loads(torch_results.read_text()))
    ids_o, boxes_o, scores_o = _sorted(json.loads(out.read_text()))
    assert np.array_equal(ids_t, ids_o)
    np.testing.assert_allclose(boxes_o, boxes_t, atol=0.05)
    np.testing.assert_allclose(scores_o, scores_t, atol=1e-4)


def test_missing_model_is_an_error(tiny_coco, tmp_path, capsys):
    (tmp_path / "model").mkdir()  # --out may not go inside the --model folder (an input)
    assert cli(["detect", "--model", str(tmp_path / "model"), "--coco", str(tiny_coco), "--out",
                str(tmp_path / "r.json")]) == 2
    assert "model.pt" in capsys.readouterr().err
