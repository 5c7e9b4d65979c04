"""People in manual wheelchairs: a pedestrian body family whose poses are a seated figure pushing its wheels' rims.

Frame and conventions as :mod:`pipeline.world.people` (x forward, y left, z up, ground at z = 0, metres for a
person of :data:`pipeline.world.gait.MODEL_STATURE_M`; the render scales the whole to the person's stature). The
chair is an everyday folding one (ISO 7176-5 measures; our choice of values within the usual ranges): 24-inch rear
wheels (0.60 m across) with pushrims 0.04 m outside them, 0.6 m apart; 6-inch front casters; a seat 0.46 m above the
ground, 0.42 m wide and deep; a sling backrest to 0.9 m with push handles; footplates; overall about 1.05 m long,
0.7 m wide and, with its occupant, 1.3 m tall.

A wheelchair user is one pedestrian actor, chair and person together, as nuScenes' annotators box a wheelchair
with the person in it (category human.pedestrian.wheelchair: "if a person is in the wheelchair, include in the
annotation"); roadsynth's labels make them pedestrians whose ``person`` is "wheelchair_user", which its nuScenes
export writes as human.pedestrian.wheelchair. A COCO-style annotator would box the seated person, whose silhouette
the chair's wheels widen by a few centimetres each side.

The poses follow :class:`pipeline.world.people.PersonFamily`'s layout, so that the gait's pose choice
(:func:`pipeline.world.gait.gait_poses`) serves both: the WALK_PHASES of the walk cycle are the push cycle at the same
phases: a push over the rims' top from 20 deg behind it to 40 deg ahead for 45 % of the cycle, then the hands
lifted back over the rims (the semicircular pattern, one of the four patterns of Boninger et al., "Propulsion patterns
and pushrim biomechanics in manual wheelchair propulsion", Arch. Phys. Med. Rehabil. 83, 2002; the contact angle and
the push's share of the cycle are our choice, within the ranges such studies report), the trunk leaning forward as
the hands push and back as they return; the STAND_POSES sit still (hands on the rims, on the thighs, one of each);
the RUN_PHASES push faster (the same cycle, leaning 8 deg more); a family with umbrella poses (rain) repeats the
walking and still ones, without an umbrella (a wheelchair user needs both hands for the rims).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import ObjectClass, Person
from pipeline.world.figures import FOREARM_M, UPPER_ARM_M, Outfit, Pose, figure, pose
from pipeline.world.gait import RUN_PHASES, STAND_POSES, UMBRELLA_FIRST, WALK_PHASES, PosedFamily
from pipeline.world.mesh import Mesh
from pipeline.world.solids import Part, capsule, cylinder, ellipsoid, merge, torus

WHEEL_X_M = -0.08  # the rear axle, behind the hip joints
WHEEL_R_M = 0.30  # a 24-inch wheel's tyre, outside
TYRE_M = 0.016  # the tyre's tube radius
WHEEL_Y_M = 0.30  # each rear wheel's plane from the centre line
PUSHRIM_R_M = 0.27
PUSHRIM_Y_M = 0.34  # the pushrims 0.04 m outside the wheels
CASTER_X_M, CASTER_Y_M, CASTER_R_M = 0.28, 0.2, 0.075
SEAT_Z_M = 0.46
HIP_ABOVE_SEAT_M = 0.08  # the hip joints above the seat's cushion
PUSH_SHARE = 0.45  # of the push cycle, the hands on the rims
PUSH_FROM_DEG, PUSH_TO_DEG = -20.0, 40.0  # the hands' angle on the rim from its top, forward positive
RECOVERY_LIFT_M = 0.09  # the hands over the rims on the way back
LEAN_DEG = (5.0, 12.0)  # the trunk's lean: sitting, and the most added at the push's end
RUN_LEAN_DEG = 8.0  # more, pushing fast
REACH = 0.98  # a wrist beyond this share of the arm's length from its shoulder is drawn in to it


def _rim_point(side: float, angle_deg: float, radius: float) -> np.ndarray:
    """A point on the circle of ``radius`` about a rear wheel's axle, in its pushrim's plane, ``angle_deg`` from its
    top (forward positive); ``side`` +1 left, -1 right."""
    a = np.radians(angle_deg)
    return np.array([WHEEL_X_M + radius * np.sin(a), side * PUSHRIM_Y_M, WHEEL_R_M + radius * np.cos(a)])


def _reachable(shoulder: np.ndarray, wrist: np.ndarray) -> np.ndarray:
    """``wrist``, drawn towards ``shoulder`` where the arm could not reach it."""
    d = wrist - shoulder
    reach = REACH * (UPPER_ARM_M + FOREARM_M)
    dist = float(np.linalg.norm(d))
    return wrist if dist <= reach else shoulder + d * (reach / dist)


def push_hands(phase: float) -> tuple[float, float]:
    """The hands' angle on (or over) the rims from their top (deg, forward positive) and their distance from the
    axle (m) at push-cycle ``phase`` in [0, 1): the push from PUSH_FROM_DEG to PUSH_TO_DEG on the rim for PUSH_SHARE
    of the cycle, then back over it, lifted by up to RECOVERY_LIFT_M."""
    phase = float(phase) % 1.0
    if phase < PUSH_SHARE:
        u = phase / PUSH_SHARE
        return PUSH_FROM_DEG + (PUSH_TO_DEG - PUSH_FROM_DEG) * u, PUSHRIM_R_M
    u = (phase - PUSH_SHARE) / (1.0 - PUSH_SHARE)
    return PUSH_TO_DEG - (PUSH_TO_DEG - PUSH_FROM_DEG) * u, PUSHRIM_R_M + RECOVERY_LIFT_M * np.sin(np.pi * u)


def push_lean_deg(phase: float, running: bool = False) -> float:
    """The trunk's forward lean (deg) at push-cycle ``phase``: LEAN_DEG's sitting lean, plus up to its second value,
    growing as the hands push forward (the most at the push's end) and back while they return; plus RUN_LEAN_DEG
    pushing fast."""
    phase = float(phase) % 1.0
    lean0, lean_push = LEAN_DEG
    if phase < PUSH_SHARE:
        push = lean_push * np.sin(0.5 * np.pi * phase / PUSH_SHARE)
    else:
        push = lean_push * np.cos(0.5 * np.pi * (phase - PUSH_SHARE) / (1.0 - PUSH_SHARE))
    return lean0 + push + RUN_LEAN_DEG * running


def seated_pose(lean_deg: float, hands: str | tuple[float, float]) -> Pose:
    """The seated figure: hips over the seat, thighs forward, feet on the footplates, the trunk leaning ``lean_deg``
    forward; ``hands`` "lap" (on the thighs), "mixed" (the left on its rim's top, the right on the thigh) or (angle,
    radius) on the rims (:func:`push_hands`)."""
    lean = np.radians(lean_deg)
    pelvis = np.array([WHEEL_X_M + 0.04, 0.0, SEAT_Z_M + HIP_ABOVE_SEAT_M])
    chest = pelvis + 0.52 * np.array([np.sin(lean), 0.0, np.cos(lean)])
    head = chest + [0.05 + 0.1 * np.sin(lean), 0.0, 0.19]
    ankles = np.array([[0.3, 0.1, 0.19], [0.3, -0.1, 0.19]])
    shoulders = chest + np.array([[0.0, 0.185, -0.02], [0.0, -0.185, -0.02]])
    lap = [pelvis + [0.3, side * 0.12, 0.08] for side in (1.0, -1.0)]
    if hands == "lap":
        wrists = lap
    elif hands == "mixed":
        wrists = [_rim_point(1.0, 5.0, PUSHRIM_R_M), lap[1]]
    else:
        angle, radius = hands
        wrists = [_rim_point(side, angle, radius) for side in (1.0, -1.0)]
    wrists = [_reachable(shoulders[i], np.asarray(w, float)) for i, w in enumerate(wrists)]
    on_rim = [abs(w[1]) > 0.25 for w in wrists]
    hand_dirs = [(0.6, 0.0, -0.8) if rim else (1.0, 0.0, -0.3) for rim in on_rim]
    return pose(pelvis, chest, head, ankles, [(1.0, 0.0, -0.2), (1.0, 0.0, -0.2)], wrists, hand_dirs,
                knee_dir=(1.0, 0.0, 1.0), elbow_dir=[(-1.0, 0.6, 0.0), (-1.0, -0.6, 0.0)])


def _chair(frame: str) -> list[Part]:
    """The wheelchair: rear wheels (tyre, rim, spokes, hub) with pushrims, casters on forks, the frame's tubes in
    ``frame``, seat and backrest slings, push handles, footplates."""
    parts: list[Part] = []
    for side in (1.0, -1.0):
        y = side * WHEEL_Y_M
        centre = np.array([WHEEL_X_M, y, WHEEL_R_M])
        parts += [torus(centre, WHEEL_R_M - TYRE_M, TYRE_M, "rubber", 24, 6),
                  torus(centre, WHEEL_R_M - 2 * TYRE_M - 0.006, 0.008, "rim", 20, 4),
                  torus(centre + [0.0, side * (PUSHRIM_Y_M - WHEEL_Y_M), 0.0], PUSHRIM_R_M, 0.009, "metal", 20, 4),
                  cylinder(centre - [0.0, 0.05, 0.0], centre + [0.0, 0.05, 0.0], 0.035, "trim", 10)]
        spoke_r = WHEEL_R_M - 2 * TYRE_M - 0.01
        parts += [cylinder(centre - spoke_r * np.array([np.cos(a), 0.0, np.sin(a)]),
                           centre + spoke_r * np.array([np.cos(a), 0.0, np.sin(a)]), 0.004, "metal", 4,
                           ref=(0.0, 1.0, 0.0)) for a in np.linspace(0.0, np.pi, 6, endpoint=False) + 0.3]
        x = CASTER_X_M  # a caster and its fork
        hub = np.array([x, side * CASTER_Y_M, CASTER_R_M])
        parts.append(torus(hub, CASTER_R_M - 0.015, 0.015, "rubber", 12, 4))
        parts.append(cylinder(hub - [0.0, 0.025, 0.0], hub + [0.0, 0.025, 0.0], 0.04, "trim", 10))
        parts.append(capsule(hub + [-0.02, 0.0, 0.0], [x - 0.02, side * CASTER_Y_M, 0.3], 0.011, 0.011, frame,
                             n=6, rings=1))
        rail = side * 0.22
        joints = {"seat_back": (-0.18, rail, SEAT_Z_M), "seat_front": (0.22, rail, SEAT_Z_M),
                  "low_back": (-0.16, rail, 0.26), "low_front": (0.26, rail, 0.3),
                  "back_top": (-0.22, rail, 0.9), "handle": (-0.32, rail, 0.9),
                  "foot": (0.36, side * 0.17, 0.14)}
        for a, b in (("seat_back", "seat_front"), ("low_back", "low_front"), ("seat_back", "low_back"),
                     ("seat_front", "low_front"), ("seat_back", "back_top"), ("seat_front", "foot"),
                     ("low_back", "seat_front")):
            parts.append(capsule(joints[a], joints[b], 0.012, 0.012, frame, n=6, rings=1))
        parts.append(capsule(joints["back_top"], joints["handle"], 0.015, 0.015, "trim", n=6, rings=1))  # grip
        parts.append(ellipsoid((0.36, side * 0.09, 0.12), (0.08, 0.065, 0.012), "trim", n=10, m=4))  # footplate
    parts.append(ellipsoid((0.02, 0.0, SEAT_Z_M + 0.01), (0.22, 0.22, 0.025), "fabric_black", n=16, m=4))
    parts.append(ellipsoid((-0.2, 0.0, 0.68), (0.02, 0.22, 0.2), "fabric_black", n=16, m=4,
                           axis=(-0.1, 0.0, 1.0)))
    return parts


@dataclass(frozen=True)
class WheelchairFamily(PosedFamily):
    """A person in a manual wheelchair in every pose (see the module docstring): calling it with a pose index builds
    that pose's mesh, chair and person.

    Attributes:
        name, group, outfit: as :class:`pipeline.world.people.PersonFamily`'s (the outfit is drawn seated: no coat or
            skirt below the seat, no backpack against the backrest); frame: the frame's material; share: the share
            of pedestrians who are this family's (:meth:`pipeline.world.actors.ActorMeshes.family_codes`);
            umbrella: as a PersonFamily's, for the layout of poses only (none is drawn).
    """

    frame: str = "metal"
    share: float = 0.005
    umbrella: str | None = None

    @property
    def person(self) -> Person:
        """A wheelchair user, whatever the stature group."""
        return Person.WHEELCHAIR_USER

    def __call__(self, pose: int = 0) -> Mesh:
        self.check_pose(pose)
        index = pose - UMBRELLA_FIRST if pose >= UMBRELLA_FIRST else pose
        if index < WALK_PHASES or index >= WALK_PHASES + STAND_POSES:
            running = index >= WALK_PHASES + STAND_POSES
            phase = ((index - WALK_PHASES - STAND_POSES + 0.5) / RUN_PHASES) if running else index / WALK_PHASES
            body = seated_pose(push_lean_deg(phase, running), push_hands(phase))
        else:
            body = seated_pose(LEAN_DEG[0], ("lap", (0.0, PUSHRIM_R_M), "mixed")[index - WALK_PHASES])
        return merge(_chair(self.frame) + figure(body, self.outfit), ObjectClass.PEDESTRIAN).on_ground()


def _seated(trousers: str, hair: str = "hair_black", **kw) -> Outfit:
    kw.setdefault("top", "garment")
    kw.setdefault("sleeves", kw["top"])
    return Outfit(trousers=trousers, shins=trousers, shoes=kw.pop("shoes", "trim"), hair=hair, **kw)


# About 1 % of people need a wheelchair (WHO, "Guidelines on the provision of manual wheelchairs in less resourced
# settings", 2008); fewer of them are out on a street at a given time. Our choice: 1 % of the pedestrians, half of
# them men, half women, in everyday clothes.
WHEELCHAIRS = (
    WheelchairFamily("wheelchair_man", "man", _seated("denim", hair="hair_grey", shoes="sneaker_white", girth=1.05)),
    WheelchairFamily("wheelchair_woman", "woman", _seated("fabric_black", long_hair=True, hair="hair_brown",
                                                          girth=0.92), frame="paint"),
)
