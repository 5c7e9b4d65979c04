"""Prams and pushchairs, and the people who push them: a stroller actor family and a pedestrian body family whose
poses walk with both hands on its handle bar.

Frames: a stroller's model as every actor's (:mod:`pipeline.world.actor_shapes`): x forward (the stroller's front,
away from its pusher), y left, z up, ground at z = 0, metres; its box is centred on x = y = 0 (the handle bar behind,
the front wheels ahead are its ends). A pusher's as :mod:`pipeline.world.people`'s (the pelvis above x = y = 0, the
feet on the ground, a stature of :data:`pipeline.world.gait.MODEL_STATURE_M`, scaled to each person's stature);
:func:`stroller_offset_m` takes the stroller at its size as modelled, :data:`STROLLER_SIZE_M`, whatever the pusher's
stature. A pusher family's hands reach the handle bar's height exactly at its group's mean stature
(``grip_stature_m``: its model's grips are that much higher or lower), so a pusher of another stature holds the bar
a little low or high: 0.63 x the difference, about 4 cm at one standard deviation (7 cm), as people hold a handle bar
with their arms more or less bent.

A pusher and its stroller are two actors, as nuScenes' annotator instructions (nuscenes-devkit,
docs/instructions_nuscenes.md, "Stroller") box them: the stroller (human.pedestrian.stroller; here
:attr:`pipeline.core.classes.ObjectClass.STROLLER`, a class COCO lacks) with whoever sits in it, and "pedestrians
pushing strollers ... labeled separately". The person is a :class:`PramPusherFamily`, picked among the pedestrians
by its share (:meth:`pipeline.world.actors.ActorMeshes.family_codes`); the render puts a stroller ahead of each, its
handle in the pusher's hands (:func:`stroller_offset_m`).

The stroller is an everyday four-wheeled pram or pushchair, of the kind built to EN 1888-1 (the European safety
standard for prams and pushchairs; the measures here are our choice within the usual ranges of those on sale): rear
wheels 0.28 m across on a 0.55 m track, front swivel wheels 0.2 m across, a light tubular frame, a body (a carrycot
or a seat unit) about 0.72 m long between 0.45 and 0.8 m above the ground, a folding hood of fabric over its back
half, a shopping basket under it, and a handle bar across the back at 1.03 m, 0.2 m behind the body; overall 0.95 m
long, 0.6 m wide and 1.05 m tall. Its hood and body are ``garment``: their colour is the actor's
(:func:`stroller_colors`), as a person's top is.

A pusher's poses follow :func:`pipeline.world.gait.person_pose`'s layout, so that
:func:`pipeline.world.gait.gait_poses` serves it: the legs walk and stand as
:func:`pipeline.world.gait.walking_pose` and :func:`pipeline.world.gait.standing_pose` do, the trunk leans
:data:`PUSH_LEAN_DEG` more, and both arms reach forward, elbows bent, the wrists at the handle's grips
(:data:`HAND_X_M` ahead of the pelvis, at :data:`STROLLER_HANDLE_Z_M`, 0.2 m either side of the centre line): a
pusher does not swing its arms. Its "running" poses are a brisk walk (the walk at the running poses' phases, leaning
more), its umbrella poses the walking and standing ones again without an umbrella (both hands are on the handle).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.figures import FOREARM_M, UPPER_ARM_M, Outfit, Pose, bend, figure
from pipeline.world.gait import (
    MODEL_STATURE_M,
    STAND_POSES,
    UMBRELLA_FIRST,
    WALK_PHASES,
    PosedFamily,
    run_phase,
    standing_pose,
    walking_pose,
)
from pipeline.world.mesh import Mesh
from pipeline.world.solids import Part, capsule, cylinder, ellipsoid, merge, sweep, torus

# The stroller (model frame, metres; our choice within the usual ranges, see the module docstring).
STROLLER_HANDLE_X_M = -0.455  # the handle bar's axis: its rear end, 0.2 m behind the body
STROLLER_HANDLE_Z_M = 1.03  # the handle bar's axis above the ground
GRIP_Y_M = 0.2  # where the hands hold the handle bar, either side of the centre line
GRIP_R_M = 0.02  # the handle's foam grip (its back and top are the model's rear and top)
REAR_X_M, REAR_Y_M, REAR_R_M = -0.2, 0.275, 0.14  # rear wheels: axle, each wheel's plane, the tyre's outer radius
REAR_TYRE_M = 0.025  # the rear tyre's tube radius (the wheels' outsides are the model's sides)
FRONT_X_M, FRONT_Y_M, FRONT_R_M = 0.375, 0.24, 0.1  # front swivel wheels (the tyres' fronts are the model's front)
FRONT_TYRE_M = 0.02
FRAME_Y_M = 0.24  # the frame's side tubes from the centre line
HINGE = (-0.12, 0.55)  # (x, z) where the push bar, the rear leg and the front leg meet, each side
STROLLER_SIZE_M = (0.95, 0.6, 1.05)  # (length, width, height): handle grip to front tyres, rear tyres, grip's top

# The pusher (person frame, metres at MODEL_STATURE_M).
HAND_X_M = 0.45  # the handle's grips ahead of the pelvis
PUSH_LEAN_DEG = 5.0  # the trunk's lean added to the walk's 3 deg
BRISK_LEAN_DEG = 3.0  # and more in the "running" poses (a brisk walk)
WRIST_FROM_GRIP_M = (-0.02, 0.0, 0.015)  # the wrist behind and above the bar, the palm over it
HAND_DIR = (0.6, 0.0, -0.8)  # the hand from the wrist: forward and down over the bar
ELBOW_DIR = ((-0.3, 0.5, -1.0), (-0.3, -0.5, -1.0))  # the elbows bend down and out (left, right)


def _wheel(x: float, y: float, radius: float, tyre_m: float, frame: str, spokes: int) -> list[Part]:
    """A wheel on the ground at (x, y) about y: tyre (``rubber``), rim, hub on the inside, ``spokes`` spokes. The
    tyre's 20 x 8 vertices include its lowest, foremost, rearmost and outermost points, so that it touches the ground
    and the model's ends exactly."""
    side = np.sign(y)
    centre = np.array([x, y, radius])
    rim_r = radius - 2.0 * tyre_m
    parts = [torus(centre, radius - tyre_m, tyre_m, "rubber", 20, 8),
             torus(centre, rim_r, 0.006, "rim", 20, 4),
             cylinder(centre - [0.0, side * 0.035, 0.0], centre + [0.0, side * 0.012, 0.0], 0.022, frame, 10)]
    ends = [rim_r * np.array([np.cos(a), 0.0, np.sin(a)]) for a in np.linspace(0.0, np.pi, spokes, endpoint=False)]
    parts += [cylinder(centre - e, centre + e, 0.0035, "metal", 4, ref=(0.0, 1.0, 0.0)) for e in ends]
    return parts


