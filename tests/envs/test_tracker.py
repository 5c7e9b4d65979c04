"""The perception tracker (pipeline/envs/tracker.py) on closed-form cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.envs.features import NEIGHBOUR_FIELDS, NEIGHBOUR_SLOTS
from pipeline.envs.tracker import (
    Detections,
    EgoPose,
    Tracker,
    TrackerParams,
    box_iou,
    lane_frame_tracks,
    track_neighbour_rows,
)

DT = 0.1


def _dets(*positions: tuple[float, float], boxes=None) -> Detections:
    k = len(positions)
    return Detections(np.array(positions, np.float64).reshape(k, 2),
                      np.full((k, 4), np.nan) if boxes is None else np.array(boxes, np.float64),
                      np.full(k, 3, np.int64), np.tile([4.5, 1.8], (k, 1)))


def test_a_constant_velocity_object_is_confirmed_and_its_velocity_found():
    tracker = Tracker(TrackerParams(dt_s=DT))
    out = []
    for k in range(40):
        out.append(tracker.update(_dets((30.0 - 2.0 * DT * k, 1.0 + 0.5 * DT * k))))
    assert [len(o) for o in out[:3]] == [0, 0, 1]  # confirmed at its third hit
    (track,) = out[-1]
    assert track.track_id == 1
    assert track.x[:2] == pytest.approx([30.0 - 2.0 * DT * 39, 1.0 + 0.5 * DT * 39], abs=0.02)
    assert track.x[2:] == pytest.approx([-2.0, 0.5], abs=0.05)


def test_a_missed_frame_is_coasted_and_too_many_drop_the_track():
    params = TrackerParams(dt_s=DT, max_misses=3, report_misses=3)
    tracker = Tracker(params)
    for k in range(20):
        tracker.update(_dets((20.0 + 1.0 * DT * k, 0.0)))
    (coasting,) = tracker.update(Detections.empty())  # missed: predicted one step on
    assert coasting.track_id == 1 and coasting.misses == 1
    assert coasting.x[0] == pytest.approx(20.0 + 1.0 * DT * 20, abs=0.02)
    (again,) = tracker.update(_dets((20.0 + 1.0 * DT * 21, 0.0)))
    assert again.track_id == 1 and again.misses == 0  # the same track takes the object back
    for _ in range(params.max_misses):
        assert len(tracker.update(Detections.empty())) == 1
    assert tracker.update(Detections.empty()) == []  # one miss more than max_misses
    assert tracker.tracks == []


def test_a_coasting_track_is_kept_but_reported_only_within_report_misses():
    """By default (report_misses 0, as SORT) a track that missed this frame is not reported, yet it coasts and takes
    its object back under its own id; with report_misses 1 it is reported through one miss, not two."""
    for report, shown in ((0, [1, 0, 0, 1]), (1, [1, 1, 0, 1])):
        tracker = Tracker(TrackerParams(dt_s=DT, max_misses=3, report_misses=report))
        for k in range(10):
            tracker.update(_dets((20.0 + DT * k, 0.0)))
        out = [tracker.update(_dets((21.0, 0.0))), tracker.update(Detections.empty()),
               tracker.update(Detections.empty()), tracker.update(_dets((21.0 + 3 * DT, 0.0)))]
        assert [len(o) for o in out] == shown
        assert len(tracker.tracks) == 1 and out[-1][0].track_id == 1


def test_two_crossing_objects_keep_their_identities():
    """Two objects 0.6 m apart along the road (less than the measurement's spread there) swap sides at 4 m/s
    across: their paths cross at k = 20, where only the velocities tell them apart."""
    tracker = Tracker(TrackerParams(dt_s=DT))
    history = {}
    for k in range(41):
        a = (25.0, -4.0 + 4.0 * DT * k)  # moves left
        b = (25.6, 4.0 - 4.0 * DT * k)  # moves right
        order = [a, b] if k % 2 == 0 else [b, a]  # detections come in no fixed order
        for t in tracker.update(_dets(*order)):
            history.setdefault(t.track_id, []).append((k, t.x[0], t.x[1]))
    assert sorted(history) == [1, 2]
    for rows in history.values():
        ds = np.array([r[1] for r in rows])
        assert np.ptp(ds) < 0.3  # each id stays on its own object (25 m or 25.6 m along the road)
        lateral = [r[2] for r in rows]
        assert abs(lateral[-1] - lateral[0]) > 6.0  # and followed it across


def test_a_false_detection_never_becomes_a_track():
    tracker = Tracker(TrackerParams(dt_s=DT))
    outputs = [tracker.update(_dets((40.0, 0.0))), *[tracker.update(Detections.empty()) for _ in range(5)]]
    assert all(o == [] for o in outputs)
    assert tracker.tracks == []


def test_image_boxes_associate_when_positions_jump_but_an_outlying_range_corrects_nothing():
    """A range that jumps (the LiDAR median on another surface) still matches through the image box's IoU, so no
    second track is born; outside the position gate it is an outlier: the track coasts on its prediction (a miss)
    and takes its object back at the next consistent range."""
    tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=1, report_misses=1))
    box = [100.0, 100.0, 160.0, 140.0]
    (first,) = tracker.update(_dets((30.0, 0.0), boxes=[box]))
    (second,) = tracker.update(_dets((45.0, 0.0), boxes=[[102.0, 100.0, 162.0, 140.0]]))
    assert (second.track_id, second.misses) == (first.track_id, 1)
    assert second.x.tolist() == [30.0, 0.0, 0.0, 0.0]  # predicted, not moved towards 45 m
    assert second.box_px.tolist() == [102.0, 100.0, 162.0, 140.0]  # the box follows the object
    (third,) = tracker.update(_dets((30.0, 0.0), boxes=[box]))
    assert (third.track_id, third.misses) == (first.track_id, 0)
    tracker2 = Tracker(TrackerParams(dt_s=DT, confirm_hits=1, report_misses=1))
    tracker2.update(_dets((30.0, 0.0)))
    coasting, new = tracker2.update(_dets((45.0, 0.0)))  # without boxes: a new track beside the coasting one
    assert (coasting.track_id, coasting.misses, new.track_id, new.misses) == (1, 1, 2, 0)


def test_a_range_that_stays_moved_ends_the_track_and_starts_one_there():
    """The box's object ranged at a new place on every frame (the first track was ranged on something else): the
    old track coasts max_misses frames, then a track starts at the new range; never a track moving at 150 m/s."""
    params = TrackerParams(dt_s=DT, confirm_hits=1, max_misses=2, report_misses=5)
    tracker = Tracker(params)
    box = [100.0, 100.0, 160.0, 140.0]
    tracker.update(_dets((30.0, 0.0), boxes=[box]))
    seen = [[(t.track_id, t.misses, t.x[0], t.x[2]) for t in tracker.update(_dets((45.0, 0.0), boxes=[box]))]
            for _ in range(4)]
    assert seen == [[(1, 1, 30.0, 0.0)], [(1, 2, 30.0, 0.0)], [(2, 0, 45.0, 0.0)], [(2, 0, 45.0, 0.0)]]


def test_a_tentative_track_confirms_on_consistent_positions_only():
    """A tentative track whose box's next range is an outlier is dropped and the detection starts a track of its
    own: three hits at consistent places confirm a track, three scattered ones do not."""
    tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=3))
    box = [100.0, 100.0, 160.0, 140.0]
    assert [tracker.update(_dets((x, 0.0), boxes=[box])) for x in (30.0, 45.0, 30.0)] == [[], [], []]
    assert [t.track_id for t in tracker.tracks] == [3]
    assert tracker.update(_dets((30.0, 0.0), boxes=[box])) == []
    (track,) = tracker.update(_dets((30.0, 0.0), boxes=[box]))
    assert (track.track_id, track.hits) == (3, 3)


def test_two_confirmed_tracks_of_one_object_are_merged_into_the_older():
    """One car boxed twice (the whole car and its right half), both ranged on it: the younger track is dropped. Nested
    boxes at another range, or boxes apart at the same range, or merge_overlap None, keep both."""
    whole, part = [100.0, 100.0, 160.0, 140.0], [135.0, 105.0, 158.0, 138.0]

    def run(second_place, second_box, merge_overlap=0.7):
        tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=2, merge_overlap=merge_overlap))
        tracker.update(_dets((30.0, 0.0), boxes=[whole]))
        tracker.update(_dets((30.0, 0.0), boxes=[whole]))
        out = []
        for _ in range(3):
            out = tracker.update(_dets((30.0, 0.0), second_place, boxes=[whole, second_box]))
        return [t.track_id for t in out]

    assert run((30.4, 0.3), part) == [1]
    assert run((45.0, 0.0), part) == [1, 2]  # a car farther away, seen over the first
    assert run((30.4, 0.3), [300.0, 100.0, 360.0, 140.0]) == [1, 2]
    assert run((30.4, 0.3), part, merge_overlap=None) == [1, 2]
    with pytest.raises(ValueError, match="merge_overlap"):
        TrackerParams(merge_overlap=0.0)


def test_the_same_detections_give_the_same_tracks():
    rng = np.random.default_rng(0)
    frames = [_dets(*[(float(x), float(y)) for x, y in rng.uniform(-20, 60, (rng.integers(0, 5), 2))])
              for _ in range(30)]

    def run():
        tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=2))
        return [[(t.track_id, *t.x.tolist()) for t in tracker.update(f)] for f in frames]

    assert run() == run()


def test_box_iou_closed_form():
    iou = box_iou(np.array([[0, 0, 10, 10]]), np.array([[5, 0, 15, 10], [20, 20, 30, 30], [np.nan] * 4]))
    assert iou.tolist() == [[pytest.approx(50 / 150), 0.0, 0.0]]
    smaller = box_iou(np.array([[0, 0, 10, 10]]), np.array([[5, 0, 15, 10], [2, 2, 4, 4], [8, 0, 18, 5]]),
                      over="smaller")
    assert smaller.tolist() == [[0.5, 1.0, pytest.approx(10 / 50)]]
    with pytest.raises(ValueError, match="over"):
        box_iou(np.zeros((1, 4)), np.zeros((1, 4)), over="area")


def test_tracks_fill_the_neighbour_slots_as_the_ground_truth_does():
    tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=1))
    # same lane ahead at 20 m and 35 m, left lane ahead at 10 m, right lane behind at -8 m, two lanes left: left out
    tracks = tracker.update(_dets((20.0, 0.2), (35.0, 0.0), (10.0, 3.4), (-8.0, -3.6), (15.0, 7.0)))
    rows = track_neighbour_rows(tracks, ego_lateral_offset_m=0.1, lane_width_m=3.5, range_m=100.0)
    col = {name: k for k, name in enumerate(NEIGHBOUR_FIELDS)}
    row = {slot: rows[k] for k, slot in enumerate(NEIGHBOUR_SLOTS)}
    assert row["leader"][col["ds_m"]] == pytest.approx(20.0)
    assert row["left_leader"][col["ds_m"]] == pytest.approx(10.0)
    assert row["right_follower"][col["ds_m"]] == pytest.approx(-8.0)
    for slot in ("right_leader", "left_follower", "follower"):
        assert not row[slot].any()
    assert row["leader"][col["present"]] == 1.0 and row["leader"][col["length_m"]] == pytest.approx(4.5)
    with pytest.raises(ValueError, match="lane_width_m"):
        track_neighbour_rows(tracks, 0.0, 0.0, 100.0)


def test_parameters_and_inputs_are_checked():
    with pytest.raises(ValueError, match="confirm_hits"):
        TrackerParams(confirm_hits=0)
    with pytest.raises(ValueError, match="gate_probability"):
        TrackerParams(gate_probability=1.0)
    with pytest.raises(ValueError, match="position_m"):
        _dets((float("nan"), 0.0))


def _scored(positions, scores) -> Detections:
    det = _dets(*positions)
    return Detections(det.position_m, det.box_px, det.class_id, det.size_m, np.array(scores, np.float64))


def test_weak_detections_keep_a_track_but_never_start_one():
    """ByteTrack's rule (birth_score 0.5): a weak detection (0.2) seen every frame never becomes a track; a car
    confirmed from confident ones stays tracked, and corrected, on weak ones; with birth_score 0 the weak one is
    tracked as before, and scores left out (None) count as confident."""
    params = TrackerParams(dt_s=DT, birth_score=0.5)
    tracker = Tracker(params)
    for _ in range(10):
        assert tracker.update(_scored([(40.0, 3.5)], [0.2])) == []  # a far lamp's glare, frame after frame
    assert tracker.tracks == []
    for k in range(5):
        tracker.update(_scored([(20.0 + DT * k, 0.0)], [0.8]))
    for k in range(5, 25):  # it fades: weak detections only, the object drifts away at 1 m/s
        (track,) = tracker.update(_scored([(20.0 + DT * k, 0.0)], [0.2]))
    assert track.track_id == 1  # the weak detections before it started none
    assert track.misses == 0 and track.x[0] == pytest.approx(20.0 + DT * 24, abs=0.05)
    assert track.x[2] == pytest.approx(1.0, abs=0.1)
    plain = Tracker(TrackerParams(dt_s=DT))
    for _ in range(3):
        out = plain.update(_scored([(40.0, 3.5)], [0.2]))
    assert len(out) == 1
    unscored = Tracker(params)
    for _ in range(3):
        out = unscored.update(_dets((40.0, 3.5)))
    assert len(out) == 1


def test_confident_detections_are_associated_before_weak_ones():
    """A track with a weak detection nearer its prediction and a confident one a little farther (both in its gate)
    takes the confident one; the weak one, left over, starts nothing. Without the rule it takes the nearer one and
    the confident one starts a track of its own."""
    def run(birth_score):
        tracker = Tracker(TrackerParams(dt_s=DT, birth_score=birth_score))
        for _ in range(5):
            tracker.update(_scored([(30.0, 0.0)], [0.9]))
        (track,) = [t for t in tracker.update(_scored([(30.05, 0.0), (30.6, 0.1)], [0.1, 0.9])) if t.confirmed]
        return tracker, track

    tracker, track = run(0.5)
    assert len(tracker.tracks) == 1 and track.x[0] > 30.2  # corrected towards the confident one
    tracker, track = run(0.0)
    assert len(tracker.tracks) == 2 and track.x[0] < 30.1


def test_birth_score_is_checked():
    with pytest.raises(ValueError, match="birth_score"):
        TrackerParams(birth_score=1.5)
    with pytest.raises(ValueError, match="score"):
        Detections(np.zeros((2, 2)), np.zeros((2, 4)), np.zeros(2, np.int64), np.zeros((2, 2)), np.zeros(3))


def _circle_pose(k: int, radius_m: float = 20.0, speed_mps: float = 5.0) -> EgoPose:
    """The ego driving a left-hand circle about the origin, at (radius, 0) heading +y at k = 0."""
    theta = speed_mps / radius_m * DT * k
    return EgoPose.moving(radius_m * math.cos(theta), radius_m * math.sin(theta), theta + math.pi / 2, speed_mps)


def _ego_frame(pose: EgoPose, point: tuple[float, float]) -> tuple[float, float]:
    dx, dy = point[0] - pose.x_m, point[1] - pose.y_m
    c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    return c * dx + s * dy, -s * dx + c * dy


def test_tracks_are_read_in_the_ego_lane_frame_in_closed_form():
    """An ego at (10, 5) heading +y at 5 m/s, turned 90 deg left of its lane (the lane runs along +x): a car at rest
    10 m ahead of it lies 10 m to the lane's left, and closes at 5 m/s across it, none along it."""
    pose = EgoPose.moving(10.0, 5.0, math.pi / 2, 5.0)
    tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=1))
    (track,) = tracker.update(_dets((10.0, 0.0)), pose)
    assert track.x[:2] == pytest.approx([10.0, 15.0])  # the fixed frame
    track.x[2:] = 0.0  # at rest there
    (rel,) = lane_frame_tracks([track], pose, heading_rel_rad=math.pi / 2, speed_mps=5.0)
    assert rel.x == pytest.approx([0.0, 10.0, -5.0, -5.0])
    assert rel.track_id == track.track_id and track.x[:2] == pytest.approx([10.0, 15.0])  # the track is untouched


