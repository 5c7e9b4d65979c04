"""The reference driver (pipeline/envs/driver.py): IDM, MOBIL and traffic signals in closed form, and episodes in the
real env (the highway; an urban seed whose ego, before signals were observed, drove into junction A4 at red and
collided there)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from pipeline.envs.driver import IdmParams, MobilParams, Neighbour, ReferenceAgent, ReferenceDriver, idm_accel, mobil
from pipeline.envs.features import NEIGHBOUR_FIELDS, NEIGHBOUR_SLOTS, SIGNAL_AMBER, SIGNAL_GO, SIGNAL_STOP

IDM = IdmParams()


def test_free_road_acceleration_is_the_free_term():
    for v in (0.0, 10.0, 20.0, IDM.desired_speed_mps):
        assert idm_accel(v, IDM) == pytest.approx(IDM.max_accel_mps2 * (1 - (v / IDM.desired_speed_mps) ** 4))
    assert idm_accel(IDM.desired_speed_mps, IDM) == pytest.approx(0.0, abs=1e-12)


def test_the_equilibrium_gap_gives_zero_acceleration():
    v = 20.0
    s_star = IDM.min_gap_m + v * IDM.time_headway_s
    gap = s_star / math.sqrt(1 - (v / IDM.desired_speed_mps) ** 4)
    assert idm_accel(v, IDM, gap, v) == pytest.approx(0.0, abs=1e-12)
    assert idm_accel(v, IDM, 0.9 * gap, v) < 0 < idm_accel(v, IDM, 1.1 * gap, v)


def test_closing_in_brakes_harder_and_an_overlap_cannot_be_undone():
    assert idm_accel(20.0, IDM, 30.0, 10.0) < idm_accel(20.0, IDM, 30.0, 20.0) < idm_accel(20.0, IDM, 30.0, 30.0)
    assert idm_accel(20.0, IDM, 0.0, 20.0) == -math.inf


def _slow_leader(**extra: Neighbour) -> dict[str, Neighbour]:
    return {"leader": Neighbour(ds_m=20.0, speed_mps=15.0, length_m=4.5), **extra}


def test_mobil_leaves_a_slow_leader_for_a_free_left_lane():
    choice = mobil(25.0, 4.5, _slow_leader(), +1, IDM, MobilParams())
    assert choice.safe and choice.change
    # the gain is the free-road acceleration less the car-following one, less the keep-right bias
    gap = 20.0 - 4.5
    gain = idm_accel(25.0, IDM) - idm_accel(25.0, IDM, gap, 15.0)
    assert choice.incentive == pytest.approx(gain - MobilParams().keep_right_bias_mps2)


def test_mobil_refuses_to_cut_in_front_of_a_close_fast_follower():
    fast_behind = Neighbour(ds_m=-6.0, speed_mps=33.0, length_m=4.5)
    choice = mobil(25.0, 4.5, _slow_leader(left_follower=fast_behind), +1, IDM, MobilParams())
    after = idm_accel(33.0, IDM, 6.0 - 4.5, 25.0)
    assert after < -MobilParams().safe_decel_mps2
    assert not choice.safe and not choice.change


def test_mobil_keeps_right_when_nothing_is_gained():
    params = MobilParams()
    right = mobil(25.0, 4.5, {}, -1, IDM, params)
    left = mobil(25.0, 4.5, {}, +1, IDM, params)
    assert right.incentive == pytest.approx(params.keep_right_bias_mps2) and right.change
    assert left.incentive == pytest.approx(-params.keep_right_bias_mps2) and not left.change


def test_mobil_does_not_change_into_a_lane_it_cannot_see_behind():
    # A front camera's perception fills only the leaders: an empty left-follower slot there is not an empty lane.
    front_camera = ("left_leader", "leader", "right_leader")
    blind = mobil(25.0, 4.5, _slow_leader(), +1, IDM, MobilParams(), front_camera)
    seen = mobil(25.0, 4.5, _slow_leader(), +1, IDM, MobilParams(), NEIGHBOUR_SLOTS)
    assert seen.change and not blind.safe and not blind.change
    assert blind.incentive == pytest.approx(seen.incentive)  # it would gain as much; it is the safety that fails


def test_the_reference_agent_takes_the_observed_slots_from_a_perception_wrapper():
    class FrontCamera(gym.Wrapper):
        observed_slots = ("left_leader", "leader", "right_leader")

    env = gym.make("roadsynth/Scenario-v0", scenario="highway", vehicles=20, warmup_s=5.0, time_limit_s=1.0)
    try:
        obs, _ = env.reset(seed=1)
        plain, wrapped = ReferenceAgent(env), ReferenceAgent(FrontCamera(env))
        plain.reset(obs)
        wrapped.reset(obs)
        assert plain.driver.observed_slots == NEIGHBOUR_SLOTS
        assert wrapped.driver.observed_slots == FrontCamera.observed_slots
    finally:
        env.close()


def test_politeness_counts_the_old_followers_gain():
    # Behind the ego a follower is held up: leaving its lane frees it; with politeness the incentive grows.
    follower = Neighbour(ds_m=-12.0, speed_mps=25.0, length_m=4.5)
    lonely = mobil(25.0, 4.5, {"follower": follower}, +1, IDM, MobilParams(politeness=0.0))
    polite = mobil(25.0, 4.5, {"follower": follower}, +1, IDM, MobilParams(politeness=1.0))
    assert polite.incentive > lonely.incentive


def _obs(speed: float, offset: float = 0.0, **slots: tuple[float, float, float]) -> dict[str, np.ndarray]:
    rows = np.zeros((len(NEIGHBOUR_SLOTS), len(NEIGHBOUR_FIELDS)), np.float32)
    for slot, (ds, dv, length) in slots.items():
        rows[NEIGHBOUR_SLOTS.index(slot)] = (1.0, ds, 0.0, dv, length, 1.8)
    return {"ego": np.array([speed, 0.0, 1.0, offset, 0.0, 1000.0], np.float32), "neighbours": rows}


def test_the_driver_follows_with_idm_and_steers_to_the_chosen_lane():
    driver = ReferenceDriver(dt_s=0.1, cooldown_s=0.0)
    obs = _obs(25.0, leader=(20.0, -10.0, 4.5))
    driver.reset(obs)
    lon, lat = driver.accelerations(obs, 3.5, lambda side: side == +1)  # only a left lane
    assert lon == pytest.approx(idm_accel(25.0, IDM, 20.0 - 4.5, 15.0))
    assert driver.target_offset_m == pytest.approx(3.5) and lat == pytest.approx(3.5)
    # No drivable lane: it stays and brakes behind the leader.
    stay = ReferenceDriver(dt_s=0.1, cooldown_s=0.0)
    stay.reset(obs)
    assert stay.accelerations(obs, 3.5, lambda side: False)[1] == 0.0
    assert stay.target_offset_m == 0.0


def _signal(obs: dict[str, np.ndarray], distance: float | None, state: int = SIGNAL_STOP) -> dict[str, np.ndarray]:
    row = np.zeros(3, np.float32) if distance is None else np.array([1.0, distance, state], np.float32)
    return {**obs, "signal": row}


def test_a_red_signal_is_a_standing_vehicle_at_its_stop_line():
    driver = ReferenceDriver(dt_s=0.1)
    obs = _obs(10.0)
    driver.reset(obs)
    free = driver.accelerations(obs, 3.5)[0]
    assert free == pytest.approx(idm_accel(10.0, IDM))
    lon = driver.accelerations(_signal(obs, 30.0), 3.5)[0]
    assert lon == pytest.approx(idm_accel(10.0, IDM, 30.0, 0.0)) and lon < 0.0
    assert driver.accelerations(_signal(obs, 30.0, SIGNAL_GO), 3.5)[0] == pytest.approx(free)
    # A leader nearer than the stop line governs; a farther one does not.
    near = _signal(_obs(10.0, leader=(12.0, -10.0, 4.5)), 30.0)
    assert driver.accelerations(near, 3.5)[0] == pytest.approx(idm_accel(10.0, IDM, 12.0 - 4.5, 0.0))


def test_at_amber_it_stops_where_it_comfortably_can_and_else_drives_on_through_the_red():
    driver = ReferenceDriver(dt_s=0.1, amber_decel_mps2=4.0)
    obs = _obs(12.0)
    driver.reset(obs)
    # 12 m/s needs 18 m at 4 m/s^2: from 40 m it stops ...
    assert driver.accelerations(_signal(obs, 40.0, SIGNAL_AMBER), 3.5)[0] == pytest.approx(
        idm_accel(12.0, IDM, 40.0, 0.0))
    # ... from 10 m it drives on, and keeps on when the same signal turns red 5 m later ...
    driver.reset(obs)
    free = idm_accel(12.0, IDM)
    assert driver.accelerations(_signal(obs, 10.0, SIGNAL_AMBER), 3.5)[0] == pytest.approx(free)
    assert driver.accelerations(_signal(obs, 5.0, SIGNAL_STOP), 3.5)[0] == pytest.approx(free)
    # ... but the next signal, farther on, is obeyed again.
    assert driver.accelerations(_signal(obs, 60.0, SIGNAL_STOP), 3.5)[0] == pytest.approx(
        idm_accel(12.0, IDM, 60.0, 0.0))
    # A red seen first from near is obeyed: it never chose to go.
    driver.reset(obs)
    assert driver.accelerations(_signal(obs, 5.0, SIGNAL_STOP), 3.5)[0] < -3.0
    # No "signal" row (an older observation) or none present: IDM alone.
    assert driver.accelerations(_signal(obs, None), 3.5)[0] == pytest.approx(free)


def test_the_road_s_speed_limit_caps_the_desired_speed():
    driver = ReferenceDriver(dt_s=0.1)
    obs = _obs(13.0)
    driver.reset(obs)
    city = IdmParams(desired_speed_mps=13.89)
    assert driver.accelerations(obs, 3.5, speed_limit_mps=13.89)[0] == pytest.approx(idm_accel(13.0, city))
    assert driver.accelerations(obs, 3.5, speed_limit_mps=50.0)[0] == pytest.approx(idm_accel(13.0, IDM))


def test_it_keeps_to_lanes_that_follow_its_route_and_leaves_one_that_does_not():
    # A slow leader ahead, the left lane free: MOBIL would go left ...
    obs = _obs(20.0, leader=(30.0, -10.0, 4.5))
    driver = ReferenceDriver(dt_s=0.1, cooldown_s=0.0)
    driver.reset(obs)
    driver.accelerations(obs, 3.5, lambda side: side == +1, lambda side: 500.0)
    assert driver.target_offset_m == pytest.approx(3.5)
    # ... but not when the left lane leaves the route within 60 m and its own goes on for 500 m.
    driver = ReferenceDriver(dt_s=0.1, cooldown_s=0.0)
    driver.reset(obs)
    driver.accelerations(obs, 3.5, lambda side: side == +1, lambda side: 60.0 if side == 1 else 500.0)
    assert driver.target_offset_m == 0.0
    # Its own lane leaves the route in 40 m (under 5 s at 20 m/s): it changes right, where nothing is gained ...
    free = _obs(20.0)
    driver = ReferenceDriver(dt_s=0.1, cooldown_s=0.0)
    driver.reset(free)
    lon, _ = driver.accelerations(free, 3.5, lambda side: side == -1, lambda side: 40.0 if side == 0 else 500.0)
    assert driver.target_offset_m == pytest.approx(-3.5)
    # ... but not in front of a close follower there; it then brakes for its lane's end, 40 m ahead.
    blocked = _obs(20.0, right_follower=(-6.0, 5.0, 4.5))
    driver = ReferenceDriver(dt_s=0.1, cooldown_s=0.0)
    driver.reset(blocked)
    lon, _ = driver.accelerations(blocked, 3.5, lambda side: side == -1, lambda side: 40.0 if side == 0 else 500.0)
    assert driver.target_offset_m == 0.0 and lon == pytest.approx(idm_accel(20.0, IDM, 40.0, 0.0))
    # With a front camera alone (no follower slots) it cannot see a gap: no change, and it drives on.
    driver = ReferenceDriver(dt_s=0.1, cooldown_s=0.0, observed_slots=("left_leader", "leader", "right_leader"))
    driver.reset(free)
    lon, _ = driver.accelerations(free, 3.5, lambda side: side == -1, lambda side: 40.0 if side == 0 else 500.0)
    assert driver.target_offset_m == 0.0 and lon == pytest.approx(idm_accel(20.0, IDM))


def test_parameters_are_checked_naming_the_field():
    with pytest.raises(ValueError, match="desired_speed_mps"):
        IdmParams(desired_speed_mps=0.0)
    with pytest.raises(ValueError, match="politeness"):
        MobilParams(politeness=float("nan"))
    with pytest.raises(ValueError, match="dt_s"):
        ReferenceDriver(dt_s=0.0)
    with pytest.raises(ValueError, match="amber_decel_mps2"):
        ReferenceDriver(amber_decel_mps2=-1.0)
    with pytest.raises(ValueError, match="must_change_m"):
        ReferenceDriver(must_change_m=float("nan"))


def _drive(env_id: str, seed: int, time_limit_s: float) -> tuple[list[float], bool, bool, dict]:
    """One episode of the reference agent: the ego's speed per step, terminated, truncated and the last info."""
    import pipeline.envs  # noqa: F401  (registers the envs)

    env = gym.make(env_id, time_limit_s=time_limit_s)
    try:
        obs, _ = env.reset(seed=seed)
        agent = ReferenceAgent(env)
        agent.reset(obs)
        speeds = []
        while True:
            obs, _, terminated, truncated, info = env.step(agent.act(obs))
            speeds.append(float(obs["ego"][0]))
            if terminated or truncated:
                return speeds, terminated, truncated, info
    finally:
        env.close()