def _frame(frame: str) -> list[Part]:
    """Wheels, the frame's tubes in ``frame`` (push bars, rear and front legs, axle, a low bar each side), the
    handle bar with its foam grip, and the basket under the body."""
    parts: list[Part] = []
    hx, hz = HINGE
    tube = 0.012
    for s in (1.0, -1.0):
        y = s * FRAME_Y_M
        parts += _wheel(REAR_X_M, s * REAR_Y_M, REAR_R_M, REAR_TYRE_M, frame, 5)
        parts += _wheel(FRONT_X_M, s * FRONT_Y_M, FRONT_R_M, FRONT_TYRE_M, frame, 0)
        fork_top = np.array([FRONT_X_M + 0.05, y, 0.26])  # the swivel axis ahead of the hub: the wheel trails
        hub = np.array([FRONT_X_M, s * (FRONT_Y_M + 0.03), FRONT_R_M])
        parts += [capsule((STROLLER_HANDLE_X_M, y, STROLLER_HANDLE_Z_M), (hx, y, hz), tube, tube, frame, 8, 1),
                  capsule((hx, y, hz), (REAR_X_M, y, REAR_R_M), tube, tube, frame, 8, 1),
                  capsule((hx, y, hz), fork_top, tube, tube, frame, 8, 1),
                  capsule((REAR_X_M, y, REAR_R_M), fork_top - [0.0, 0.0, 0.02], 0.009, 0.009, frame, 8, 1),
                  capsule(fork_top, hub, 0.01, 0.01, frame, 8, 1),  # the swivel fork
                  cylinder(fork_top + [0.0, 0.0, -0.03], fork_top + [0.0, 0.0, 0.03], 0.02, "trim", 10),
                  ellipsoid((hx, y, hz), (0.035, 0.02, 0.035), "trim", 10, 6)]  # the fold's hinge
    parts += [capsule((REAR_X_M, -FRAME_Y_M, REAR_R_M), (REAR_X_M, FRAME_Y_M, REAR_R_M), 0.01, 0.01, frame, 8, 1,
                      ref=(0.0, 0.0, 1.0)),  # the rear axle
              capsule((STROLLER_HANDLE_X_M, -FRAME_Y_M, STROLLER_HANDLE_Z_M),
                      (STROLLER_HANDLE_X_M, FRAME_Y_M, STROLLER_HANDLE_Z_M), tube, tube, frame, 8, 1,
                      ref=(0.0, 0.0, 1.0)),
              capsule((STROLLER_HANDLE_X_M, -0.23, STROLLER_HANDLE_Z_M),
                      (STROLLER_HANDLE_X_M, 0.23, STROLLER_HANDLE_Z_M), GRIP_R_M, GRIP_R_M, "trim", 8, 2,
                      ref=(0.0, 0.0, 1.0)),  # the foam grip (8 sides: vertices at its back and top)
              sweep([(-0.2, 0.0, 0.25), (-0.17, 0.0, 0.25), (0.22, 0.0, 0.25), (0.25, 0.0, 0.25)],
                    [(0.0, 0.0), (0.08, 0.17), (0.08, 0.17), (0.0, 0.0)], "fabric_black", 12, ref=(0.0, 0.0, 1.0))]
    return parts


