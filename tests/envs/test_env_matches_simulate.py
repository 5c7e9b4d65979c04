"""The env's background traffic is the simulate stage's: same seed -> same ego and the same traffic at reset."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

import pipeline.envs  # noqa: F401  (registers the envs)
from pipeline.stages.simulate import resolve_scenario, simulate

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("scenario", ["highway", "urban"])
def test_reset_with_seed_n_is_simulate_with_seed_n_at_its_first_frame(tmp_path, scenario):
    seed, vehicles, warmup_s, time_limit_s = 4, 60, 25.0, 10.0
    config, _ = resolve_scenario(scenario, vehicles=vehicles, duration_s=time_limit_s, warmup_s=warmup_s)
    stats = simulate(config, seed, tmp_path / "run", progress=False)
    frame0 = pd.read_parquet(tmp_path / "run" / "trajectories.parquet").query("frame == 0 and not parked")
    ego_row = frame0[frame0["is_ego"]].iloc[0]

    env = gym.make(f"roadsynth/{scenario.capitalize()}-v0", vehicles=vehicles, warmup_s=warmup_s,
                   time_limit_s=time_limit_s)
    try:
        obs, info = env.reset(seed=seed)
        sumo = env.unwrapped._sumo
        moving = sorted(v for v in sumo.vehicle.getIDList())
        speeds = {v: sumo.vehicle.getSpeed(v) for v in moving}
    finally:
        env.close()
    assert info["ego_id"] == stats["ego_id"]
    assert obs["ego"][0] == pytest.approx(ego_row["speed_mps"], abs=1e-4)
    recorded = frame0[frame0["cls"] != "pedestrian"].set_index("actor_id")["speed_mps"]
    assert sorted(recorded.index) == moving
    np.testing.assert_allclose([speeds[v] for v in recorded.index], recorded.to_numpy(), atol=1e-9)
