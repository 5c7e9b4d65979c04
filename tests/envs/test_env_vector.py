"""Gymnasium's async vectorisation: one process (one libsumo) per env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import pipeline.envs  # noqa: F401  (registers the envs)

pytestmark = pytest.mark.slow


def _make() -> gym.Env:
    return gym.make("roadsynth/Highway-v0", vehicles=60, warmup_s=25.0, time_limit_s=10.0)


def test_async_vector_env_with_two_processes_steps_and_resets():
    envs = gym.vector.AsyncVectorEnv([_make, _make])
    try:
        first, _ = envs.reset(seed=[1, 2])
        assert first["ego"].shape == (2, 6) and first["neighbours"].shape == (2, 6, 6)
        assert not np.array_equal(first["ego"][0], first["ego"][1])
        for _ in range(5):
            obs, rewards, terminated, truncated, _ = envs.step(np.zeros((2, 2), dtype=np.float32))
            assert rewards.shape == (2,) and np.isfinite(rewards).all()
            assert not terminated.any() and not truncated.any()
        assert not np.array_equal(obs["ego"], first["ego"])
        again, _ = envs.reset(seed=[1, 2])
        np.testing.assert_array_equal(again["ego"], first["ego"])
        np.testing.assert_array_equal(again["neighbours"], first["neighbours"])
    finally:
        envs.close()
