"""The environment fails clearly and leaks nothing (issue 38): bad options are refused up front naming them, a
record folder that cannot be written is refused at construction (not at close(), losing the episode), the
temporary folder goes on every exit path, and an env used after close() says so."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import pipeline.envs  # noqa: F401  (registers the envs)

SMALL = {"vehicles": 20, "warmup_s": 5.0, "time_limit_s": 1.0}


@pytest.mark.parametrize(("kwargs", "named"), [
    ({"dt": 0}, "dt"), ({"dt": float("nan")}, "dt"), ({"dt": -0.1}, "dt"), ({"dt": 5.0}, "dt"), ({"dt": "0.1"}, "dt"),
    ({"time_limit_s": float("nan")}, "time_limit_s"), ({"time_limit_s": float("inf")}, "time_limit_s"),
    ({"max_speed_mps": -1.0}, "max_speed_mps"), ({"nearby_k": 1.5}, "nearby_k"),
    ({"normalize_actions": "yes"}, "normalize_actions")])
def test_bad_options_are_refused_naming_them(kwargs, named):
    with pytest.raises(ValueError, match=named):
        gym.make("roadsynth/Highway-v0", **SMALL | kwargs)


def test_a_record_folder_that_cannot_be_written_is_refused_at_construction(tmp_path):
    a_file = tmp_path / "episodes"
    a_file.write_text("not a folder")
    with pytest.raises(ValueError, match=r"record=.*episodes: is a file"):
        gym.make("roadsynth/Highway-v0", **SMALL, record=a_file)
    unwritable = Path("/proc/self/roadsynth-episodes")  # no one, root included, creates files under /proc
    with pytest.raises(ValueError, match="record=/proc/self/roadsynth-episodes: cannot write episodes there"):
        gym.make("roadsynth/Highway-v0", **SMALL, record=unwritable)


def _env_folders(tmp: Path) -> list[str]:
    return sorted(p.name for p in tmp.iterdir() if p.name.startswith("roadsynth-env-"))


def test_an_env_dropped_without_close_removes_its_folder(tmp_path, monkeypatch):
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    env = gym.make("roadsynth/Highway-v0", **SMALL)
    env.reset(seed=1)
    assert len(_env_folders(tmp_path)) == 1
    del env
    gc.collect()
    assert _env_folders(tmp_path) == []


def test_a_script_that_exits_without_close_leaves_no_folder(tmp_path):
    script = ("import gymnasium as gym, pipeline.envs\n"
              "env = gym.make('roadsynth/Highway-v0', vehicles=20, warmup_s=5.0, time_limit_s=1.0)\n"
              "env.reset(seed=1)\nenv.step(env.action_space.sample())\n")
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    assert _env_folders(tmp_path) == []


def test_an_env_used_after_close_says_so():
    env = gym.make("roadsynth/Highway-v0", **SMALL)
    env.reset(seed=1)
    env.close()
    inner = env.unwrapped
    for call in (lambda: inner.reset(seed=1), lambda: inner.step(inner.action_space.sample())):
        with pytest.raises(RuntimeError, match=r"after close\(\)"):
            call()
    env.close()  # closing twice is harmless