@pytest.mark.slow
def test_the_reference_agent_drives_the_highway_without_collision():
    speeds, terminated, truncated, info = _drive("roadsynth/Highway-v0", 3, 20.0)
    assert truncated and not terminated, info["reason"]  # a collision or leaving the road terminates
    assert np.mean(speeds) > 15.0  # it drives, at highway speed


@pytest.mark.slow
def test_the_reference_agent_waits_at_red_in_the_city():
    """Urban seed 4: its ego comes to junction A4 while its signal is red (before signals were observed it drove in
    at 1.4 m/s and collided with a car turning in, 6.7 s later). Every step the observation's signal row is SUMO's
    next signal on the ego's way, and the ego never enters a junction on a red light."""
    import libsumo

    import pipeline.envs  # noqa: F401  (registers the envs)

    env = gym.make("roadsynth/Urban-v0", time_limit_s=12.0)
    try:
        obs, _ = env.reset(seed=4)
        agent = ReferenceAgent(env)
        agent.reset(obs)
        ego = env.unwrapped.ego_id
        reds, waited, before, lane = 0, 0, obs["signal"], libsumo.vehicle.getLaneID(ego)
        while True:
            waited += round(float(obs["signal"][2])) == SIGNAL_STOP and obs["ego"][0] < 0.1
            nxt = libsumo.vehicle.getNextTLS(ego)
            assert obs["signal"][0] == 1.0 and obs["signal"][1] == pytest.approx(nxt[0][2], abs=1e-3)
            obs, _, terminated, truncated, info = env.step(agent.act(obs))
            now = libsumo.vehicle.getLaneID(ego)
            if now.startswith(":") and not lane.startswith(":"):  # it entered a junction
                reds += round(float(before[2])) == SIGNAL_STOP
            before, lane = obs["signal"], now
            if terminated or truncated:
                break
        assert truncated and not terminated, info["reason"]
        assert reds == 0 and waited > 10  # it stood at the red for more than a second
    finally:
        env.close()


@pytest.mark.slow
def test_the_reference_agent_keeps_to_its_route_and_the_city_s_limit():
    """Urban seed 6: its ego, on the lane that goes on along its route, was taken by MOBIL into a lane that turns off
    it (the episode ended "left_route" 3.9 s in) before lanes were weighed by the route; and the driver aimed at the
    motorway's 120 km/h in the city before the road's limit capped its desired speed."""
    speeds, terminated, truncated, info = _drive("roadsynth/Urban-v0", 6, 30.0)
    assert truncated and not terminated, info["reason"]
    assert max(speeds) <= 13.89 + 0.05 and max(speeds) > 5.0  # it drives, within the city's 50 km/h


def test_a_seed_sumo_cannot_take_is_refused_at_reset():
    import pipeline.envs  # noqa: F401  (registers the envs)

    env = gym.make("roadsynth/Highway-v0", vehicles=20, warmup_s=5.0)
    try:
        for seed in (2**31, -1):
            with pytest.raises(ValueError, match=r"reset\(seed="):
                env.reset(seed=seed)
    finally:
        env.close()
