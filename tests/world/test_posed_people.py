"""People posed through the walk cycle: the phase from the distance walked, and boxes that enclose the posed body in
every pose (the labels' boxes are these boxes)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actors import ActorMeshes, Actors, actor_variants, place_actors, umbrella_meshes
from pipeline.world.gait import (
    MODEL_STATURE_M,
    RUN_ABOVE_MPS,
    RUN_PHASES,
    STAND_POSES,
    STANDING_BELOW_MPS,
    UMBRELLA_FIRST,
    UMBRELLA_POSES,
    WALK_BELOW_MPS,
    WALK_PHASES,
    gait_poses,
    run_clearance_m,
    run_phase,
    running_pose,
    running_rows,
    stride_m,
    walking_pose,
)
from pipeline.world.people import FAMILIES, PEDESTRIANS, STATURE_M, person_statures
from pipeline.world.posed_people import posed_boxes, umbrella_carriers

MESHES = ActorMeshes()


def test_stride_follows_alexanders_relation():
    # stride = 2.3 h (v^2 / (g h))^0.3 with h = 0.53 x stature: 1.75 m at 1.34 m/s, worked by hand.
    h = 0.53 * 1.75
    assert stride_m(np.array([1.34]), np.array([1.75]))[0] == pytest.approx(2.3 * h * (1.34**2 / (9.81 * h)) ** 0.3)
    assert 1.2 < stride_m(np.array([1.34]), np.array([1.75]))[0] < 1.5
    assert stride_m(np.array([0.0]), np.array([1.75]))[0] == 0.0


def test_phase_advances_with_the_distance_walked():
    """At a constant speed the phase index steps through the cycle at speed / stride cycles per second; a person
    slower than STANDING_BELOW_MPS stands (the standing poses); the result does not depend on the rows' order."""
    t = np.arange(0.0, 4.0, 0.1)
    v = np.full(len(t), 1.3)
    cycles_per_s = 1.3 / stride_m(np.array([1.3]), np.array([1.7]))[0]
    pose = gait_poses(np.full(len(t), 7), t, v, np.full(len(t), 1.7), np.full(len(t), 0.25))
    expected = np.floor(np.mod(0.25 + cycles_per_s * t, 1.0) * WALK_PHASES) % WALK_PHASES
    assert np.mean(pose == expected) > 0.95  # the trapezoids round the same as t x rate but for float ties
    assert set(pose.tolist()) == set(range(WALK_PHASES))
    standing = gait_poses(np.full(len(t), 7), t, np.full(len(t), 0.5 * STANDING_BELOW_MPS), np.full(len(t), 1.7),
                          np.full(len(t), 0.25))
    assert set(standing.tolist()) <= set(range(WALK_PHASES, WALK_PHASES + STAND_POSES))
    # Two people's rows shuffled give each the same poses.
    rng = np.random.default_rng(0)
    tid = np.r_[np.full(len(t), 7), np.full(len(t), 9)]
    tt, vv = np.r_[t, t], np.r_[v, np.full(len(t), 0.9)]
    both = gait_poses(tid, tt, vv, np.full(2 * len(t), 1.7), np.r_[np.full(len(t), 0.25), np.zeros(len(t))])
    order = rng.permutation(len(tid))
    shuffled = gait_poses(tid[order], tt[order], vv[order], np.full(2 * len(t), 1.7),
                          np.r_[np.full(len(t), 0.25), np.zeros(len(t))][order])
    np.testing.assert_array_equal(shuffled, both[order])
    np.testing.assert_array_equal(both[: len(t)], pose)


def test_the_torso_bobs_and_the_arms_swing_against_the_legs():
    """Through the cycle the pelvis rises and falls (a few cm, twice per cycle), and at the left heel strike the left
    foot is ahead and the left hand behind (the right hand ahead)."""
    poses = [walking_pose(k / 16) for k in range(16)]
    hip_z = np.array([p.pelvis[2] for p in poses])
    assert 0.02 < hip_z.max() - hip_z.min() < 0.08
    strike = poses[0]
    assert strike.ankles[0, 0] > strike.ankles[1, 0] + 0.3
    assert strike.wrists[0, 0] < strike.wrists[1, 0] - 0.1


RUNNING = range(WALK_PHASES + STAND_POSES, WALK_PHASES + STAND_POSES + RUN_PHASES)


