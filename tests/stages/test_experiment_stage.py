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
    # a file of the user's in the experiment folder, or beside its records: the rerun refuses, and keeps it
    for mine in (out / "NOTES.md", out / "records" / "plot.png"):
        mine.write_text("mine")
        assert main(argv) == 2
        assert mine.read_text() == "mine"
        mine.unlink()
    assert main(argv) == 0


@pytest.mark.parametrize(("flags", "message"), [
    (["--export", "coco,pdf"], "--export: unknown format pdf"),
    (["--task-cpus", "2"], "--ray-address, --task-cpus and --ray-timeout apply to --executor ray only"),
])
def test_bad_flags_are_refused_before_anything_is_written(tiny, tmp_path, capsys, flags, message):
    out = tmp_path / "exp"
    assert main(["experiment", "run", str(tiny), "--out", str(out), *flags]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def renamed(source: Path, target: Path, name: str) -> Path:
    """A copy of the config ``source`` whose ``name:`` is ``name``."""
    data = yaml.safe_load(source.read_text())
    data["name"] = name
    target.write_text(yaml.safe_dump(data))
    return target


def experiment(path: Path, scenarios: list, conditions: list, seeds: list[int]) -> Path:
    path.write_text(yaml.safe_dump({"name": "dup", "scenarios": [str(s) for s in scenarios], "seeds": seeds,
                                    "conditions": [str(c) for c in conditions], "vehicles": 40, "warmup_s": 20,
                                    "duration_s": 1, "frames": 2}))
    return path


CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_two_scenario_files_of_one_name_are_refused_naming_both(tmp_path, capsys):
    a = renamed(CONFIGS / "scenarios" / "highway.yaml", tmp_path / "a.yaml", "road")
    b = renamed(CONFIGS / "scenarios" / "urban.yaml", tmp_path / "b.yaml", "road")
    config = experiment(tmp_path / "exp.yaml", [a, b], ["noon"], [1])
    out = tmp_path / "exp"
    assert main(["experiment", "run", str(config), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert (f"{config}: scenarios[0] ({a}) and scenarios[1] ({b}) both have name: road; the runs "
            "(sim/NAME-SEED, records/NAME-SEED-CONDITION) are named after it") in err
    assert "give each scenario file its own name" in err and not out.exists()


def test_a_scenario_or_condition_listed_twice_is_refused(tmp_path, capsys):
    config = experiment(tmp_path / "exp.yaml", ["highway", "highway"], ["noon"], [1])
    assert main(["experiment", "run", str(config), "--out", str(tmp_path / "exp")]) == 2
    err = capsys.readouterr().err
    assert f"{config}: scenarios[0] and scenarios[1] are both " in err and "highway.yaml (name: highway)" in err
    night = renamed(CONFIGS / "conditions" / "night.yaml", tmp_path / "dark.yaml", "noon")
    config = experiment(tmp_path / "exp2.yaml", ["highway"], ["noon", "night", night], [1])
    assert main(["experiment", "run", str(config), "--out", str(tmp_path / "exp")]) == 2
    err = capsys.readouterr().err
    assert "conditions[0] (" in err and f"noon.yaml) and conditions[2] ({night}) both have name: noon" in err
    assert not (tmp_path / "exp").exists()


def test_names_that_join_into_one_record_folder_are_refused(tmp_path, capsys):
    hw = renamed(CONFIGS / "scenarios" / "highway.yaml", tmp_path / "hw.yaml", "hw")
    hw1 = renamed(CONFIGS / "scenarios" / "highway.yaml", tmp_path / "hw1.yaml", "hw-1")
    late = renamed(CONFIGS / "conditions" / "noon.yaml", tmp_path / "late.yaml", "2-noon")
    config = experiment(tmp_path / "exp.yaml", [hw, hw1], [late, "noon"], [1, 2])
    assert main(["experiment", "run", str(config), "--out", str(tmp_path / "exp")]) == 2
    err = capsys.readouterr().err
    assert (f"scenario hw ({hw}) seed 1 condition 2-noon ({late}) and scenario hw-1 ({hw1}) seed 2 condition noon "
            in err and "would both write records/hw-1-2-noon" in err)
    assert not (tmp_path / "exp").exists()


def test_a_merge_that_fails_leaves_status_json_incomplete_with_its_error(tiny, tmp_path):
    from pipeline.core.config import ExperimentConfig, load_config
    from pipeline.stages.experiment import _merge
    from pipeline.stages.matrix import resolve_matrix

    matrix = resolve_matrix(load_config(ExperimentConfig, tiny, "experiments")[0], source=tiny)
    out = tmp_path / "exp"
    out.mkdir()  # tasks said done, but no record is there: the export fails
    with pytest.raises(ValueError, match=r"highway-4-noon: dataset record not found"):
        _merge(matrix, out, {"render": {"status": "done"}}, ["coco"], None, False, complete=True)
    status = json.loads((out / "status.json").read_text())
    assert status["complete"] is False and status["merge"]["status"] == "failed"
    assert status["merge"]["format"] == "coco"
    assert "highway-4-noon: dataset record not found" in status["merge"]["error"]
    assert not (out / "coco").exists()
