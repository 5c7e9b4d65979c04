"""People in wheelchairs (pipeline.world.wheelchairs): the chair stands on its wheels, the hands push on the rims in
phase, the person sits at a seated person's height, and the pose layout is a walking family's."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.world.gait import STAND_POSES, UMBRELLA_FIRST, UMBRELLA_POSES, WALK_PHASES
from pipeline.world.materials import material_index
from pipeline.world.people import FAMILIES, UMBRELLA_FAMILIES
from pipeline.world.wheelchairs import (
    CASTER_R_M,
    CASTER_X_M,
    PUSH_FROM_DEG,
    PUSH_SHARE,
    PUSH_TO_DEG,
    PUSHRIM_R_M,
    PUSHRIM_Y_M,
    WHEEL_R_M,
    WHEEL_X_M,
    WHEELCHAIRS,
    push_hands,
    push_lean_deg,
    seated_pose,
)


@pytest.mark.parametrize("family", WHEELCHAIRS, ids=lambda f: f.name)
def test_the_chair_stands_on_its_four_wheels_and_the_person_sits_at_a_seated_height(family):
    for pose in range(family.poses):
        mesh = family(pose)
        v = mesh.vertices
        assert v[:, 2].min() == 0.0
        tyres = v[mesh.triangles[mesh.material == material_index("rubber")].ravel()]
        for x, y, r in ((WHEEL_X_M, 0.3, WHEEL_R_M), (CASTER_X_M, 0.2, CASTER_R_M)):
            for side in (1.0, -1.0):  # each wheel's lowest point on the ground, below its axle
                near = tyres[(np.abs(tyres[:, 0] - x) < r) & (np.abs(tyres[:, 1] - side * y) < 0.03)]
                assert near[:, 2].min() < 5e-3  # (polygonal tyres)
        length, width, height = v.max(axis=0) - v.min(axis=0)
        # A manual wheelchair with its footrests ~0.8-1.1 m long and ~0.6-0.75 m wide (ISO 7176-5 measures of
        # everyday chairs); a seated adult of 1.75 m: the seat ~0.48 m up plus a sitting height of ~0.91 m (52 % of
        # the stature).
        assert 0.8 < length < 1.1 and 0.6 < width < 0.8 and 1.3 < height < 1.45
    assert len(family(0)) < 4500


def test_the_hands_push_on_the_rims_then_come_back_over_them():
    """Through the push share of the cycle each wrist grips its pushrim (within 1 cm of the rim's circle, at the
    angle the cycle gives, which runs from PUSH_FROM_DEG to PUSH_TO_DEG); then the hands come back above the rims."""
    for k in range(40):
        phase = k / 40
        angle, radius = push_hands(phase)
        body = seated_pose(push_lean_deg(phase), (angle, radius))
        for i, side in enumerate((1.0, -1.0)):
            d = body.wrists[i] - [WHEEL_X_M, side * PUSHRIM_Y_M, WHEEL_R_M]
            assert abs(d[1]) < 0.01
            if phase < PUSH_SHARE:
                assert PUSH_FROM_DEG <= angle <= PUSH_TO_DEG and radius == PUSHRIM_R_M
                assert abs(np.hypot(d[0], d[2]) - PUSHRIM_R_M) < 0.01
                assert abs(np.degrees(np.arctan2(d[0], d[2])) - angle) < 2.5
            else:
                assert np.hypot(d[0], d[2]) >= PUSHRIM_R_M - 1e-9
    angles = [push_hands(k / 40)[0] for k in range(40) if k / 40 < PUSH_SHARE]
    assert np.all(np.diff(angles) > 0)  # forward along the rim while pushing


def test_the_poses_follow_a_walking_familys_layout():
    """As many poses as a walking family (with umbrella poses in the rain's set, which hold none: the same meshes
    as the walking and still ones), and the arms moving through the push cycle."""
    walking = FAMILIES[0]
    rainy = next(f for f in UMBRELLA_FAMILIES if f.name == WHEELCHAIRS[0].name)
    assert WHEELCHAIRS[0].poses == walking.poses and rainy.poses == walking.poses + UMBRELLA_POSES
    for k in range(WALK_PHASES + STAND_POSES):
        np.testing.assert_array_equal(rainy(UMBRELLA_FIRST + k).vertices, WHEELCHAIRS[0](k).vertices)
    hands = {tuple(np.round(WHEELCHAIRS[0](k).vertices.max(axis=0), 3)) for k in range(WALK_PHASES)}
    assert len(hands) > WALK_PHASES // 2  # the arms move through the cycle