def test_a_runner_starts_above_the_threshold_and_walks_again_below_the_lower_one():
    """The gait changes with a hysteresis: a walker runs from the first row faster than RUN_ABOVE_MPS, a runner walks
    again from the first one slower than WALK_BELOW_MPS, in between the gait stays; each track starts walking; the
    rows' order does not matter."""
    lo, hi, mid = WALK_BELOW_MPS, RUN_ABOVE_MPS, 0.5 * (WALK_BELOW_MPS + RUN_ABOVE_MPS)
    v = np.array([1.4, mid, hi + 0.1, mid, mid, lo - 0.1, mid, hi + 0.5, 0.0])
    expected = np.array([0, 0, 1, 1, 1, 0, 0, 1, 0], bool)
    t = 0.1 * np.arange(len(v))
    np.testing.assert_array_equal(running_rows(np.full(len(v), 3), t, v), expected)
    # Two tracks, the second starting in between (walks), rows shuffled.
    tid = np.r_[np.full(len(v), 3), np.full(3, 4)]
    tt, vv = np.r_[t, 0.1 * np.arange(3)], np.r_[v, mid, hi + 0.1, mid]
    both = np.r_[expected, [False, True, True]]
    order = np.random.default_rng(1).permutation(len(tid))
    np.testing.assert_array_equal(running_rows(tid[order], tt[order], vv[order]), both[order])
    # At a runner's speed the poses are the running ones, at the same phase rate as walking.
    t = np.arange(0.0, 3.0, 0.05)
    pose = gait_poses(np.full(len(t), 7), t, np.full(len(t), 3.0), np.full(len(t), 1.75), np.full(len(t), 0.25))
    assert set(pose.tolist()) == set(RUNNING)
    cycles_per_s = 3.0 / stride_m(np.array([3.0]), np.array([1.75]))[0]
    expected = RUNNING[0] + np.floor(np.mod(0.25 + cycles_per_s * t, 1.0) * RUN_PHASES) % RUN_PHASES
    assert np.mean(pose == expected) > 0.95


def test_a_runner_floats_between_steps_with_bent_arms_and_knees():
    """Running (Novacheck 1998): a foot is on the ground until 39 % of its cycle, so two of the eight sampled poses are
    in the float, both soles off the ground; the mesh's lowest sole is where the pose puts it; the pelvis rises and
    falls 5-12 cm; the elbows stay bent near 90 deg and the swinging knee bends beyond 90 deg (walking: ~60)."""
    phases = [run_phase(i) for i in RUNNING]
    clearance = np.array([run_clearance_m(p) for p in phases])
    assert (clearance > 0.02).sum() == 2 and (clearance[clearance <= 0.02] == 0.0).all()
    family = FAMILIES[0]
    for i, c in zip(RUNNING, clearance, strict=True):
        assert family(i).vertices[:, 2].min() == pytest.approx(c, abs=1e-9)
    poses = [running_pose(k / 32) for k in range(32)]
    hip_z = np.array([p.pelvis[2] for p in poses])
    assert 0.05 < hip_z.max() - hip_z.min() < 0.12

    def angle(a, b, c):
        u, w = a - b, c - b
        return np.degrees(np.arccos(u @ w / np.linalg.norm(u) / np.linalg.norm(w)))

    elbows = [180.0 - angle(p.shoulders[i], p.elbows[i], p.wrists[i]) for p in poses for i in range(2)]
    knees = [180.0 - angle(p.hips[i], p.knees[i], p.ankles[i]) for p in poses for i in range(2)]
    walk_knees = [180.0 - angle(p.hips[i], p.knees[i], p.ankles[i]) for p in map(walking_pose, np.arange(32) / 32)
                  for i in range(2)]
    assert min(elbows) > 70.0 and max(elbows) < 110.0
    assert max(knees) > 95.0 > max(walk_knees) + 20.0


def test_statures_follow_their_group():
    n = 2000
    track = np.arange(1, n + 1)
    for group, (mean, sd, low, high) in STATURE_M.items():
        h = person_statures(np.full(n, group), track, seed=3)
        assert low <= h.min() and h.max() <= high
        if group != "child":
            assert h.mean() == pytest.approx(mean, abs=0.01) and h.std() == pytest.approx(sd, rel=0.15)
        np.testing.assert_array_equal(person_statures(np.full(n, group), track, seed=3), h)
    child = person_statures(np.full(n, "child"), track, seed=3)
    assert 1.25 < child.mean() < 1.42


def _person_rows(n_frames: int = 40, speed_mps: float = 1.3, people: int = 24):
    """A straight walk of ``people`` persons of every family (variants chosen so), on ground at z = 2 m."""
    tracks = np.arange(1, people + 1)
    variant = actor_variants(tracks, 5)
    boxes = Boxes3D(np.zeros((people, 3)), np.tile([0.215, 0.478, 1.719], (people, 1)), np.zeros(people))
    actors = Actors(tracks, ["pedestrian"] * people, boxes, np.zeros((people, 3)), variant=variant)
    row_actor = np.repeat(np.arange(people), n_frames)
    t = np.tile(np.arange(n_frames) * 0.1, people)
    yaw = np.repeat(np.linspace(-3.0, 3.0, people), n_frames)
    x = t * speed_mps * np.cos(yaw) + 10.0 * row_actor
    y = t * speed_mps * np.sin(yaw)
    center = np.column_stack([x, y, np.full(len(x), 2.0 + 1.719 / 2)])
    rows = Boxes3D(center, np.tile([0.215, 0.478, 1.719], (len(x), 1)), yaw)
    return actors, row_actor, t, np.full(len(x), speed_mps), rows


