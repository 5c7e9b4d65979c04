"""Prams and their pushers (pipeline.world.prams): the stroller stands on its four wheels and fills its stated size with
the handle where it says; the pusher walks as a walker does with both hands on the handle in every pose, in a walking
family's layout of poses; pushers are their share of the pedestrians and leave everyone else's family as it was."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actors import ActorMeshes, Actors, actor_variants
from pipeline.world.figures import FOREARM_M, UPPER_ARM_M, figure
from pipeline.world.gait import (
    MODEL_STATURE_M,
    RUN_PHASES,
    STAND_POSES,
    UMBRELLA_FIRST,
    UMBRELLA_POSES,
    WALK_PHASES,
    run_phase,
    standing_pose,
    walking_pose,
)
from pipeline.world.materials import material_index
from pipeline.world.people import FAMILIES, PEDESTRIANS, STATURE_M, UMBRELLA_FAMILIES
from pipeline.world.prams import (
    FRONT_R_M,
    FRONT_X_M,
    FRONT_Y_M,
    GRIP_R_M,
    HAND_X_M,
    PRAM_PUSHERS,
    REAR_R_M,
    REAR_X_M,
    REAR_Y_M,
    STROLLER_COLOR_TAG,
    STROLLER_COLORS,
    STROLLER_HANDLE_X_M,
    STROLLER_HANDLE_Z_M,
    STROLLER_SIZE_M,
    STROLLERS,
    grips,
    pusher_pose,
    stroller_colors,
    stroller_offset_m,
)
from pipeline.world.solids import merge
from pipeline.world.wheelchairs import WHEELCHAIRS

RAINY = tuple(f for f in UMBRELLA_FAMILIES if getattr(f, "pram", False))


@pytest.mark.parametrize("family", STROLLERS, ids=lambda f: f.name)
def test_the_stroller_stands_on_four_wheels_and_fills_its_size(family):
    """The lowest point of each of the four tyres is on the ground; the mesh spans STROLLER_SIZE_M, centred on
    x = y = 0; its rearmost and highest points are the handle's grip, at STROLLER_HANDLE_X/Z_M; the hood is over the
    back half of the body."""
    mesh = family()
    v = mesh.vertices
    assert mesh.semantic == ObjectClass.STROLLER.semantic and v[:, 2].min() == 0.0
    tyres = v[mesh.triangles[mesh.material == material_index("rubber")].ravel()]
    for x, y, r in ((REAR_X_M, REAR_Y_M, REAR_R_M), (FRONT_X_M, FRONT_Y_M, FRONT_R_M)):
        for side in (1.0, -1.0):
            near = tyres[(np.abs(tyres[:, 0] - x) < r) & (np.abs(tyres[:, 1] - side * y) < 0.03)]
            assert len(near) and near[:, 2].min() < 1e-9
    lo, hi = v.min(axis=0), v.max(axis=0)
    np.testing.assert_allclose(hi - lo, STROLLER_SIZE_M, atol=1e-9)
    np.testing.assert_allclose(0.5 * (lo + hi)[:2], [0.0, 0.0], atol=1e-9)
    rear, top = v[np.argmin(v[:, 0])], v[np.argmax(v[:, 2])]
    assert rear[0] == pytest.approx(STROLLER_HANDLE_X_M - GRIP_R_M) and rear[2] == pytest.approx(STROLLER_HANDLE_Z_M)
    assert top[0] == pytest.approx(STROLLER_HANDLE_X_M) and top[2] == pytest.approx(STROLLER_HANDLE_Z_M + GRIP_R_M)
    fabric = v[mesh.triangles[mesh.material == material_index("garment")].ravel()]
    hood = fabric[fabric[:, 2] > 0.85]
    assert len(hood) and hood[:, 0].max() < 0.12  # the body runs from x = -0.25 to 0.47 (0.4 for a pushchair)


def _shift(family, pose: int) -> float:
    """How far the family's mesh of ``pose`` was lowered to put its lower sole on the ground."""
    return float(merge(figure(pusher_pose(pose, family.grip_stature_m), family.outfit),
                       ObjectClass.PEDESTRIAN).vertices[:, 2].min())


@pytest.mark.parametrize("family", PRAM_PUSHERS + RAINY, ids=lambda f: f.name + ("_rain" if f.umbrella else ""))
def test_both_hands_hold_the_handle_in_every_pose(family):
    """In every pose each wrist, as the mesh has it, is within 3 cm of its grip on the handle (HAND_X_M ahead of the
    pelvis, 0.2 m to its side, at the height where the handle bar is for a person of the family's grip stature: the
    group's mean); the elbows are bent (the wrist nearer the shoulder than the arm's length), the bones keep their
    lengths; the lower sole is on the ground."""
    assert family.grip_stature_m == STATURE_M[family.group][0]
    np.testing.assert_array_equal(grips(), [[HAND_X_M, y, STROLLER_HANDLE_Z_M] for y in (0.2, -0.2)])
    grip = grips(family.grip_stature_m)
    np.testing.assert_allclose(grip[:, 2] * family.grip_stature_m / MODEL_STATURE_M, STROLLER_HANDLE_Z_M, atol=1e-12)
    for pose in range(family.poses):
        p = pusher_pose(pose, family.grip_stature_m)
        wrists = p.wrists - [0.0, 0.0, _shift(family, pose)]
        assert np.linalg.norm(wrists - grip, axis=1).max() < 0.03
        np.testing.assert_allclose(np.linalg.norm(p.elbows - p.shoulders, axis=1), UPPER_ARM_M, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(p.wrists - p.elbows, axis=1), FOREARM_M, atol=1e-9)
        assert np.linalg.norm(p.wrists - p.shoulders, axis=1).max() < 0.97 * (UPPER_ARM_M + FOREARM_M)
        assert p.elbows[:, 2].max() < p.shoulders[:, 2].min() and p.elbows[:, 2].min() > p.wrists[:, 2].max()
        assert family(pose).vertices[:, 2].min() == 0.0