def test_a_turning_ego_sees_a_parked_car_at_rest_and_a_leader_on_its_circle():
    """The ego drives a 20 m circle at 5 m/s (0.25 rad/s, a junction's turn); a parked car stands 25 m ahead of its
    start, and a leader drives the same circle 15 m of arc ahead at the same speed. With the ego's pose the tracker
    finds the parked car at rest and the leader at its own speed along its way, and reads both as the ground-truth
    features would (dv along the ego's lane less its speed); in the ego's own turning frame, taken as fixed, the
    parked car seems to slide sideways at 2 m/s."""
    parked = (20.0, 25.0)
    lead = 15.0 / 20.0  # the leader's angle ahead on the circle
    with_pose, turning = Tracker(TrackerParams(dt_s=DT)), Tracker(TrackerParams(dt_s=DT))
    for k in range(30):
        pose = _circle_pose(k)
        theta = 5.0 / 20.0 * DT * k + lead
        seen = [_ego_frame(pose, parked), _ego_frame(pose, (20.0 * math.cos(theta), 20.0 * math.sin(theta)))]
        tracks = with_pose.update(_dets(*seen), pose)
        naive = turning.update(_dets(*seen))
    car, leader = sorted(tracks, key=lambda t: t.track_id)
    assert np.hypot(*car.x[2:]) < 0.3
    assert np.hypot(*leader.x[2:]) == pytest.approx(5.0, abs=0.3)
    rel_car, rel_leader = lane_frame_tracks([car, leader], pose, heading_rel_rad=0.0, speed_mps=5.0)
    assert rel_car.x[2:] == pytest.approx([-5.0, 0.0], abs=0.3)
    # the leader's heading is 0.75 rad from the ego's: along the ego's lane it moves at 5 cos(0.75); a constant-
    # velocity filter lags the turn of its velocity (1.25 m/s^2 towards the circle's centre) by a few tenths of m/s
    assert rel_leader.x[2] == pytest.approx(5.0 * math.cos(lead) - 5.0, abs=0.5)
    assert rel_leader.x[:2] == pytest.approx(_ego_frame(pose, (20.0 * math.cos(theta), 20.0 * math.sin(theta))),
                                             abs=0.1)
    naive_car = min(naive, key=lambda t: t.track_id)
    # the parked car "moves" across the ego's frame at the turn rate times its distance ahead (~2 m/s here)
    assert abs(naive_car.x[3]) > 1.5