UMBRELLA = range(UMBRELLA_FIRST, UMBRELLA_FIRST + UMBRELLA_POSES)


def test_umbrellas_are_drawn_once_per_person():
    """Each person carries one with probability ``share`` (binomial over 4000), the same draw for a track in any
    order and call; share 0 nobody, 1 everybody; another seed draws others."""
    track = np.arange(1, 4001)
    carries = umbrella_carriers(track, 5, 0.6)
    assert abs(carries.mean() - 0.6) < 4 * np.sqrt(0.24 / 4000)
    order = np.random.default_rng(2).permutation(len(track))
    np.testing.assert_array_equal(umbrella_carriers(track[order], 5, 0.6), carries[order])
    assert not umbrella_carriers(track, 5, 0.0).any() and umbrella_carriers(track, 5, 1.0).all()
    assert (umbrella_carriers(track, 6, 0.6) != carries).mean() > 0.3


@pytest.mark.parametrize(("speed_mps", "umbrellas"), [(1.3, 0.0), (0.0, 0.0), (3.0, 0.0), (1.3, 1.0), (0.0, 1.0),
                                                      (3.0, 1.0)])
def test_boxes_enclose_the_posed_body_in_every_pose(speed_mps, umbrellas):
    """Each row's box holds its posed, placed mesh exactly (it touches all six faces): the 3D label encloses the body
    in every phase of the gait, standing and running, and the umbrella over it in the rain (runners carry none); the
    feet are on the ground (a runner's lower sole its clearance above it in the float), the pelvis over the
    trajectory point, and the body as tall as its stature in the pose (with the umbrella's canopy, ~1.18 x)."""
    actors, row_actor, t, v, rows = _person_rows(speed_mps=speed_mps)
    meshes = umbrella_meshes() if umbrellas else MESHES
    boxes, pose = posed_boxes(meshes, actors, row_actor, t, v, rows, seed=5, umbrellas=umbrellas)
    expected = {1.3: set(range(WALK_PHASES)), 0.0: set(range(WALK_PHASES, WALK_PHASES + STAND_POSES)),
                3.0: set(RUNNING)}[speed_mps]
    if umbrellas and speed_mps != 3.0:
        expected = {UMBRELLA_FIRST + p for p in expected}
    assert set(pose.tolist()) == expected
    per_row = Actors(np.arange(1, len(pose) + 1), ["pedestrian"] * len(pose), boxes, np.zeros((len(pose), 3)),
                     variant=actors.variant[row_actor], pose=pose)
    geo = place_actors(per_row, meshes)
    family = meshes.family_codes(actors)
    stature = person_statures(np.array([meshes.families[f].group for f in family]), actors.track_id, 5)
    for k in range(0, len(pose), 3 if speed_mps == 3.0 or umbrellas else 7):
        v_world = geo.vertices[geo.vertex_actor == k] - boxes.center[k]
        c, s = np.cos(boxes.yaw_rad[k]), np.sin(boxes.yaw_rad[k])
        local = np.column_stack([c * v_world[:, 0] + s * v_world[:, 1], -s * v_world[:, 0] + c * v_world[:, 1],
                                 v_world[:, 2]])
        np.testing.assert_allclose(local.min(axis=0), -0.5 * boxes.size[k], atol=1e-6)
        np.testing.assert_allclose(local.max(axis=0), 0.5 * boxes.size[k], atol=1e-6)
        a = row_actor[k]
        lift = run_clearance_m(run_phase(pose[k])) if pose[k] in RUNNING else 0.0
        assert boxes.center[k, 2] - 0.5 * boxes.size[k, 2] == pytest.approx(2.0 + lift * stature[a] / MODEL_STATURE_M,
                                                                             abs=0.01)  # soles on the ground
        model = meshes.family_models(family[a:a + 1], pose[k:k + 1])[0]
        scale = stature[a] / MODEL_STATURE_M
        pelvis_unit = -(meshes.model_low[model][:2] + 0.5 * meshes.model_extent[model][:2]) / meshes.model_extent[
            model][:2]  # the pelvis (x = y = 0 as modelled) in the unit box
        pelvis = boxes.center[k, :2] + [c * pelvis_unit[0] * boxes.size[k, 0] - s * pelvis_unit[1] * boxes.size[k, 1],
                                        s * pelvis_unit[0] * boxes.size[k, 0] + c * pelvis_unit[1] * boxes.size[k, 1]]
        np.testing.assert_allclose(pelvis, rows.center[k, :2], atol=1e-9)
        assert boxes.size[k, 2] == pytest.approx(meshes.model_extent[model][2] * scale)
        low, high = (1.12, 1.25) if pose[k] in UMBRELLA else (0.9, 1.05)
        assert low * stature[a] < boxes.size[k, 2] < high * stature[a]


