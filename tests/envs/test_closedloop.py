"""``roadsynth closedloop`` end to end on a tiny config: a real highway, the reference agent, a constant ONNX
detector the test builds (one car box in every frame), a small rig."""

from __future__ import annotations

import json

import gymnasium as gym
import pytest
import yaml

import pipeline.envs  # noqa: F401  (registers the envs)
from pipeline.core.config.closedloop import ClosedLoopConfig
from pipeline.envs.closedloop import _report
from pipeline.envs.driver import ReferenceAgent
from pipeline.stages.cli import main as cli_main
from tests.detect.test_onnx_heads import constant_model, yolox_output
from tests.envs.test_perception import SMALL_RIG

pytestmark = pytest.mark.slow
TINY = {"name": "tiny", "scenarios": ["highway"], "seeds": [1, 2], "conditions": ["morning"], "episode_s": 1.5,
        "vehicles": 60, "warmup_s": 20.0, "rig": "small.yaml", "detector": "onnx:car.onnx"}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("closedloop")
    (root / "small.yaml").write_text(SMALL_RIG)
    constant_model(root / "car.onnx", yolox_output())
    config = root / "tiny.yaml"
    config.write_text(yaml.safe_dump({**TINY, "rig": str(root / "small.yaml")}))
    out = root / "out"
    assert cli_main(["closedloop", str(config), "--out", str(out), "--record", "--no-progress"]) == 0
    return root, out


