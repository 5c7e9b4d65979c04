"""The "path" row (pipeline/envs/features.py): the nearest person in the ego's path, in closed form; the reference
driver yielding to it; and in the real urban scenario, a person on the crossing the ego's route takes stops the
reference agent short of them, where a driver blind to the row runs them down (SUMO's own collision record); the
perceived row (pipeline/envs/perception.py) from LiDAR-ranged boxes of the labelled people, against the ground
truth's."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from pipeline.envs.driver import IdmParams, ReferenceAgent, ReferenceDriver, idm_accel
from pipeline.envs.features import (
    PERSON_RADIUS_M,
    is_crossing,
    path_polyline,
    path_row,
    project_on_path,
)
from pipeline.envs.perception import PERSON_CATEGORY, PERSON_TRACKER, RecentPlaces, perceived_path_row
from pipeline.envs.tracker import Detections, Track, Tracker

# An L-shaped path: 20 m east along y = 0, then 20 m north along x = 20.
L_PATH = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]])
HALF = 0.9  # half an ego's width


def test_points_project_onto_the_path_with_their_side_and_whether_they_lie_along_it():
    points = np.array([[5.0, 1.0], [5.0, -2.0], [21.0, 10.0], [-3.0, 0.0], [20.0, 25.0], [25.0, -5.0]])
    s, d, inside, seg = project_on_path(L_PATH, points)
    np.testing.assert_allclose(s[:3], [5.0, 5.0, 30.0])
    np.testing.assert_allclose(d[:3], [1.0, -2.0, -1.0])  # left positive: east of the northward leg is its right
    assert inside.tolist() == [True, True, True, False, False, True]  # behind the start, beyond the end
    assert seg.tolist()[:3] == [0, 0, 1]
    assert s[5] == pytest.approx(20.0)  # outside the bend: its vertex, along the path


def test_the_polyline_starts_at_the_bumper_cuts_the_first_lane_and_stops_at_its_range():
    lane = np.array([[-50.0, 0.0], [0.0, 0.0], [30.0, 0.0]])
    turn = np.array([[30.0, 0.0], [40.0, 10.0]])
    nxt = np.array([[40.0, 12.0], [40.0, 100.0]])  # a gap of 2 m: crossed straight
    path = path_polyline((10.0, 0.5), [lane, turn, nxt], 45.0)
    np.testing.assert_allclose(path[:3], [[10.0, 0.5], [30.0, 0.0], [40.0, 10.0]])
    lengths = np.hypot(*np.diff(path, axis=0).T)
    assert lengths.sum() == pytest.approx(45.0)
    assert path[-1, 0] == pytest.approx(40.0) and path[-2].tolist() == [40.0, 12.0]


def test_a_person_standing_in_the_path_is_at_their_place_less_their_reach():
    row = path_row(L_PATH, [[12.0, 0.5]], [[0.0, 0.0]], 10.0, HALF)
    np.testing.assert_allclose(row, [1.0, 12.0 - PERSON_RADIUS_M, 0.5], rtol=1e-6)
    # After the bend: along the path; the nearer of two.
    row = path_row(L_PATH, [[20.5, 8.0], [12.0, -1.0]], np.zeros((2, 2)), 10.0, HALF)
    np.testing.assert_allclose(row, [1.0, 12.0 - PERSON_RADIUS_M, -1.0], rtol=1e-6)
    # Beside the path (beyond half the width + the reach), behind the bumper, or beyond the path's end: nobody.
    for place in ([12.0, HALF + PERSON_RADIUS_M + 0.01], [-1.0, 0.0], [20.0, 21.0]):
        assert not path_row(L_PATH, [place], [[0.0, 0.0]], 10.0, HALF).any()
    assert not path_row(L_PATH, np.zeros((0, 2)), np.zeros((0, 2)), 10.0, HALF).any()


def test_a_person_walking_into_the_path_counts_if_they_get_there_before_the_ego():
    # 3 m to the side of the path 10 m ahead, walking towards it at 1.5 m/s: 1.4 s to the corridor's edge.
    walker = [[10.0, 3.0]], [[0.0, -1.5]]
    row = path_row(L_PATH, *walker, 5.0, HALF)  # the ego needs 2 s to get there
    assert row[0] == 1.0 and row[1] == pytest.approx(10.0 - PERSON_RADIUS_M)
    assert 0.0 < row[2] < HALF + PERSON_RADIUS_M
    assert not path_row(L_PATH, *walker, 20.0, HALF).any()  # the ego passes in 0.5 s, before they step in
    assert not path_row(L_PATH, [[10.0, 3.0]], [[0.0, 1.5]], 5.0, HALF).any()  # walking away
    # Far ahead, the look-ahead is capped at the horizon: 3 s, 4.5 m of walking, reaches from 5 m but not 6 m.
    far = np.array([[0.0, 0.0], [100.0, 0.0]])
    assert path_row(far, [[90.0, 5.0]], [[0.0, -1.5]], 1.0, HALF, horizon_s=3.0)[0] == 1.0
    assert not path_row(far, [[90.0, 6.0]], [[0.0, -1.5]], 1.0, HALF, horizon_s=3.0).any()


def test_off_the_road_a_person_counts_only_once_walking_into_the_path():
    # A corner of a walking area a turning lane's centre line passes within a metre of.
    standing = path_row(L_PATH, [[12.0, -1.0]], [[0.0, 0.0]], 5.0, HALF, on_road=[False])
    assert not standing.any()
    assert path_row(L_PATH, [[12.0, -1.0]], [[0.0, 0.0]], 5.0, HALF, on_road=[True])[0] == 1.0
    walking = path_row(L_PATH, [[12.0, -2.5]], [[0.0, 1.2]], 5.0, HALF, on_road=[False])
    assert walking[0] == 1.0 and abs(walking[2]) < HALF + PERSON_RADIUS_M


def _tracked(places: np.ndarray, *, ego_speed: float, on_road=lambda xy: np.zeros(len(xy), bool)) -> list:
    """Feed one person's places frame by frame (0.1 s apart, the ego at rest at the fixed frame's origin) to a
    person tracker; the perceived path row after each frame."""
    tracker, recent = Tracker(PERSON_TRACKER), RecentPlaces()
    rows = []
    for place in places:
        tracks = tracker.update(Detections(np.array([place]), np.full((1, 4), np.nan), np.array([PERSON_CATEGORY]),
                                           np.array([[0.5, 0.5]])))
        rows.append(perceived_path_row(tracks, L_PATH, HALF, ego_speed, on_road, recent.moved_mps(tracks, 0.1)))
    return rows


def test_a_tracked_person_walking_off_the_road_fills_the_row_once_their_walk_is_known():
    """Off the road (the map says so), a person 4 m beside the path 10 m ahead walks towards it at 1.4 m/s, the ego
    at 5 m/s: not in the row while the track's velocity is unknown (born standing, 2 m/s of doubt), then in it, at
    the place they will step in, long before they do (after 2.2 s)."""
    t = np.arange(25) * 0.1
    places = np.column_stack([np.full_like(t, 10.0), 4.0 - 1.4 * t])
    rows = _tracked(places, ego_speed=5.0)
    assert not rows[0].any() and not rows[1].any()  # one frame: no track; two: confirmed, but standing, off the road
    first = next(k for k, row in enumerate(rows) if row[0])
    assert 2 < first < 17  # filled once the speed is 3 standard deviations clear of 0, before they reach the corridor
    assert places[first, 1] > HALF + PERSON_RADIUS_M + 0.5
    for row in rows[first:]:
        assert row[0] == 1.0 and row[1] == pytest.approx(10.0 - PERSON_RADIUS_M, abs=0.05)


def test_a_tracked_person_standing_beside_the_path_never_fills_the_row_through_ranging_noise():
    """Standing 1.5 m beyond the corridor's edge, 10 m ahead, ranged with 0.5 m of noise (the tracker's own model at
    that range) for 20 s: the filtered speed never looks like a walk into the path (3 standard deviations)."""
    rng = np.random.default_rng(7)
    places = np.array([10.0, -(HALF + PERSON_RADIUS_M + 1.5)]) + rng.normal(0.0, 0.5, (200, 2))
    assert not any(row.any() for row in _tracked(places, ego_speed=1.0))
    # A person standing on the carriageway (the map says so) 0.2 m from the centre line: in the row once confirmed.
    near = np.array([10.0, 0.2]) + rng.normal(0.0, 0.05, (5, 2))
    rows = _tracked(near, ego_speed=1.0, on_road=lambda xy: np.ones(len(xy), bool))
    assert not rows[0].any() and all(row[0] == 1.0 for row in rows[1:])


def test_a_track_s_velocity_counts_only_when_known_and_a_walk_s():
    """Off the road 3 m beside the path 10 m ahead, heading for it: a track at 1.4 m/s known to 0.3 m/s walks in; the
    same at 4 m/s (no walk: a step between two people), or known only to 0.8 m/s (a young track), stands."""
    def row(speed_mps: float, sigma_mps: float):
        p = np.diag([0.1, 0.1, sigma_mps ** 2, sigma_mps ** 2])
        track = Track(1, np.array([10.0, 3.0, 0.0, -speed_mps]), p, np.full(4, np.nan), PERSON_CATEGORY,
                      np.array([0.5, 0.5]), confirmed=True)
        return perceived_path_row([track], L_PATH, HALF, 5.0, lambda xy: np.zeros(len(xy), bool))

    assert row(1.4, 0.3)[0] == 1.0
    assert not row(4.0, 0.3).any()
    assert not row(1.4, 0.8).any()
    assert not row(0.8, 0.3).any()  # known, but 3 sigma is 0.9 m/s
    # Its places moved at 0.7 m/s over the last second (a box on a group, ranged on one and then another): stands.
    def moved(speed_mps: float, moved_mps: float):
        p = np.diag([0.1, 0.1, 0.09, 0.09])
        track = Track(1, np.array([10.0, 3.0, 0.0, -speed_mps]), p, np.full(4, np.nan), PERSON_CATEGORY,
                      np.array([0.5, 0.5]), confirmed=True)
        return perceived_path_row([track], L_PATH, HALF, 5.0, lambda xy: np.zeros(len(xy), bool), [moved_mps])

    assert moved(1.4, 0.7)[0] == 1.0 and not moved(1.4, 0.69).any()
    recent = RecentPlaces()
    tracks = [Track(7, np.array([0.0, 0.0, 0.0, 0.0]), np.eye(4), np.full(4, np.nan), 1, np.ones(2))]
    assert recent.moved_mps(tracks, 0.1).tolist() == [0.0]  # one place
    for k in range(1, 15):
        tracks[0].x = np.array([0.1 * k, 0.0, 0.0, 0.0])
        assert recent.moved_mps(tracks, 0.1) == pytest.approx([1.0])  # 0.1 m a step, over up to 9 steps
    assert recent.moved_mps([], 0.1).shape == (0,) and recent.moved_mps(tracks, 0.1).tolist() == [0.0]  # forgot it
    assert not perceived_path_row([], L_PATH, HALF, 5.0, lambda xy: np.zeros(len(xy), bool)).any()


def test_crossings_are_told_from_walking_areas_and_lanes():
    assert is_crossing(":E4_c1_0") and is_crossing(":E4_c1") and is_crossing(":J_12_c0_0")
    assert not any(map(is_crossing, (":E4_w0_0", ":E4_w0", ":E4_5_0", "E4D4_2", "c1_0", "")))


def test_the_driver_stops_short_of_a_person_in_its_path():
    driver = ReferenceDriver(dt_s=0.1)
    obs = {"ego": np.array([10.0, 0.0, 1.0, 0.0, 0.0, 1000.0], np.float32),
           "neighbours": np.zeros((6, 6), np.float32), "path": np.zeros(3, np.float32)}
    driver.reset(obs)
    idm = IdmParams()
    assert driver.accelerations(obs, 3.5)[0] == pytest.approx(idm_accel(10.0, idm))
    person = {**obs, "path": np.array([1.0, 25.0, 0.4], np.float32)}
    lon = driver.accelerations(person, 3.5)[0]
    assert lon == pytest.approx(idm_accel(10.0, idm, 25.0, 0.0)) and lon < -1.0
    # A leader nearer than the person governs.
    both = {**person, "neighbours": obs["neighbours"].copy()}
    both["neighbours"][1] = (1.0, 12.0, 0.0, -10.0, 4.5, 1.8)
    assert driver.accelerations(both, 3.5)[0] == pytest.approx(idm_accel(10.0, idm, 12.0 - 4.5, 0.0))


def _person_on_the_crossing_ahead(env) -> str:
    """Put a person on the first pedestrian crossing the ego's route takes 15 m or more ahead, where it crosses the
    path's centre line, walking along the crossing at 5 cm/s (a person who walks is what SUMO checks for
    collisions; one on a stop is not): SUMO's own geometry of the network, no mock."""
    import libsumo

    inner = env.unwrapped
    path = inner.path_xy()
    best = None
    t = np.linspace(0.0, 1.0, 201)
    for lane in libsumo.lane.getIDList():
        if not is_crossing(lane):
            continue
        shape = np.array(libsumo.lane.getShape(lane))
        points = shape[0] + t[:, None] * (shape[-1] - shape[0])
        s, d, inside, _ = project_on_path(path, points)
        ok = inside & (np.abs(d) < 0.3) & (s > 15.0)
        if ok.any():
            k = np.flatnonzero(ok)[np.argmin(np.abs(d[ok]))]
            if best is None or s[k] < best[1]:
                best = (lane, s[k], points[k])
    assert best is not None, "no crossing on the ego's route within the path's range"
    lane, _, xy = best
    edge, pos, _ = libsumo.simulation.convertRoad(float(xy[0]), float(xy[1]), False, "pedestrian")
    assert is_crossing(edge), edge
    libsumo.person.add("blocker", edge, pos)
    libsumo.person.appendWalkingStage("blocker", [edge], min(pos + 2.0, libsumo.lane.getLength(lane)))
    libsumo.person.setSpeed("blocker", 0.05)
    return edge