def _hood(pivot_x: float, pivot_z: float, reach_m: float, tilts_deg: tuple[float, ...]) -> list[Part]:
    """A folding hood over the body's back half: overlapping fabric bands (``garment``), each a half ellipse from
    one side's pivot at (``pivot_x``, +-0.215, ``pivot_z``) over the top to the other, ``reach_m`` high, tilted back
    from upright by each of ``tilts_deg``; a button over each pivot."""
    parts: list[Part] = []
    phi = np.linspace(0.0, np.pi, 13)
    for tilt in np.radians(tilts_deg):
        up = np.array([-np.sin(tilt), 0.0, np.cos(tilt)])  # the band's plane: y and this
        centres = np.array([pivot_x, 0.0, pivot_z]) + np.outer(np.cos(phi), [0.0, 0.215, 0.0]) \
            + np.outer(reach_m * np.sin(phi), up)
        across = np.array([np.cos(tilt), 0.0, np.sin(tilt)])  # the band's width, normal to its plane
        parts.append(sweep(centres, np.tile([0.075, 0.008], (len(phi), 1)), "garment", 6, ref=across))
    parts += [ellipsoid((pivot_x, s * 0.222, pivot_z), (0.03, 0.012, 0.03), "trim", 10, 4) for s in (1.0, -1.0)]
    return parts


def _body_x(a: float, b: float, z: float, half_h: float, half_w: float) -> tuple[np.ndarray, np.ndarray]:
    """Stations of a rounded tub along x from ``a`` to ``b``, centred at height ``z``: its cross-section an ellipse
    of ``half_h`` by ``half_w``, the ends rounded to poles."""
    xs = [a, a + 0.01, a + 0.03, a + 0.08, b - 0.08, b - 0.03, b - 0.01, b]
    k = [0.0, 0.6, 0.87, 1.0, 1.0, 0.87, 0.6, 0.0]
    centres = np.array([[x, 0.0, z] for x in xs])
    return centres, np.array([[half_h * f, half_w * f] for f in k])


def _carrycot(accent: str) -> list[Part]:
    """A pram's carrycot: a deep tub (``garment``) from 0.5 to 0.8 m, its apron (``accent``) over the front half,
    the hood over the back half."""
    centres, radii = _body_x(-0.25, 0.47, 0.65, 0.15, 0.2)
    return [sweep(centres, radii, "garment", 16, ref=(0.0, 0.0, 1.0)),
            ellipsoid((0.22, 0.0, 0.785), (0.22, 0.175, 0.03), accent, 14, 4),
            *_hood(0.05, 0.7, 0.27, (8.0, 30.0, 52.0, 74.0))]


