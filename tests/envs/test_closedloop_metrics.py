"""Closed-loop metrics (pipeline/envs/closedloop_metrics.py) on hand-made episode logs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.envs.closedloop_metrics import EpisodeLog, compare, episode_metrics


def _log(speeds, accels=None, leader=None, dt=0.5, collided=False):
    log = EpisodeLog.empty(dt)
    for k, v in enumerate(speeds):
        lid, gap, closing, seen = leader[k] if leader else ("", math.nan, math.nan, False)
        log.add(v, 0.0 if accels is None else accels[k], lid, gap, closing, seen)
    log.collided = collided
    return log


def test_speed_progress_and_collisions_per_100km():
    m = episode_metrics(_log([20.0] * 100, dt=0.5, collided=True))  # 1000 m
    assert m["progress_m"] == pytest.approx(1000.0)
    assert m["mean_speed_mps"] == pytest.approx(20.0)
    assert m["collisions_per_100km"] == pytest.approx(100.0)
    assert episode_metrics(_log([20.0] * 100))["collisions_per_100km"] == 0.0


def test_time_to_collision_only_while_closing_in():
    leader = [("a", 30.0, 10.0, True), ("a", 20.0, 10.0, True), ("a", 12.0, 10.0, True), ("a", 12.0, -1.0, True)]
    m = episode_metrics(_log([20.0] * 4, leader=leader))
    assert m["min_ttc_s"] == pytest.approx(1.2)
    assert m["share_ttc_below_1_5s"] == pytest.approx(0.25)  # 3.0 s, 2.0 s, 1.2 s, opening
    assert episode_metrics(_log([20.0] * 4))["min_ttc_s"] == math.inf


def test_hard_brakes_count_events_not_steps():
    accels = [0, -5, -5, -1, -4.5, 0, -3.9, -4.01]
    assert episode_metrics(_log([10.0] * 8, accels))["hard_brakes"] == 3.0


def test_the_leader_is_held_only_by_a_track_where_the_tracker_would_take_it_for_the_leader():
    """Rows (present, ds, dd, dv, length, width). The gate is chi-square(2 dof, 0.99) = 9.21 sigma^2, sigma = 0.3 +
    0.02 x range: at 40 m sigma 1.1 m, a radius of 3.34 m around the true near face."""
    from pipeline.envs.closedloop_metrics import holds_leader
    from pipeline.envs.tracker import TrackerParams

    radius = math.sqrt(-2 * math.log(0.01)) * (0.3 + 0.02 * 40.0)
    truth = np.array([1.0, 40.0, 0.0, -2.0, 4.5, 1.8])
    assert holds_leader(truth, np.array([1.0, 40.0 + 0.98 * radius, 0.0, 0.0, 4.5, 1.8]))
    assert not holds_leader(truth, np.array([1.0, 40.0 + 1.02 * radius, 0.0, 0.0, 4.5, 1.8]))
    assert holds_leader(truth, np.array([1.0, 40.0, -0.98 * radius, 0.0, 4.5, 1.8]))  # across the lane as along
    assert not holds_leader(truth, np.array([1.0, 40.0 + 0.75 * radius, 0.75 * radius, 0.0, 4.5, 1.8]))  # 1.06 r
    # A truck 12 m long taken for a car (a track's typical length, 4.5 m): the same rear, 3.75 m nearer centres.
    truck = np.array([1.0, 46.0, 0.0, 0.0, 12.0, 2.5])
    assert holds_leader(truck, np.array([1.0, 42.25, 0.1, 0.0, 4.5, 1.8]))
    assert not holds_leader(truck, np.array([1.0, 46.0, 0.0, 0.0, 4.5, 1.8]))  # its centre, but the rear 3.75 m off
    # Far off the gate widens with the range: 10 m beyond a leader at 90 m is not it (the 20 % window took it).
    far = np.array([1.0, 90.0, 0.0, 0.0, 4.5, 1.8])
    assert holds_leader(far, np.array([1.0, 95.0, 0.5, 0.0, 4.5, 1.8]))
    assert not holds_leader(far, np.array([1.0, 100.0, 0.0, 0.0, 4.5, 1.8]))
    assert holds_leader(far, np.array([1.0, 100.0, 0.0, 0.0, 4.5, 1.8]), TrackerParams(sigma_per_m=0.05))
    assert not holds_leader(truth, np.array([0.0, 40.0, 0.0, -2.0, 4.5, 1.8]))  # nothing observed
    assert not holds_leader(np.zeros(6), np.array([1.0, 20.0, 0.0, 0.0, 4.5, 1.8]))  # no leader to hold


def test_first_tracked_range_is_the_gap_when_each_leader_is_first_seen():
    leader = [("a", 80.0, 0.0, False), ("a", 70.0, 0.0, False), ("a", 60.0, 0.0, True), ("a", 50.0, 0.0, True),
              ("b", 90.0, 0.0, False), ("b", 40.0, 0.0, True), ("", math.nan, math.nan, False)]
    assert episode_metrics(_log([10.0] * 7, leader=leader))["first_tracked_range_m"] == pytest.approx(50.0)
    assert math.isnan(episode_metrics(_log([10.0] * 3))["first_tracked_range_m"])


def test_compare_gives_the_mean_difference_with_a_bootstrap_interval():
    gt = [{"collisions_per_100km": 0.0, "min_ttc_s": 3.0, "share_ttc_below_1_5s": 0.0, "hard_brakes": 0.0,
           "first_tracked_range_m": 80.0, "steady_tracked_range_m": 80.0, "leader_held_0_20m": 1.0,
           "leader_held_20_40m": 1.0,
           "leader_held_40_60m": 1.0, "leader_held_60_100m": 1.0, "mean_speed_mps": 25.0, "progress_m": 750.0,
           "slot_missed_share": 0.0, "slot_false_share": 0.0, "slot_ds_error_m": 0.0, "slot_dv_error_mps": 0.0,
           "person_steps_share": 0.0, "person_missed_share": math.nan, "person_false_share": math.nan}
          for _ in range(5)]
    perceived = [{**m, "first_tracked_range_m": 80.0 - d, "min_ttc_s": math.inf if d == 30 else 2.0}
                 for m, d in zip(gt, (10, 20, 30, 40, 50), strict=True)]
    rows = {c.metric: c for c in compare(perceived, gt, resamples=4000)}
    r = rows["first_tracked_range_m"]
    assert (r.perceived, r.ground_truth, r.difference, r.seeds) == (50.0, 80.0, -30.0, 5)
    assert -50.0 <= r.ci_low < -30.0 < r.ci_high <= -10.0
    assert rows["min_ttc_s"].seeds == 4  # the infinite TTC leaves its pair out
    same = rows["mean_speed_mps"]
    assert same.difference == 0.0 and same.ci_low == same.ci_high == 0.0
    assert compare(perceived, gt, resamples=100) == compare(perceived, gt, resamples=100)  # fixed seed
    with pytest.raises(ValueError, match="one of each per seed"):
        compare(perceived[:2], gt)


def test_a_bad_step_length_is_refused():
    with pytest.raises(ValueError, match="dt_s"):
        EpisodeLog.empty(0.0)
    assert np.isnan(episode_metrics(EpisodeLog.empty(0.1))["mean_speed_mps"])


def test_perception_errors_on_the_slots():
    log = _log([10.0] * 3)
    # slots: (present, ds, dv) for truth and observation
    log.add_slots(np.array([[1, 20, 0], [1, 40, -2], [0, 0, 0]]), np.array([[1, 21, 0.5], [0, 0, 0], [1, 30, 0]]))
    log.add_slots(np.array([[1, 20, 0], [0, 0, 0], [0, 0, 0]]), np.array([[1, 19, -0.5], [0, 0, 0], [0, 0, 0]]))
    m = episode_metrics(log)
    assert m["slot_missed_share"] == pytest.approx(1 / 3)  # 3 truth slots, 1 not observed
    assert m["slot_false_share"] == pytest.approx(1 / 3)  # 3 observed slots, 1 not in the truth
    assert m["slot_ds_error_m"] == pytest.approx(1.0) and m["slot_dv_error_mps"] == pytest.approx(0.5)
    assert math.isnan(episode_metrics(_log([10.0]))["slot_ds_error_m"])


def test_the_leader_is_held_by_range_over_every_step_with_a_leader():
    from pipeline.envs.closedloop_metrics import LEADER_HELD

    assert LEADER_HELD == ("leader_held_0_20m", "leader_held_20_40m", "leader_held_40_60m", "leader_held_60_100m")
    leader = [("a", 95.0, 0.0, False), ("a", 70.0, 0.0, False), ("a", 61.0, 0.0, True), ("a", 55.0, 0.0, False),
              ("a", 45.0, 0.0, True), ("a", 40.0, 0.0, True), ("a", 19.9, 0.0, True), ("a", -0.5, 0.0, False),
              ("", math.nan, math.nan, False), ("b", 120.0, 0.0, True)]
    m = episode_metrics(_log([10.0] * len(leader), leader=leader))
    assert m["leader_held_60_100m"] == pytest.approx(2 / 4)  # 95, 70 missed; 61 and 120 (beyond: last bin) held
    assert m["leader_held_40_60m"] == pytest.approx(2 / 3)  # 40.0 falls in [40, 60)
    assert m["leader_held_20_40m"] != m["leader_held_20_40m"]  # no step with a leader there: NaN
    assert m["leader_held_0_20m"] == pytest.approx(1 / 2)  # an overlap (-0.5 m) counts in the first bin
    assert all(math.isnan(episode_metrics(_log([10.0] * 3))[k]) for k in LEADER_HELD)


def test_steady_tracked_range_needs_the_leader_held_for_a_second():
    """A leader held once at 80 m, lost, then held from 50 m on: first tracked at 80 m, steadily at 50 m (dt 0.5 s:
    two steps make a second); a leader held for one step only is never tracked steadily."""
    leader = [("a", 80.0, 0.0, True), ("a", 70.0, 0.0, False), ("a", 60.0, 0.0, False), ("a", 50.0, 0.0, True),
              ("a", 45.0, 0.0, True), ("a", 40.0, 0.0, True), ("b", 30.0, 0.0, True), ("b", 29.0, 0.0, False)]
    m = episode_metrics(_log([10.0] * len(leader), leader=leader, dt=0.5))
    assert m["first_tracked_range_m"] == pytest.approx(55.0)  # median of a's 80 m and b's 30 m
    assert m["steady_tracked_range_m"] == pytest.approx(50.0)  # a only
    # A run across a change of leader does not count for the new one.
    switch = [("a", 20.0, 0.0, True), ("b", 35.0, 0.0, True), ("b", 34.0, 0.0, False)]
    assert math.isnan(episode_metrics(_log([10.0] * 3, leader=switch, dt=0.5))["steady_tracked_range_m"])


def test_the_person_in_the_path_is_scored_as_the_leader_slots_are():
    log = EpisodeLog.empty(0.1)
    present, absent = np.array([1.0, 10.0, 0.0]), np.zeros(3)
    # 10 steps: a person in the true path on 4 (the observation holds 3 of them), and 2 false ones.
    steps = [(present, present)] * 3 + [(present, absent)] + [(absent, present)] * 2 + [(absent, absent)] * 4
    for truth, seen in steps:
        log.add(10.0, 0.0, "", math.nan, math.nan, False)
        log.add_path(truth, seen)
    m = episode_metrics(log)
    assert m["person_steps_share"] == pytest.approx(0.4)
    assert m["person_missed_share"] == pytest.approx(0.25)
    assert m["person_false_share"] == pytest.approx(0.4)
    quiet = EpisodeLog.empty(0.1)
    quiet.add(10.0, 0.0, "", math.nan, math.nan, False)
    quiet.add_path(absent, absent)
    q = episode_metrics(quiet)
    assert q["person_steps_share"] == 0.0 and np.isnan(q["person_missed_share"]) and np.isnan(q["person_false_share"])
