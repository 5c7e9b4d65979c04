"""MetaActions: discrete keep / faster / slower / lane left / lane right over the real env."""

from __future__ import annotations

import gymnasium as gym
import pytest

from pipeline.envs import MetaAction, MetaActions

pytestmark = pytest.mark.slow


def test_lane_left_settles_in_the_next_lane_and_slower_lowers_the_speed():
    env = MetaActions(gym.make("roadsynth/Highway-v0", vehicles=80, warmup_s=30.0, time_limit_s=20.0))
    try:
        obs, _ = env.reset(seed=1)
        assert env.action_space == gym.spaces.Discrete(5)
        speed, lane = float(obs["ego"][0]), int(obs["ego"][2])
        for action in [MetaAction.LANE_LEFT] + [MetaAction.KEEP] * 40:
            obs, _, terminated, truncated, _ = env.step(action)
            assert not (terminated or truncated)
        assert int(obs["ego"][2]) == lane + 1
        assert abs(obs["ego"][3]) < 0.1  # centred in the new lane
        assert obs["ego"][0] == pytest.approx(speed, abs=0.01)  # KEEP held the speed
        for action in [MetaAction.SLOWER] + [MetaAction.KEEP] * 60:
            obs, _, terminated, truncated, _ = env.step(action)
            assert not (terminated or truncated)
        assert obs["ego"][0] == pytest.approx(speed - 5.0, abs=0.2)
    finally:
        env.close()