def _seat_unit(accent: str) -> list[Part]:
    """A pushchair's seat unit: a shallow shell (``garment``) from 0.45 to 0.6 m, a padded seat and reclined back
    (``accent``), a leg rest down to the front, a bumper bar across, the hood over the back."""
    centres, radii = _body_x(-0.25, 0.4, 0.52, 0.07, 0.2)
    seat = [(-0.27, 0.0, 0.93), (-0.2, 0.0, 0.62), (-0.12, 0.0, 0.57), (0.18, 0.0, 0.58), (0.3, 0.0, 0.52),
            (0.42, 0.0, 0.36)]
    return [sweep(centres, radii, "garment", 16, ref=(0.0, 0.0, 1.0)),
            sweep(seat, np.tile([0.17, 0.03], (len(seat), 1)), accent, 12, ref=(0.0, 1.0, 0.0)),
            ellipsoid((0.43, 0.0, 0.34), (0.05, 0.17, 0.02), "trim", 12, 4, axis=(0.6, 0.0, 1.0)),  # footrest
            capsule((0.3, -0.2, 0.72), (0.3, 0.2, 0.72), 0.015, 0.015, "trim", 8, 2, ref=(0.0, 0.0, 1.0)),
            *[capsule((0.3, s * 0.2, 0.72), (0.26, s * 0.2, 0.56), 0.012, 0.012, "trim", 8, 1) for s in (1.0, -1.0)],
            *_hood(-0.1, 0.78, 0.24, (5.0, 28.0, 50.0, 72.0))]


@dataclass(frozen=True)
class StrollerFamily:
    """A pram or pushchair (see the module docstring), one pose: calling it builds its mesh, lowest point (the
    tyres) on the ground, its box :data:`STROLLER_SIZE_M` centred on x = y = 0.

    Attributes:
        name: the family's name; carrycot: a pram's carrycot (else a pushchair's seat unit); frame: the tubes' and
            hubs' material; accent: the apron's or seat's fabric.
    """

    name: str
    carrycot: bool
    frame: str
    accent: str

    @property
    def __name__(self) -> str:
        return self.name

    def __call__(self, pose: int = 0) -> Mesh:
        body = _carrycot(self.accent) if self.carrycot else _seat_unit(self.accent)
        return merge(_frame(self.frame) + body, ObjectClass.STROLLER).on_ground()


STROLLERS = (
    StrollerFamily("pram", True, "metal", "fabric_black"),
    StrollerFamily("pushchair", False, "trim", "fabric_grey"),
)

# A stroller's colour (sRGB, the hood's and body's ``garment``), one drawn per stroller: our choice, as the prams and
# pushchairs on a city street look, not a survey: mostly black, dark grey and navy, a few grey, beige, red, olive.
STROLLER_COLORS = ((25, 25, 28), (25, 25, 28), (25, 25, 28), (25, 25, 28), (60, 60, 64), (60, 60, 64),
                   (28, 36, 64), (120, 120, 125), (190, 160, 115), (130, 30, 40), (85, 90, 55))
STROLLER_COLOR_TAG = 0x57C0


def stroller_colors(track_id: np.ndarray, seed: int) -> np.ndarray:
    """(N, 3) uint8 sRGB colours of N strollers, one of :data:`STROLLER_COLORS` each (uniformly), drawn from
    ``numpy.random.default_rng([seed, STROLLER_COLOR_TAG, track id])`` (the same in every frame and shard)."""
    pick = [np.random.default_rng([int(seed), STROLLER_COLOR_TAG, int(t)]).integers(len(STROLLER_COLORS))
            for t in np.asarray(track_id).tolist()]
    return np.array([STROLLER_COLORS[k] for k in pick], np.uint8).reshape(-1, 3)


def stroller_offset_m(stature_m: np.ndarray) -> np.ndarray:
    """(N,) float64 metres from a pusher's pelvis ground point, along its heading, to the centre of its stroller's box
    (:data:`STROLLER_SIZE_M`, centred on the model's x = 0), for pushers of ``stature_m`` (N,): the pusher's grips
    (:data:`HAND_X_M` scaled to the stature) on the handle bar (:data:`STROLLER_HANDLE_X_M` behind the centre)."""
    return HAND_X_M * np.asarray(stature_m, np.float64) / MODEL_STATURE_M - STROLLER_HANDLE_X_M