def test_every_family_is_picked_and_others_keep_their_boxes():
    """Persons' families cover all of PEDESTRIANS (the walking families and the wheelchair users); a car's row keeps
    its box and pose 0."""
    people = 400
    tracks = np.arange(1, people + 2)
    classes = ["pedestrian"] * people + ["car"]
    sizes = np.tile([0.215, 0.478, 1.719], (people + 1, 1))
    sizes[-1] = [4.5, 1.8, 1.5]
    boxes = Boxes3D(np.zeros((people + 1, 3)), sizes, np.zeros(people + 1))
    actors = Actors(tracks, classes, boxes, np.zeros((people + 1, 3)), variant=actor_variants(tracks, 9))
    names = {MESHES.families[f].__name__ for f in MESHES.family_codes(actors)[:people]}
    assert names == {f.name for f in PEDESTRIANS}
    out, pose = posed_boxes(MESHES, actors, np.arange(people + 1), np.zeros(people + 1), np.ones(people + 1), boxes, 9)
    np.testing.assert_array_equal(out.size[-1], [4.5, 1.8, 1.5])
    assert pose[-1] == 0 and MESHES.model_class[MESHES.model_codes(actors)[-1]] == ObjectClass.CAR


def test_wheelchair_users_are_their_share_and_leave_everyone_else_their_family():
    """A family with a share (the wheelchair users, 0.5 % each) is picked by a draw of its own: over 40,000 people
    each is within binomial bounds of its share, and every other person, but for the pram pushers (the other families
    with a share: tests/world/test_prams.py), has the family they have without them."""
    from pipeline.world.prams import PRAM_PUSHERS
    from pipeline.world.wheelchairs import WHEELCHAIRS

    n = 40000
    tracks = np.arange(1, n + 1)
    boxes = Boxes3D(np.zeros((n, 3)), np.tile([0.215, 0.478, 1.719], (n, 1)), np.zeros(n))
    actors = Actors(tracks, ["pedestrian"] * n, boxes, np.zeros((n, 3)), variant=actor_variants(tracks, 4))
    names = np.array([MESHES.families[f].__name__ for f in MESHES.family_codes(actors)])
    walking = ActorMeshes(families={ObjectClass.PEDESTRIAN: FAMILIES})
    without = np.array([walking.families[f].__name__ for f in walking.family_codes(actors)])
    rare = np.isin(names, [f.name for f in WHEELCHAIRS + PRAM_PUSHERS])
    for family in WHEELCHAIRS:
        share = np.mean(names == family.name)
        assert abs(share - family.share) < 4 * np.sqrt(family.share * (1 - family.share) / n)
    np.testing.assert_array_equal(names[~rare], without[~rare])
    assert set(without) == {f.name for f in FAMILIES}


def test_a_bicycles_cranks_turn_with_the_distance_ridden():
    """At 5 m/s a bicycle with a 5 m development turns its cranks once a second: over 2 s sampled at 10 Hz every
    pose appears, in order; stopped, the cranks stay; its box stays as simulated."""
    from pipeline.world.gait import crank_poses
    from pipeline.world.two_wheelers import CRANK_PHASES, DEVELOPMENT_M

    t = np.arange(0.0, 2.0, 0.1)
    pose = crank_poses(np.full(len(t), 3), t, np.full(len(t), DEVELOPMENT_M), DEVELOPMENT_M, CRANK_PHASES,
                       np.full(len(t), 0.01))
    np.testing.assert_array_equal(pose, np.floor(np.mod(t + 0.01, 1.0) * CRANK_PHASES))
    stopped = crank_poses(np.full(len(t), 3), t, np.zeros(len(t)), DEVELOPMENT_M, CRANK_PHASES, np.full(len(t), 0.3))
    assert set(stopped.tolist()) == {2}
    boxes = Boxes3D(np.zeros((len(t), 3)), np.tile([1.75, 0.65, 1.7], (len(t), 1)), np.zeros(len(t)))
    bike = Actors([3], ["bicycle"], Boxes3D(np.zeros((1, 3)), [[1.75, 0.65, 1.7]], np.zeros(1)), np.zeros((1, 3)),
                  variant=[0])
    out, got = posed_boxes(MESHES, bike, np.zeros(len(t), np.int64), t, np.full(len(t), DEVELOPMENT_M), boxes, 1)
    np.testing.assert_array_equal(out.size, boxes.size)
    assert len(set(got.tolist())) == CRANK_PHASES