def _drive_towards_the_person(blind: bool):
    import libsumo

    import pipeline.envs  # noqa: F401  (registers the envs)

    env = gym.make("roadsynth/Urban-v0", time_limit_s=25.0)
    try:
        obs, _ = env.reset(seed=2)
        _person_on_the_crossing_ahead(env)
        agent = ReferenceAgent(env)
        agent.reset(obs)
        seen, info = [], {}
        while True:
            if blind:
                obs = {**obs, "path": np.zeros(3, np.float32)}
            obs, _, terminated, truncated, info = env.step(agent.act(obs))
            if "blocker" in libsumo.person.getIDList() and obs["path"][0] == 1.0:
                fx, fy = libsumo.vehicle.getPosition(env.unwrapped.ego_id)
                px, py = libsumo.person.getPosition("blocker")
                straight = math.sqrt(max((px - fx) ** 2 + (py - fy) ** 2 - float(obs["path"][2]) ** 2, 0.0))
                seen.append((float(obs["path"][1]), straight, float(obs["ego"][0])))
            if terminated or truncated:
                return info, seen
    finally:
        env.close()


@pytest.mark.slow
def test_the_reference_agent_stops_for_a_person_on_a_crossing_where_a_blind_one_runs_them_down():
    info, seen = _drive_towards_the_person(blind=False)
    assert info["reason"] == "time_limit" and "collision" not in info
    assert len(seen) > 50
    # The row's distance is the person's along the straight approach (less their offset across it), less their reach.
    for distance, straight, _speed in seen:
        assert distance == pytest.approx(straight - PERSON_RADIUS_M, abs=0.15)
    stood = [distance for distance, _straight, speed in seen if speed < 0.01]
    assert len(stood) > 20  # it stood for 2 s or more ...
    assert all(IdmParams().min_gap_m - 0.5 < d < IdmParams().min_gap_m + 0.5 for d in stood)  # ... s0 short of them
    info, _ = _drive_towards_the_person(blind=True)
    assert info["reason"] == "collision"
    hit = info["collision"]
    assert (hit["other"], hit["other_kind"], hit["type"]) == ("blocker", "person", "crossing")