def test_it_writes_every_episode_the_comparisons_a_report_and_plots(run):
    _, out = run
    metrics = json.loads((out / "metrics.json").read_text())
    assert sorted((e["seed"], e["mode"]) for e in metrics["episodes"]) == [
        (1, "ground_truth"), (1, "perceived"), (2, "ground_truth"), (2, "perceived")]
    assert all(e["steps"] == 15 and e["end"] == "time_limit" and e["collision"] is None for e in metrics["episodes"])
    assert sorted(metrics["comparisons"]) == ["highway/morning", "morning"]
    assert [c["metric"] for c in metrics["comparisons"]["morning"]] == metrics["metric_names"]
    speed = next(c for c in metrics["comparisons"]["morning"] if c["metric"] == "mean_speed_mps")
    assert speed["seeds"] == 2 and speed["ground_truth"] > 0
    report = (out / "report.md").read_text()
    assert "| mean_speed_mps |" in report and "plots/morning.png" in report
    assert (out / "plots" / "morning.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "plots" / "leader_by_range.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "plots/leader_by_range.png" in report
    assert "Collisions" not in report
    assert json.loads((out / "meta.json").read_text())["stage"] == "closedloop"


def test_the_ground_truth_run_is_the_agents_episode_in_the_plain_env(run, tmp_path):
    """The same agent in the environment without perception, same seed: the same trajectories, byte for byte."""
    _, out = run
    env = gym.make("roadsynth/Scenario-v0", scenario="highway", vehicles=60, warmup_s=20.0, time_limit_s=1.5,
                   record=tmp_path / "plain")
    try:
        obs, _ = env.reset(seed=1)
        agent = ReferenceAgent(env)
        agent.reset(obs)
        while True:
            obs, _, terminated, truncated, _ = env.step(agent.act(obs))
            if terminated or truncated:
                break
    finally:
        env.close()
    recorded = out / "episodes" / "highway-1-morning-ground_truth" / "episode-0000" / "trajectories.parquet"
    plain = tmp_path / "plain" / "episode-0000" / "trajectories.parquet"
    assert recorded.read_bytes() == plain.read_bytes()


def test_the_perceived_run_saw_what_the_detector_reported(run):
    _, out = run
    perceived = out / "episodes" / "highway-1-morning-perceived" / "episode-0000" / "trajectories.parquet"
    assert perceived.exists()


def test_a_missing_detector_is_named_with_the_config_file(tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({**TINY, "detector": "onnx:nowhere.onnx"}))
    assert cli_main(["closedloop", str(config), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert str(config) in err and "detector" in err and "nowhere.onnx" in err
    assert not (tmp_path / "o").exists()


def test_a_bad_config_value_is_refused(tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({**TINY, "detector": "yolo:x"}))
    assert cli_main(["closedloop", str(config), "--out", str(tmp_path / "o")]) == 2
    assert "onnx:PATH" in capsys.readouterr().err
    config.write_text(yaml.safe_dump({**TINY, "agent": "ppo"}))
    assert cli_main(["closedloop", str(config), "--out", str(tmp_path / "o")]) == 2


def test_an_interrupted_run_resumes_with_the_episodes_it_kept(run, monkeypatch):
    """One episode fails: nothing is written to --out, the others are kept in OUT.partial/; the rerun runs only the
    missing one and writes what an uninterrupted run writes. A changed setting discards what was kept."""
    import pipeline.envs.closedloop as closedloop

    root, out = run
    resumed = root / "resumed"
    config = root / "tiny.yaml"
    real, ran = closedloop.episode_row, []

    def failing(*args):
        if args[-2:] == ("perceived", None) and args[3] == 2:  # seed 2's perceived episode
            raise RuntimeError("interrupted")
        ran.append(args[3:6])
        return real(*args)

    monkeypatch.setattr(closedloop, "episode_row", failing)
    assert cli_main(["closedloop", str(config), "--out", str(resumed), "--no-progress"]) != 0
    assert not resumed.exists() and len(ran) == 3
    kept = sorted(p.name for p in (root / "resumed.partial" / "rows").iterdir())
    assert kept == [f"highway-{n}-morning-{m}.json" for n, m in
                    [(1, "ground_truth"), (1, "perceived"), (2, "ground_truth")]]

    ran.clear()
    monkeypatch.setattr(closedloop, "episode_row", lambda *args: ran.append(args[3:6]) or real(*args))
    assert cli_main(["closedloop", str(config), "--out", str(resumed), "--no-progress"]) == 0
    assert ran == [(2, "morning", "perceived")] and not (root / "resumed.partial").exists()
    local, again = (json.loads((d / "metrics.json").read_text()) for d in (out, resumed))
    assert again["episodes"] == local["episodes"] and again["comparisons"] == local["comparisons"]

    # kept rows of other settings are not reused
    partial = root / "changed.partial"
    (partial / "rows").mkdir(parents=True)
    (partial / "fingerprint.txt").write_text("another config\n")
    (partial / "rows" / "highway-1-morning-perceived.json").write_text("{}")
    ran.clear()
    assert cli_main(["closedloop", str(config), "--out", str(root / "changed"), "--no-progress"]) == 0
    assert len(ran) == 4 and not partial.exists()


def test_on_ray_the_episodes_give_the_local_runs_metrics(run):
    # Each episode in a fresh Ray worker process: the same rows, in the config's order, as one after the other here.
    ray = pytest.importorskip("ray")
    root, out = run
    if ray.is_initialized():
        ray.shutdown()
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        on_ray = root / "on-ray"
        assert cli_main(["closedloop", str(root / "tiny.yaml"), "--out", str(on_ray), "--executor", "ray",
                         "--no-progress"]) == 0
    finally:
        ray.shutdown()
    local, remote = (json.loads((d / "metrics.json").read_text()) for d in (out, on_ray))
    assert remote["episodes"] == local["episodes"] and remote["comparisons"] == local["comparisons"]


def test_the_report_lists_what_each_collision_hit():
    config = ClosedLoopConfig(**{**TINY, "conditions": ["night"]})
    hit = {"other": "ped0067", "other_kind": "person", "other_type": "DEFAULT_PEDTYPE", "other_speed_mps": 0.0,
           "ego_speed_mps": 7.61, "ego_is_collider": True, "type": "crossing", "lane": ":E1_18_0", "pos_m": 2.3,
           "time_s": 7.4}
    rows = [{"scenario": "urban", "seed": 3, "condition": "night", "mode": "perceived", "end": "collision",
             "collision": hit},
            {"scenario": "urban", "seed": 3, "condition": "night", "mode": "ground_truth", "end": "time_limit",
             "collision": None}]
    report = _report(config, rows, {})
    assert "Episode ends: ground_truth time_limit: 1, perceived collision: 1" in report
    assert ("| urban | night | 3 | perceived | 7.4 | person ped0067 | DEFAULT_PEDTYPE | 7.6 | 0.0 | crossing | "
            ":E1_18_0 |") in report
    assert report.count("| urban | night | 3 |") == 1
