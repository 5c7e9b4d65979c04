"""Smoke test of examples/train_ppo.py's pieces (the optional ``rl`` extra): PPO runs a few hundred steps on the
real highway env with meta-actions. Skipped when stable-baselines3 is not installed; no training quality asserted."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytestmark = pytest.mark.slow

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "train_ppo.py"


def load_example():
    spec = importlib.util.spec_from_file_location("train_ppo_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_ppo_runs_on_the_meta_action_env():
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    example = load_example()
    venv = VecNormalize(DummyVecEnv([lambda: example.make_meta_env(seeds=(0,))]), norm_reward=False)
    try:
        model = PPO("MultiInputPolicy", venv, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
        model.learn(total_timesteps=128)  # 640 env steps of 0.1 s: the 30 s episode ends at least once
        returns = venv.env_method("get_episode_rewards")[0]
        lengths = venv.env_method("get_episode_lengths")[0]
        obs = venv.reset()
        action, _ = model.predict(obs, deterministic=True)
    finally:
        venv.close()
    assert len(returns) >= 1 and all(np.isfinite(returns))
    # A 30 s episode is at most 60 decisions of 0.5 s; progress pays at most 1 per 0.1 s step.
    assert all(0 < n <= 60 for n in lengths)
    assert all(r <= 300.0 for r in returns)
    assert action.shape == (1,) and 0 <= int(action[0]) < 5
