"""Fixtures of the render and preview tests: a run long enough to pick every 10th frame, a small rig (fast to
render) and one record rendered from them."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pipeline.core.config import ConditionConfig, RigConfig, load_config
from tests.conftest import REPO, simulated_highway

EVERY_10TH = 3  # --frames 3 of the 21-frame run: frames 0, 10, 20


def kill_render_after(monkeypatch, shards: int) -> list[tuple[int, ...]]:
    """Make the render stage fail as if killed (KeyboardInterrupt) when it starts shard number ``shards + 1``;
    returns the frames of the shards it rendered, filled as they run. ``monkeypatch.undo()`` restores it."""
    from pipeline.stages import render as render_module

    real, done = render_module.render_shard, []

    def killed(job):
        if len(done) == shards:
            raise KeyboardInterrupt("killed")
        done.append(job.frames)
        return real(job)

    monkeypatch.setattr(render_module, "render_shard", killed)
    return done


@pytest.fixture(scope="session")
def run_21_frames(tmp_path_factory) -> Path:
    """A highway run recording 21 frames at 10 Hz (2.1 s), traffic around the ego."""
    return simulated_highway(tmp_path_factory, 5, vehicles=120, duration_s=2.1, warmup_s=60.0)


@pytest.fixture(scope="session")
def small_rig(tmp_path_factory) -> RigConfig:
    """The default rig with a 160x120 camera and a 32-channel LiDAR at 0.4 deg: the same geometry, fewer rays."""
    data = yaml.safe_load((REPO / "configs" / "rigs" / "default.yaml").read_text())
    data["name"] = "small"
    data["cameras"][0].update(width_px=160, height_px=120)
    data["lidars"][0].update(channels=32, horizontal_resolution_deg=0.4)
    path = tmp_path_factory.mktemp("rig") / "small.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_config(RigConfig, path, "rigs")[0]


@pytest.fixture(scope="session")
def noon_condition() -> ConditionConfig:
    return load_config(ConditionConfig, "noon", "conditions")[0]


@pytest.fixture(scope="session")
def small_record(run_21_frames, small_rig, noon_condition, tmp_path_factory) -> Path:
    """Every 10th frame of ``run_21_frames`` under noon, rendered in one go (shards of 2)."""
    from pipeline.stages.render import render

    out = tmp_path_factory.mktemp("record") / "highway-5-noon"
    render(run_21_frames, noon_condition, small_rig, out, frames=EVERY_10TH, workers=1, shard_size=2,
           progress=False)
    return out


RAY_FRAMES = 4  # of small_highway_run, in shards of 1: four tasks


@pytest.fixture(scope="session")
def four_frame_record(small_highway_run, small_rig, noon_condition, tmp_path_factory) -> Path:
    """RAY_FRAMES frames of ``small_highway_run`` under noon, shards of 1, rendered here: the Ray tests' reference."""
    from pipeline.stages.render import render

    out = tmp_path_factory.mktemp("local") / "highway-7-noon"
    render(small_highway_run, noon_condition, small_rig, out, frames=RAY_FRAMES, workers=1, shard_size=1,
           progress=False)
    return out