def test_the_legs_walk_and_stand_as_a_walkers():
    """Walking poses' legs and pelvis are walking_pose's at the pose's phase, standing ones standing_pose's, the
    "running" ones (a brisk walk) walking_pose's at the running poses' phases; the trunk leans further forward."""
    legs = ("pelvis", "hips", "knees", "ankles", "feet")
    for pose in range(WALK_PHASES + STAND_POSES + RUN_PHASES):
        if pose < WALK_PHASES:
            walker = walking_pose(pose / WALK_PHASES)
        elif pose < WALK_PHASES + STAND_POSES:
            walker = standing_pose(pose - WALK_PHASES)
        else:
            walker = walking_pose(run_phase(pose))
        p = pusher_pose(pose)
        for name in legs:
            np.testing.assert_allclose(getattr(p, name), getattr(walker, name), atol=1e-12, err_msg=f"{pose} {name}")
        assert p.chest[0] > walker.chest[0] + 0.03  # leaning a few degrees more (0.52 m from the pelvis)


def test_the_poses_follow_a_walking_familys_layout():
    """As many poses as a walking family's, with the umbrella poses in the rain's set (the same meshes as the walking
    and standing ones: both hands are on the handle); the family says it pushes a pram, the others do not."""
    walking = FAMILIES[0]
    for family, rainy in zip(PRAM_PUSHERS, RAINY, strict=True):
        assert family.poses == walking.poses and rainy.poses == walking.poses + UMBRELLA_POSES
        assert family.pram and rainy.pram and rainy.name == family.name
        for k in (0, 5, WALK_PHASES + 1):
            np.testing.assert_array_equal(rainy(UMBRELLA_FIRST + k).vertices, family(k).vertices)
    assert not any(getattr(f, "pram", False) for f in FAMILIES + WHEELCHAIRS)
    assert PEDESTRIANS == FAMILIES + WHEELCHAIRS + PRAM_PUSHERS


@pytest.mark.parametrize("stature", [1.55, 1.9])
def test_the_stroller_offset_puts_the_handle_in_the_hands(stature):
    """A pusher of ``stature`` (its model scaled by stature / MODEL_STATURE_M) with its stroller's box centre
    stroller_offset_m ahead of its pelvis: the handle bar's axis is at the hands' grip, HAND_X_M scaled (closed form),
    and the placed stroller's rearmost point GRIP_R_M behind it."""
    offset = stroller_offset_m(np.array([stature]))[0]
    grip_x = HAND_X_M * stature / MODEL_STATURE_M
    assert offset + STROLLER_HANDLE_X_M == pytest.approx(grip_x, abs=1e-12)
    assert offset - 0.5 * STROLLER_SIZE_M[0] == pytest.approx(grip_x - GRIP_R_M, abs=1e-12)
    stroller = STROLLERS[0]().vertices + [offset, 0.0, 0.0]
    assert stroller[:, 0].min() == pytest.approx(grip_x - GRIP_R_M, abs=1e-9)
    wrist_x = pusher_pose(0).wrists[:, 0] * stature / MODEL_STATURE_M
    np.testing.assert_allclose(wrist_x, grip_x, atol=0.03)


def test_pushers_are_their_share_and_leave_everyone_else_their_family():
    """Over 40,000 people each pusher family is within binomial bounds of its share (1 %); the wheelchair users and
    every other person have the family they have without the pushers."""
    n = 40000
    tracks = np.arange(1, n + 1)
    boxes = Boxes3D(np.zeros((n, 3)), np.tile([0.215, 0.478, 1.719], (n, 1)), np.zeros(n))
    actors = Actors(tracks, ["pedestrian"] * n, boxes, np.zeros((n, 3)), variant=actor_variants(tracks, 4))
    meshes = ActorMeshes()
    names = np.array([meshes.families[f].__name__ for f in meshes.family_codes(actors)])
    before = ActorMeshes(families={ObjectClass.PEDESTRIAN: FAMILIES + WHEELCHAIRS})
    without = np.array([before.families[f].__name__ for f in before.family_codes(actors)])
    pushing = np.isin(names, [f.name for f in PRAM_PUSHERS])
    for family in PRAM_PUSHERS:
        share = np.mean(names == family.name)
        assert family.share == 0.01 and abs(share - family.share) < 4 * np.sqrt(family.share * (1 - family.share) / n)
    np.testing.assert_array_equal(names[~pushing], without[~pushing])
    assert np.isin(without[pushing], [f.name for f in FAMILIES]).all()  # pushers come from the walkers only


def test_stroller_colours_are_one_draw_per_track():
    """Each stroller's colour is STROLLER_COLORS[k], k from its own stream (seed, STROLLER_COLOR_TAG, track id): the
    same track gets the same colour, another seed others; most are dark."""
    track = np.arange(1, 2001)
    colors = stroller_colors(track, 7)
    assert colors.shape == (2000, 3) and colors.dtype == np.uint8
    for t in (1, 17, 2000):
        k = np.random.default_rng([7, STROLLER_COLOR_TAG, t]).integers(len(STROLLER_COLORS))
        np.testing.assert_array_equal(colors[t - 1], STROLLER_COLORS[k])
    np.testing.assert_array_equal(stroller_colors(np.array([17, 17]), 7), colors[[16, 16]])
    assert not np.array_equal(stroller_colors(track, 8), colors)
    assert np.mean(colors.max(axis=1) <= 64) > 0.55
    assert stroller_colors(np.zeros(0, np.int64), 7).shape == (0, 3)
