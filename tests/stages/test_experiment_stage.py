"""``roadsynth experiment run`` with the local executor: the matrix from one command, in the layout of the Makefile's
``paper`` target, read back by the records' and COCO's own readers; a rerun skips every finished task; bad flags
are refused before anything is written."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest
import yaml
from pycocotools.coco import COCO

from pipeline.core.record import DatasetRecord
from pipeline.stages.cli import main as cli_main


def main(argv: list[str]) -> int:
    try:
        return cli_main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


@pytest.fixture
def tiny(tmp_path, small_rig) -> Path:
    """One highway run of 40 vehicles, 1 s recorded, two frames under noon and night, the small rig."""
    rig = tmp_path / "small.yaml"
    rig.write_text(yaml.safe_dump(small_rig.model_dump(mode="json")))
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump({"name": "tiny", "scenarios": ["highway"], "seeds": [4],
                                    "conditions": ["noon", "night"], "rig": str(rig), "vehicles": 40,
                                    "warmup_s": 20, "duration_s": 1, "frames": 2}))
    return path


@pytest.mark.slow
def test_the_matrix_runs_from_one_command_and_a_rerun_skips_it(tiny, tmp_path, caplog):
    out = tmp_path / "exp"
    argv = ["experiment", "run", str(tiny), "--out", str(out), "--workers", "1", "--no-progress"]
    assert main(argv) == 0
    assert sorted(p.name for p in (out / "records").iterdir()) == ["highway-4-night", "highway-4-noon"]
    for condition in ("noon", "night"):
        record = DatasetRecord(out / "records" / f"highway-4-{condition}")
        assert record.info.condition == condition and record.info.seed == 4 and len(record.frames) == 2
    coco = COCO(str(out / "coco" / "annotations.json"))
    assert len(coco.getImgIds()) == 4
    status = json.loads((out / "status.json").read_text())
    assert status["complete"] and [t["status"] for t in status["tasks"].values()] == ["done"] * 3
    assert json.loads((out / "meta.json").read_text())["stage"] == "experiment"
    caplog.clear()
    caplog.set_level(logging.INFO, "pipeline.stages.experiment")
    assert main(argv) == 0
    status = json.loads((out / "status.json").read_text())
    assert [t["status"] for t in status["tasks"].values()] == ["skipped"] * 3
    assert "render highway-4 condition night: skipped (finished earlier)" in caplog.text


@pytest.mark.parametrize(("flags", "message"), [
    (["--export", "coco,pdf"], "--export: unknown format pdf"),
    (["--task-cpus", "2"], "--ray-address and --task-cpus apply to --executor ray only"),
])
def test_bad_flags_are_refused_before_anything_is_written(tiny, tmp_path, capsys, flags, message):
    out = tmp_path / "exp"
    assert main(["experiment", "run", str(tiny), "--out", str(out), *flags]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()
