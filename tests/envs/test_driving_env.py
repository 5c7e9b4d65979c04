"""RoadsynthEnv on a small real highway run (no mocks): Gymnasium's checker, determinism, collisions, lanes."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import pipeline.envs  # noqa: F401  (registers the envs)
from pipeline.envs.features import NEIGHBOUR_SLOTS, SIGNAL_AMBER, SIGNAL_GO, SIGNAL_STOP, signal_row
from pipeline.traffic.simulation import SumoBusyError, active_sumo_owner, close_sumo, start_sumo

pytestmark = pytest.mark.slow

SMALL = {"vehicles": 80, "warmup_s": 30.0, "time_limit_s": 20.0}
LEADER = NEIGHBOUR_SLOTS.index("leader")


def make(**kwargs) -> gym.Env:
    return gym.make("roadsynth/Highway-v0", **{**SMALL, **kwargs})


def rollout(env: gym.Env, seed: int, steps: int) -> tuple[list[dict], list[float]]:
    obs, _ = env.reset(seed=seed)
    actions = np.random.default_rng(7).uniform(-1.0, 1.0, size=(steps, 2)).astype(np.float32)
    observations, rewards = [obs], []
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            break
    return observations, rewards


@pytest.mark.parametrize("env_id", ["roadsynth/Highway-v0", "roadsynth/Urban-v0"])
def test_check_env_passes_without_warnings(env_id):
    env = gym.make(env_id, **SMALL)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env.unwrapped)
    finally:
        env.close()
    assert active_sumo_owner() is None


@pytest.mark.parametrize("env_id", ["roadsynth/Highway-v0", "roadsynth/Urban-v0"])
def test_same_seed_and_actions_give_identical_observations_and_rewards(env_id):
    env = gym.make(env_id, **SMALL, nearby_k=8)
    try:
        first_obs, first_rewards = rollout(env, seed=11, steps=40)
        second_obs, second_rewards = rollout(env, seed=11, steps=40)
        other_obs, _ = rollout(env, seed=12, steps=1)
    finally:
        env.close()
    assert first_rewards == second_rewards
    assert len(first_obs) == len(second_obs) > 1
    for a, b in zip(first_obs, second_obs, strict=True):
        for key in ("ego", "neighbours", "nearby"):
            np.testing.assert_array_equal(a[key], b[key])
    # The seed reaches the demand and SUMO: another seed is another episode.
    assert not np.array_equal(first_obs[0]["ego"], other_obs[0]["ego"])


def test_observations_are_finite_and_inside_the_declared_spaces():
    env = make(nearby_k=8)
    try:
        observations, rewards = rollout(env, seed=3, steps=30)
    finally:
        env.close()
    assert set(env.observation_space.spaces) == {"ego", "neighbours", "signal", "path", "nearby"}
    for obs in observations:
        assert obs in env.observation_space
        assert (obs["signal"] == 0).all()  # the highway has no traffic signal
        assert (obs["path"] == 0).all()  # nor people
        assert obs["ego"].dtype == obs["neighbours"].dtype == np.float32
        assert np.isfinite(obs["ego"]).all() and np.isfinite(obs["neighbours"]).all()
        absent = obs["neighbours"][:, 0] == 0
        assert (obs["neighbours"][absent] == 0).all()  # presence is the mask; absent rows carry no values
    assert np.isfinite(rewards).all()


def test_braking_never_reverses():
    env = make()
    try:
        env.reset(seed=2)
        for _ in range(60):
            obs, _, terminated, truncated, info = env.step(np.array([-1.0, 0.0], dtype=np.float32))
            assert obs["ego"][0] >= 0.0
            if terminated or truncated:
                break
        assert obs["ego"][0] == 0.0
        _, _, _, _, info = env.step(np.array([-1.0, 0.0], dtype=np.float32))
        assert info["reward_terms"]["progress"] == 0.0  # standing still earns nothing
    finally:
        env.close()


def test_full_throttle_into_the_leader_is_a_collision_that_terminates():
    env = make()
    try:
        obs, _ = env.reset(seed=1)
        assert obs["neighbours"][LEADER, 0] == 1.0
        gap_start = obs["neighbours"][LEADER, 1]
        leader, _ = env.unwrapped._sumo.vehicle.getLeader(env.unwrapped.ego_id, 200.0)
        for _ in range(200):
            obs, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
            if terminated or truncated:
                break
            assert "collision" not in info
    finally:
        env.close()
    assert terminated and not truncated
    assert info["reason"] == "collision"
    # What was hit, from SUMO's own record: the leader, rear-ended on its lane by the ego, which was the faster.
    hit = info["collision"]
    assert (hit["other"], hit["other_kind"], hit["type"], hit["ego_is_collider"]) == (leader, "vehicle", "collision",
                                                                                        True)
    assert hit["ego_speed_mps"] > hit["other_speed_mps"] >= 0.0
    assert info["reward_terms"]["collision"] == -env.unwrapped.options.reward.collision
    assert reward < 0
    assert gap_start > 0


def test_lateral_motion_changes_lane_and_leaving_the_road_terminates():
    env = make()
    try:
        obs, _ = env.reset(seed=1)
        lane = obs["ego"][2]
        for i in range(20):  # push left for 1 s, then stop the lateral motion
            obs, _, terminated, truncated, _ = env.step(np.array([0.0, 1.0 if i < 10 else -1.0], dtype=np.float32))
        assert obs["ego"][2] == lane + 1
        assert not terminated and not truncated
        for _ in range(200):  # now drift right until past the outer border
            obs, _, terminated, truncated, info = env.step(np.array([0.0, -1.0], dtype=np.float32))
            if terminated or truncated:
                break
    finally:
        env.close()
    assert terminated and info["reason"] in ("off_road", "collision")


def test_a_second_env_takes_the_simulation_over_and_the_first_then_refuses_to_run():
    first, second = make(), make()
    try:
        first.reset(seed=1)
        first.step(np.zeros(2, dtype=np.float32))
        second.reset(seed=1)
        assert active_sumo_owner() == second.unwrapped._owner
        # libsumo would have let the first env read the second's simulation (its clock jumped back): refused.
        with pytest.raises(SumoBusyError, match="was taken over by"):
            first.step(np.zeros(2, dtype=np.float32))
        with pytest.raises(SumoBusyError, match="was taken over by"):
            first.unwrapped.lane_width_m()
        _, _, _, _, info = second.step(np.zeros(2, dtype=np.float32))
        assert info["time_s"] == pytest.approx(0.1)
        first.reset(seed=1)  # takes it back
        with pytest.raises(SumoBusyError, match="was taken over by"):
            second.step(np.zeros(2, dtype=np.float32))
        second.close()  # does not close the simulation it no longer holds
        _, _, _, _, info = first.step(np.zeros(2, dtype=np.float32))
        assert info["time_s"] == pytest.approx(0.1)
    finally:
        first.close()
        second.close()
    assert active_sumo_owner() is None


def test_an_env_cannot_take_over_a_simulation_that_does_not_yield():
    env = make()
    start_sumo(["-n", str(Path(env.unwrapped.sumo_inputs(1)[0]).parent.parent / "net" / "network.net.xml")],
               "a simulate run")
    try:
        with pytest.raises(SumoBusyError, match=r"held by a simulate run\); RoadsynthEnv"):
            env.reset(seed=1)
    finally:
        close_sumo("a simulate run")
        env.close()
    assert active_sumo_owner() is None


def test_neighbour_slots_lie_where_their_names_say_and_reappear_in_nearby():
    env = make(nearby_k=8)
    seen = set()
    try:
        for seed in (1, 2, 3):
            observations, _ = rollout(env, seed=seed, steps=30)
            for obs in observations:
                rows, nearby = obs["neighbours"], obs["nearby"]
                for slot, row in zip(NEIGHBOUR_SLOTS, rows, strict=True):
                    if not row[0]:
                        continue
                    seen.add(slot)
                    assert (row[1] > 0) == slot.endswith("leader"), (slot, row)
                    # (Leader and follower follow SUMO's lane continuation: at a merge the leader may be a lane aside.)
                    if slot.startswith("left"):
                        assert row[2] > 0.5, (slot, row)
                    elif slot.startswith("right"):
                        assert row[2] < -0.5, (slot, row)
                present = nearby[nearby[:, 0] == 1]
                distance = np.hypot(present[:, 1], present[:, 2])
                assert (np.diff(distance) >= 0).all()  # nearest first
                assert set(present[:, 7]) <= set(range(1, 7))  # a class index for every present row
                for row in rows[rows[:, 0] == 1]:
                    if np.hypot(row[1], row[2]) < distance[-1] - 2.0:  # one of the K nearest: the same vehicle
                        # Slots are road-aligned, nearby rows local: ds agrees to well under a metre here, dd not
                        # where SUMO's lane continuation differs from the geometry (a leader past a merge).
                        same = np.isclose(present[:, 3:6], row[3:6], atol=1e-4).all(axis=1)
                        same &= np.abs(present[:, 1] - row[1]) < 1.0
                        assert same.any(), (row, present)
    finally:
        env.close()
    assert {"leader", "follower"} <= seen and len(seen) >= 4


def test_drifting_onto_the_urban_parking_lane_or_sidewalk_is_off_road():
    env = gym.make("roadsynth/Urban-v0", **SMALL)
    try:
        env.reset(seed=0)
        inner = env.unwrapped
        road = inner._sumo.vehicle.getRoadID(inner.ego_id)
        assert not inner.lane_drivable(0) and not inner.lane_drivable(1), road  # sidewalk, parking lane
        for _ in range(100):  # (it starts nearly at rest: lateral speed needs some longitudinal speed)
            obs, _, terminated, truncated, info = env.step(np.array([0.3, -1.0], dtype=np.float32))
            if terminated or truncated:
                break
    finally:
        env.close()
    assert terminated and info["reason"] == "off_road"
    assert obs["ego"][2] >= 2  # never mapped onto a lane it may not use


def test_the_signal_row_is_the_nearest_signal_in_range_with_its_state():
    ahead = [("J1", 3, 42.5, "r"), ("J2", 0, 80.0, "G")]
    np.testing.assert_array_equal(signal_row(ahead, 100.0), np.array([1.0, 42.5, SIGNAL_STOP], np.float32))
    np.testing.assert_array_equal(signal_row(ahead, 40.0), np.zeros(3, np.float32))  # beyond the range: none
    np.testing.assert_array_equal(signal_row([], 100.0), np.zeros(3, np.float32))
    for letters, state in (("Gg", SIGNAL_GO), ("yu", SIGNAL_AMBER), ("rs", SIGNAL_STOP)):
        assert {signal_row([("J", 0, 5.0, c)], 100.0)[2] for c in letters} == {state}
    with pytest.raises(ValueError, match="traffic signal 'J': link state 'x'"):
        signal_row([("J", 0, 5.0, "x")], 100.0)

