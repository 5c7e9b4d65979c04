"""Reward terms and options: closed-form cases."""

from __future__ import annotations

import pytest

from pipeline.envs.env import _options
from pipeline.envs.options import EnvOptions, RewardWeights
from pipeline.envs.reward import reward_terms

W = RewardWeights(progress=1.0, comfort=0.5, lane_keeping=0.25, collision=10.0, off_road=7.0, jerk_ref_mps3=10.0)
BASE = {"target_speed_mps": 20.0, "dt_s": 0.1, "jerk_mps3": 0.0, "lateral_offset_m": 0.0, "half_lane_width_m": 1.75,
        "collided": False, "off_road": False}


def terms(**kwargs) -> dict[str, float]:
    return reward_terms(W, **{**BASE, "progress_m": 1.0, **kwargs})


def test_progress_is_route_distance_over_target_distance_capped_at_one():
    assert terms(progress_m=1.0)["progress"] == pytest.approx(0.5)  # 1 m of the 2 m a 20 m/s target covers in 0.1 s
    assert terms(progress_m=5.0)["progress"] == 1.0  # faster than the target earns no more
    assert terms(progress_m=0.0)["progress"] == 0.0
    assert terms(progress_m=-3.0)["progress"] == 0.0  # losing route distance (turning back) is never rewarded


def test_comfort_and_lane_keeping_are_squared_and_saturate():
    assert terms(jerk_mps3=5.0)["comfort"] == pytest.approx(-0.5 * 0.25)
    assert terms(jerk_mps3=-50.0)["comfort"] == pytest.approx(-0.5)
    assert terms(lateral_offset_m=0.875)["lane_keeping"] == pytest.approx(-0.25 * 0.25)
    assert terms(lateral_offset_m=-9.0)["lane_keeping"] == pytest.approx(-0.25)


def test_collision_and_off_road_cost_their_weights():
    assert terms(collided=True)["collision"] == -10.0
    assert terms(off_road=True)["off_road"] == -7.0
    assert terms()["collision"] == 0.0 and terms()["off_road"] == 0.0


def test_options_are_checked_and_keywords_reach_them():
    with pytest.raises(ValueError, match="accel_min_mps2 < 0 < accel_max_mps2"):
        EnvOptions(accel_min_mps2=1.0)
    with pytest.raises(ValueError, match="reward weight comfort"):
        RewardWeights(comfort=-1.0)
    with pytest.raises(TypeError, match="unknown option.*speed_limit"):
        _options(None, {"speed_limit": 3.0})
    options = _options(None, {"accel_max_mps2": 2.0, "reward": {"collision": 3.0}})
    assert options.accel_max_mps2 == 2.0 and options.reward.collision == 3.0


def test_scenario_env_takes_a_yaml_path_and_needs_a_scenario(tmp_path):
    import gymnasium as gym

    import pipeline.envs  # noqa: F401  (registers the envs)
    from pipeline.core.config import config_dir

    path = tmp_path / "mine.yaml"
    path.write_text((config_dir() / "scenarios" / "urban.yaml").read_text().replace("name: urban", "name: mine"))
    env = gym.make("roadsynth/Scenario-v0", scenario=str(path), vehicles=10)
    assert env.unwrapped.config.name == "mine" and env.unwrapped.config.demand.vehicles == 10
    env.close()
    with pytest.raises(TypeError, match="needs scenario"):
        gym.make("roadsynth/Scenario-v0")