def test_in_the_city_the_nearby_rows_hold_vehicles_and_the_people_go_to_the_path_row():
    """Both context subscriptions (vehicles for "nearby", persons for "path") share SUMO's results: the persons'
    entries must not become nearby vehicles."""
    import libsumo

    import pipeline.envs  # noqa: F401  (registers the envs)

    env = gym.make("roadsynth/Urban-v0", time_limit_s=3.0, nearby_k=64)
    try:
        obs, _ = env.reset(seed=3)
        agent = ReferenceAgent(env)
        agent.reset(obs)
        for _ in range(20):
            obs, *_ = env.step(agent.act(obs))
            results = libsumo.vehicle.getContextSubscriptionResults(env.unwrapped.ego_id)
            people = [k for k in results if k in set(libsumo.person.getIDList())]
            rows = obs["nearby"][obs["nearby"][:, 0] == 1.0]
            assert people and len(rows) > 0
            assert (rows[:, 7] >= 1).all()  # a vehicle class, never the 0 a person would get
            assert len(rows) == min(64, len(results) - len(people) - 1)  # every vehicle but the ego, no person
    finally:
        env.close()


class LabelledPeople:
    """A detector that boxes exactly the frame's labelled people (tight boxes of >= 30 visible pixels), score 1."""

    def __init__(self, env) -> None:
        self.env = env

    def predict(self, rgbs):
        from pipeline.detect.infer import Detections

        labels = self.env.unwrapped._truth["labels"].to_pandas()
        cam = labels[(labels.sensor == "front") & labels.visible & (labels.visible_px >= 30)
                     & (labels.category_id == 1)]
        return [Detections(cam[["x1", "y1", "x2", "y2"]].to_numpy(float), np.ones(len(cam)),
                           cam.category_id.to_numpy(np.int64))]


