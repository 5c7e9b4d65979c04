"""``make realism ONNX=...`` on a tiny matrix (one highway seed, morning and fog, 2 frames of a small camera) with the
real COCO-pretrained YOLOX-nano: every stage runs, the report has its tables, contact sheets and plot, and a second
make does nothing. Skipped where the model is absent (the project does not ship it)."""

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

MODEL = REPO.parent / "shared" / "models" / "yolox_nano.onnx"
pytestmark = [pytest.mark.slow, pytest.mark.skipif(shutil.which("make") is None, reason="no make")]


@pytest.mark.skipif(not MODEL.is_file(), reason=f"{MODEL}: the COCO-pretrained detector is absent")
def test_make_realism_tiny(tmp_path):
    experiment = yaml.safe_load((REPO / "configs" / "experiments" / "realism.yaml").read_text())
    assert not set(experiment["seeds"]) & {1, 2, 3, 4}  # held out from the seeds the renderer was tuned on
    assert experiment["score_threshold"] == 0.3 and len(experiment["conditions"]) == 6
    experiment.update(scenarios=["highway"], vehicles=40, warmup_s=20, duration_s=2)
    (tmp_path / "tiny.yaml").write_text(yaml.safe_dump(experiment))
    rig = yaml.safe_load((REPO / "configs" / "rigs" / "default.yaml").read_text())
    rig["name"] = "small"
    rig["cameras"][0].update(width_px=320, height_px=240)
    rig["lidars"][0].update(channels=16, horizontal_resolution_deg=1.0)
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig))
    out = tmp_path / "out"
    cmd = ["make", "--no-print-directory", "realism-outputs", f"BIN={Path(sys.executable).parent}",
           f"REALISM={tmp_path / 'tiny.yaml'}", f"REALISM_OUT={out}", f"ONNX={MODEL}", "REALISM_FRAMES=2",
           f"REALISM_SEEDS={experiment['seeds'][0]}", "REALISM_CONDITIONS=morning fog",
           f"REALISM_RIG={tmp_path / 'rig.yaml'}"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    run = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    seed = experiment["seeds"][0]
    assert sorted(p.name for p in (out / "records").iterdir()) == [f"highway-{seed}-fog", f"highway-{seed}-morning"]
    report = out / "report" / MODEL.stem
    metrics = json.loads((report / "metrics.json").read_text())
    assert metrics["score_threshold"] == 0.3 and metrics["distance"]["visibility_m"] == {"fog": 80.0}
    assert list(dict.fromkeys(r["group"] for r in metrics["rows"])) == ["all", "morning", "fog"]  # the matrix order
    assert {r["class_group"] for r in metrics["rows"]} == {"vehicles", "people", "two-wheelers"}
    assert metrics["luma"]["morning"]["images"] == 2 and metrics["luma"]["fog"]["mean"] > 0
    text = (report / "realism.md").read_text()
    assert "| morning |" in text and "| fog |" in text and "T fog (V 80 m)" in text
    assert (report / "recall_by_distance.png").is_file()
    for group, missed in metrics["missed_objects"].items():
        assert (report / f"missed_{group.replace('-', '_')}.png").is_file() == (missed["missed"] > 0)
    meta = json.loads((report / "meta.json").read_text())
    assert meta["config"]["task"] == "realism"
    again = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, check=True)
    assert "roadsynth" not in again.stdout  # everything up to date: no stage reruns


def test_make_realism_needs_the_onnx_model():
    run = subprocess.run(["make", "realism-outputs", f"BIN={Path(sys.executable).parent}"], cwd=REPO,
                         capture_output=True, text=True)
    assert run.returncode != 0 and "make realism ONNX=path/to/detector.onnx" in run.stderr
