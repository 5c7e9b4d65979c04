"""The whole DVC pipeline on a tiny params file, in a temporary clone: every stage's outputs exist, and a
second ``dvc repro`` does nothing.

The stages run the clone's own code (``PYTHONPATH`` puts the clone before the editable install), as
``make demo`` in a fresh clone does: Python's bytecode and numba's kernel cache are written into the clone's
``pipeline/**/__pycache__/`` while the stages run, inside the stages' dependencies, and must not make DVC
see those dependencies as changed (``.dvcignore``).

Run-level splits need two runs (one trains, one tests), so the tiny experiment has one scenario, two
seeds and two conditions, two frames per run and condition, and a detector trained for a few steps.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests.conftest import REPO

pytestmark = pytest.mark.slow

TINY_PARAMS = {
    "scenarios": ["highway"], "seeds": [1, 2], "conditions": ["morning", "night"], "frames_per_run": 2,
    "rig": "default", "simulate": {"vehicles": 150, "warmup_s": 60, "duration_s": 1},
    "splits": "test=highway:2,train=*", "train": {"config": "tiny", "conditions": "morning", "seed": 0},
}


def _run(args: list[str], cwd: Path) -> str:
    path = f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"
    env = {**os.environ, "DVC_NO_ANALYTICS": "1", "PATH": path, "PYTHONPATH": str(cwd)}
    env.pop("NUMBA_CACHE_DIR", None)  # numba caches beside the modules, as on a user's machine
    proc = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, f"{' '.join(args)} failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    return proc.stdout + proc.stderr


@pytest.fixture(scope="module")
def clone(tmp_path_factory) -> Path:
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("needs git and a git checkout")
    dest = tmp_path_factory.mktemp("pipeline") / "roadsynth"
    _run(["git", "clone", "--quiet", str(REPO), str(dest)], cwd=REPO)
    (dest / "params.yaml").write_text(yaml.safe_dump(TINY_PARAMS, sort_keys=False))
    tiny = yaml.safe_load((dest / "configs" / "detector" / "default.yaml").read_text())
    tiny["name"] = "tiny"
    tiny["train"].update(steps=3, batch_size=2, warmup_steps=1)
    (dest / "configs" / "detector" / "tiny.yaml").write_text(yaml.safe_dump(tiny, sort_keys=False))
    _run(["git", "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qam", "tiny params"], cwd=dest)
    _run([str(Path(sys.executable).parent / "dvc"), "repro"], cwd=dest)
    return dest


def test_every_stage_wrote_its_outputs(clone):
    for path in ["data/sim/highway-1/trajectories.parquet", "data/sim/highway-2/stats.json",
                 "data/records/highway-1-morning/record.json", "data/records/highway-2-night/labels.parquet",
                 "previews/highway-1-night.png", "data/exports/coco/annotations_train.json",
                 "data/exports/coco/annotations_test.json", "data/exports/kitti/training/label_2",
                 "data/exports/mcap/runs.mcap", "data/exports/mcap/runs.layout.json",
                 "data/models/baseline/model.pt", "data/models/baseline/loss.csv",
                 "data/detections/test.json", "data/eval/metrics.json", "reports/report.md",
                 "reports/examples.png", "reports/metrics.json", "metrics/simulate/highway-2.json"]:
        assert (clone / path).exists(), path


def test_the_stages_ran_the_clones_code_and_cached_kernels_beside_it(clone):
    """What the next test relies on: the stages' own caches were written inside their dependencies."""
    cached = [p.relative_to(clone).as_posix() for p in (clone / "pipeline").rglob("__pycache__/*.nbi")]
    assert any(p.startswith("pipeline/core/") for p in cached), cached
    assert any(p.startswith("pipeline/sensors/") for p in cached), cached


def test_dvc_status_is_clean_after_repro(clone):
    out = _run([str(Path(sys.executable).parent / "dvc"), "status"], cwd=clone)
    assert "Data and pipelines are up to date" in out, out


def test_a_second_repro_does_nothing(clone):
    out = _run([str(Path(sys.executable).parent / "dvc"), "repro"], cwd=clone)
    assert "Running stage" not in out
    assert "Data and pipelines are up to date" in out