def grips(grip_stature_m: float = MODEL_STATURE_M) -> np.ndarray:
    """(2, 3) the handle's grips (left, right) in a pusher's model frame (at MODEL_STATURE_M), for a family whose
    hands meet the handle bar (:data:`STROLLER_HANDLE_Z_M` above the ground) at a stature of ``grip_stature_m``:
    HAND_X_M ahead of the pelvis, GRIP_Y_M either side, at STROLLER_HANDLE_Z_M x MODEL_STATURE_M / grip_stature_m."""
    z = STROLLER_HANDLE_Z_M * MODEL_STATURE_M / grip_stature_m
    return np.array([[HAND_X_M, GRIP_Y_M, z], [HAND_X_M, -GRIP_Y_M, z]])


def pushing_pose(p: Pose, grip_stature_m: float = MODEL_STATURE_M) -> Pose:
    """``p`` with both hands on the handle: each wrist WRIST_FROM_GRIP_M from its grip (:func:`grips` of
    ``grip_stature_m``), the hand over the bar, the elbow bent down and out."""
    wrists = grips(grip_stature_m) + WRIST_FROM_GRIP_M
    elbows = np.array([bend(p.shoulders[i], wrists[i], UPPER_ARM_M, FOREARM_M, ELBOW_DIR[i]) for i in range(2)])
    hand = np.asarray(HAND_DIR) / np.linalg.norm(HAND_DIR)
    return replace(p, wrists=wrists, elbows=elbows, hands=np.array([hand, hand]))


def pusher_pose(index: int, grip_stature_m: float = MODEL_STATURE_M) -> Pose:
    """Pose ``index`` of a pusher (:func:`pipeline.world.gait.person_pose`'s layout): the walk at phase index /
    WALK_PHASES, standing, the brisk walk at the running poses' phases, then the walking and standing ones again
    (the umbrella poses, without one); the trunk leaning PUSH_LEAN_DEG more than a walker's, the hands on the
    handle (:func:`pushing_pose` at ``grip_stature_m``)."""
    if index >= UMBRELLA_FIRST:
        index -= UMBRELLA_FIRST
    lean = 3.0 + PUSH_LEAN_DEG
    if index < WALK_PHASES:
        body = walking_pose(index / WALK_PHASES, lean)
    elif index < WALK_PHASES + STAND_POSES:
        body = standing_pose(index - WALK_PHASES, lean)
    else:
        body = walking_pose(run_phase(index), lean + BRISK_LEAN_DEG)
    return pushing_pose(body, grip_stature_m)


@dataclass(frozen=True)
class PramPusherFamily(PosedFamily):
    """A person pushing a pram or pushchair (the stroller is an actor of its own), in every pose of
    :func:`pusher_pose`: calling it with a pose index builds that pose's mesh, the lower sole on the ground.

    Attributes:
        name, group, outfit: as :class:`pipeline.world.people.PersonFamily`'s; share: the share of pedestrians who
            are this family's (:meth:`pipeline.world.actors.ActorMeshes.family_codes`); umbrella: as a
            PersonFamily's, for the layout of poses only (none is drawn); grip_stature_m: the stature at which the
            hands meet the handle bar exactly (the group's mean, :data:`pipeline.world.people.STATURE_M`); pram:
            True, a class constant: the render puts a stroller in front of every person of a family that has it set
            (:func:`stroller_offset_m`).
    """

    grip_stature_m: float = MODEL_STATURE_M
    share: float = 0.01
    umbrella: str | None = None
    pram: ClassVar[bool] = True

    def __call__(self, pose: int = 0) -> Mesh:
        self.check_pose(pose)
        return merge(figure(pusher_pose(pose, self.grip_stature_m), self.outfit), ObjectClass.PEDESTRIAN).on_ground()


# Our choice: about 2 % of urban pedestrians push a pram or pushchair (no count at hand), as many women as men here.
PRAM_PUSHERS = (
    PramPusherFamily("pram_woman", "woman", Outfit(
        top="garment", sleeves="garment", trousers="denim", shins="denim", shoes="sneaker_white", hair="hair_brown",
        long_hair=True, shoulder_bag="fabric_beige", girth=0.9), 1.63),
    PramPusherFamily("pram_man", "man", Outfit(
        top="garment", sleeves="garment", trousers="fabric_grey", shins="fabric_grey", shoes="leather",
        hair="hair_black", skin="skin_medium", backpack="fabric_navy"), 1.76),
)