def test_a_track_is_born_moving_as_the_ego_or_standing():
    """From a moving ego (10 m/s along +x), a first sighting is born at the ego's velocity (traffic ahead), or at
    rest with birth_with_ego False (a person), in the fixed frame."""
    pose = EgoPose.moving(0.0, 0.0, 0.0, 10.0)
    for with_ego, velocity in ((True, [10.0, 0.0]), (False, [0.0, 0.0])):
        tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=1, birth_with_ego=with_ego))
        (track,) = tracker.update(_dets((12.0, 1.0)), pose)
        assert track.x.tolist() == [12.0, 1.0, *velocity]
    with pytest.raises(ValueError, match="birth_with_ego"):
        TrackerParams(birth_with_ego=1)


def test_without_the_iou_gate_a_box_does_not_drag_a_track_to_a_jumped_range():
    """iou_gate None (people): the same box ranged 15 m farther (the background behind a sliver of a person) starts
    a tentative track of its own; the person's track coasts and takes its object back the frame after."""
    tracker = Tracker(TrackerParams(dt_s=DT, confirm_hits=1, iou_gate=None, report_misses=1))
    box = [100.0, 100.0, 110.0, 140.0]
    (first,) = tracker.update(_dets((12.0, 0.0), boxes=[box]))
    (coasting, jumped) = tracker.update(_dets((27.0, 0.0), boxes=[box]))
    assert (coasting.track_id, coasting.misses, coasting.x[0]) == (first.track_id, 1, 12.0)
    assert jumped.track_id != first.track_id
    back = [t for t in tracker.update(_dets((12.0, 0.0), boxes=[box])) if t.track_id == first.track_id]
    assert len(back) == 1 and back[0].misses == 0
    with pytest.raises(ValueError, match="iou_gate"):
        TrackerParams(iou_gate=1.5)
