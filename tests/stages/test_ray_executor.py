"""The Ray executor on a local Ray of 2 CPUs: the same bytes as the local executor, for one render's shards and for
an experiment's matrix; a shard that raises is named while the others finish; reruns skip what is finished.

Skipped without Ray (``pip install 'roadsynth[ray]'``; ``make setup-dev`` installs it)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
import yaml

from pipeline.core.config import ExperimentConfig, load_config
from pipeline.stages.executor import ExecutorSpec, TaskFailures
from pipeline.stages.render import render
from tests.conftest import tree_hashes
from tests.stages.conftest import RAY_FRAMES as FRAMES
from tests.stages.test_executor import check_contract

ray = pytest.importorskip("ray")

pytestmark = pytest.mark.slow
RAY = ExecutorSpec("ray", task_cpus=1)


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    """One local Ray instance of 2 CPUs for the module (the executor uses an initialised Ray as it is)."""
    if ray.is_initialized():
        ray.shutdown()
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_shards_on_ray_give_the_local_executors_bytes(small_highway_run, small_rig, noon_condition, four_frame_record,
                                                      tmp_path):
    out = tmp_path / "highway-7-noon"
    summary = render(small_highway_run, noon_condition, small_rig, out, frames=FRAMES, workers=2, shard_size=1,
                     progress=False, executor=RAY)
    assert summary["frames"] == FRAMES and summary["shards_resumed"] == 0
    assert tree_hashes(out, skip=("meta.json",)) == tree_hashes(four_frame_record, skip=("meta.json",))
    assert not (tmp_path / ".highway-7-noon.partial").exists()


def test_ray_keeps_the_executor_contract():
    check_contract(RAY)


def _with_unknown_class(sim: Path, into: Path, frame: int) -> Path:
    """A copy of the run ``sim`` whose other actors at ``frame`` have a class no renderer knows."""
    shutil.copytree(sim, into)
    table = pd.read_parquet(into / "trajectories.parquet")
    table.loc[(table["frame"] == frame) & ~table["is_ego"], "cls"] = "spaceship"
    table.to_parquet(into / "trajectories.parquet")
    return into


def test_a_failing_shard_is_named_while_the_others_finish(small_highway_run, small_rig, noon_condition,
                                                          four_frame_record, tmp_path):
    frames = json.loads((four_frame_record / "meta.json").read_text())["config"]["frames"]
    bad_frame = frames[2]
    sim = _with_unknown_class(small_highway_run, tmp_path / "highway-7", bad_frame)
    out = tmp_path / "bad-noon"
    with pytest.raises(TaskFailures) as failed:
        render(sim, noon_condition, small_rig, out, frames=FRAMES, workers=2, shard_size=1, progress=False,
               executor=RAY)
    assert list(failed.value.failures) == [f"run highway-7 (seed 7) condition noon shard 2 frames [{bad_frame}]"]
    assert "1 of 4 shards failed" in str(failed.value) and "spaceship" in str(failed.value)
    assert not out.exists()  # no record from three shards of four
    shards = tmp_path / ".bad-noon.partial" / "shards"
    assert sorted(p.name for p in shards.glob("done-*")) == ["done-00000", "done-00001", "done-00003"]
    # The finished shards are the local executor's: their images are byte-identical.
    partial = tmp_path / ".bad-noon.partial" / "record"
    for frame in (frames[0], frames[1], frames[3]):
        name = f"cameras/front/rgb/{frame:06d}.png"
        assert (partial / name).read_bytes() == (four_frame_record / name).read_bytes()


def _tiny_experiment(path: Path, rig: Path) -> ExperimentConfig:
    path.write_text(yaml.safe_dump({"name": "tiny", "scenarios": ["highway"], "seeds": [1, 2],
                                    "conditions": ["noon", "night"], "rig": str(rig), "vehicles": 40,
                                    "warmup_s": 20, "duration_s": 1, "frames": 2}))
    return load_config(ExperimentConfig, path, "experiments")[0]


def test_the_matrix_on_ray_gives_the_local_bytes_and_a_rerun_skips_it(small_rig, tmp_path):
    from pipeline.stages.experiment import run_experiment
    from pipeline.stages.matrix import resolve_matrix

    rig = tmp_path / "small.yaml"
    rig.write_text(yaml.safe_dump(small_rig.model_dump(mode="json")))
    matrix = resolve_matrix(_tiny_experiment(tmp_path / "tiny.yaml", rig))
    here, there = tmp_path / "local", tmp_path / "ray"
    run_experiment(matrix, here, ExecutorSpec("local"), workers=1, formats=["coco"], progress=False)
    status = run_experiment(matrix, there, RAY, workers=1, formats=["coco"], progress=False)
    assert [s["status"] for s in status.values()] == ["done"] * 6
    # Everything but the meta.json files (the command line, and the export's, its input paths) is the same.
    assert tree_hashes(there, skip=("meta.json",)) == tree_hashes(here, skip=("meta.json",))
    assert len(list((there / "records").iterdir())) == 4 and (there / "coco" / "annotations.json").is_file()
    again = run_experiment(matrix, there, RAY, workers=1, formats=["coco"], progress=False)
    assert [s["status"] for s in again.values()] == ["skipped"] * 6
    # The merge ran again: the same export; status.json now says "skipped".
    rewritten = ("meta.json", "status.json")
    assert tree_hashes(there, skip=rewritten) == tree_hashes(here, skip=rewritten)