@pytest.mark.slow
def test_perceived_a_person_crossing_the_ego_s_way_fills_the_path_row_where_the_ground_truth_has_them(
        small_default_rig):
    """Urban seed 3: a person walks over the crossing the ego turns across (YOLOX-nano missed him at night and the
    ego ran him down). Seen by a detector of the labelled people, ranged by the LiDAR and tracked, the perceived row
    holds him for at least 1 s, always where the ground truth's row has him (the ground truth's holds him earlier:
    walking in, on SUMO's velocity, before his track's is known)."""
    import pipeline.envs  # noqa: F401  (registers the envs)
    from pipeline.envs.perception import PerceivedFeatures

    # The closed loop's episode (its traffic depends on the episode's length: 30 s), driven for its first 7 s:
    # he walks into the path ~4.4 s in, 18 m ahead, and is past it at 6.7 s.
    env = gym.make("roadsynth/Urban-v0", time_limit_s=30.0, sensors=["camera", "lidar"], rig=small_default_rig)
    wrapped = PerceivedFeatures(env, LabelledPeople(env))
    try:
        obs, info = wrapped.reset(seed=3)
        agent = ReferenceAgent(wrapped)
        agent.reset(obs)
        rows = []
        while True:
            obs, _, terminated, truncated, info = wrapped.step(agent.act(obs))
            rows.append((obs["path"].copy(), info["ground_truth"]["path"].copy()))
            if terminated or truncated or len(rows) == 70:
                break
    finally:
        wrapped.close()
    assert "reason" not in info, info.get("collision")
    filled = [k for k, (seen, _) in enumerate(rows) if seen[0] == 1.0]
    assert len(filled) >= 10
    for k in filled:
        seen, gt = rows[k]
        assert gt[0] == 1.0 and seen[1] == pytest.approx(gt[1], abs=0.5)
