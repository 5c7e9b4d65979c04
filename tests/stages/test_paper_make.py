"""``make paper ONNX=...`` on a tiny version of the paper's experiment (2 seeds x 2 conditions x 2 frames of a
small camera): every stage runs, the report puts both detectors beside the paper's Table 1, and a second
make does nothing."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO
from tests.detect.conftest import TINY_CONFIG

pytestmark = [pytest.mark.slow, pytest.mark.skipif(shutil.which("make") is None, reason="no make")]


def _onnx_model(root: Path) -> Path:
    """The real YOLOX-nano where present, else a YOLOX-shaped head with one constant box."""
    real = REPO.parent / "shared" / "models" / "yolox_nano.onnx"
    if real.is_file():
        return real
    from tests.detect.test_onnx_heads import constant_model, yolox_output

    path = root / "head.onnx"
    constant_model(path, yolox_output())
    return path


def test_make_paper_tiny(tmp_path):
    experiment = yaml.safe_load((REPO / "configs" / "experiments" / "paper_table1.yaml").read_text())
    experiment.update(scenarios=["highway"], seeds=[1, 2], vehicles=40, warmup_s=20, duration_s=2)
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(experiment))
    rig = yaml.safe_load((REPO / "configs" / "rigs" / "default.yaml").read_text())
    rig["name"] = "small"
    rig["cameras"][0].update(width_px=320, height_px=240)
    rig["lidars"][0].update(channels=16, horizontal_resolution_deg=1.0)
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig))
    (tmp_path / "det.yaml").write_text(yaml.safe_dump(TINY_CONFIG))
    onnx = _onnx_model(tmp_path)
    out = tmp_path / "out"
    cmd = ["make", "--no-print-directory", "paper-outputs", f"BIN={Path(sys.executable).parent}",
           f"PAPER={tmp_path / 'tiny.yaml'}", f"PAPER_OUT={out}", f"ONNX={onnx}", "PAPER_FRAMES=2",
           f"PAPER_RIG={tmp_path / 'rig.yaml'}", f"PAPER_TRAIN_CONFIG={tmp_path / 'det.yaml'}"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    run = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    name = onnx.stem
    assert sorted(p.name for p in (out / "records").iterdir()) == [
        "highway-1-morning", "highway-1-night", "highway-2-morning", "highway-2-night"]
    gt = json.loads((out / "coco" / "annotations_test.json").read_text())
    assert {img["seed"] for img in gt["images"]} == {2} and len(gt["images"]) == 4  # last seed tests
    test_ids = {img["id"] for img in gt["images"]}
    for detector in ("baseline", name):
        results = json.loads((out / "detections" / f"{detector}.json").read_text())
        assert {r["image_id"] for r in results} <= test_ids
        assert (out / "eval" / detector / "metrics.json").is_file()
    text = (out / "report" / "report.md").read_text()
    assert "| morning | paper (Li et al., Table 1) | 0.82 | 0.81 | 0.79 | 0.47 | 0.41 | 0.40 | 0.40 | 0.28 |" in text
    assert "| night | baseline |" in text and f"| night | {name} |" in text
    if any(not a["iscrowd"] for a in gt["annotations"]):
        assert "| height_px:" in text  # recall by box height
    assert set(json.loads((out / "report" / "metrics.json").read_text())) == {"baseline", name}
    again = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, check=True)
    assert "roadsynth" not in again.stdout  # everything up to date: no stage reruns


def test_make_paper_needs_the_onnx_model():
    run = subprocess.run(["make", "paper-outputs", f"BIN={Path(sys.executable).parent}"], cwd=REPO,
                         capture_output=True, text=True)
    assert run.returncode != 0 and "make paper ONNX=path/to/detector.onnx" in run.stderr
