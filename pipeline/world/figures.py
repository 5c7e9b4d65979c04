"""Human figures for pedestrians and riders: a pose (joint positions) dressed in an outfit, as smooth closed parts.

Frame: metres, x forward (the way the figure faces), y left, z up, the ground at z = 0 for a pedestrian. Joints
are given per side as (left, right) = (+y, -y). Proportions follow adult anthropometry for a stature of 1.75 m
(head 1/7.5 of the stature, hip joints at ~0.53, knees ~0.28, shoulders' span ~0.25 of it); a figure's parts are
tapered tubes (:func:`pipeline.world.solids.limb`) and ellipsoids. Materials: the outfit's top in ``paint`` (the
actor's colour) by default, trousers ``cloth``, skin ``skin``, shoes and hair ``trim``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.world.solids import Part, capsule, ellipsoid, limb, sweep

THIGH_M = 0.43  # hip joint to knee
SHIN_M = 0.43  # knee to ankle
UPPER_ARM_M = 0.30  # shoulder to elbow
FOREARM_M = 0.26  # elbow to wrist
# Torso cross-sections along the pelvis (s = 0, between the hip joints) -> shoulder line (s = 1) axis:
# (s, half-width, half-depth) in metres; the ends are poles. The trousers reach up to s = 0.15.
_TORSO = ((-0.26, 0.0, 0.0), (-0.2, 0.115, 0.08), (-0.06, 0.165, 0.105), (0.2, 0.145, 0.095), (0.5, 0.16, 0.11),
          (0.8, 0.175, 0.105), (0.95, 0.17, 0.09), (1.03, 0.125, 0.07), (1.08, 0.0, 0.0))
_WAIST_S = 0.15


def bend(root, tip, l1: float, l2: float, towards) -> np.ndarray:
    """The middle joint (knee, elbow) of a two-bone chain from ``root`` to ``tip`` with bone lengths l1, l2,
    bent towards the direction ``towards`` (3,); a tip out of reach straightens the chain."""
    root, tip, towards = (np.asarray(p, np.float64) for p in (root, tip, towards))
    d = tip - root
    dist = np.linalg.norm(d)
    axis = d / dist
    dist = min(dist, 0.999 * (l1 + l2))
    along = (l1 * l1 - l2 * l2 + dist * dist) / (2.0 * dist)
    side = towards - (towards @ axis) * axis
    side /= np.linalg.norm(side)
    return root + along * axis + np.sqrt(max(l1 * l1 - along * along, 0.0)) * side


@dataclass(frozen=True)
class Pose:
    """Joint positions (metres). Per-side arrays are (2, 3): [left, right].

    Attributes:
        pelvis: (3,) midpoint of the hip joints; chest: (3,) midpoint of the shoulder joints; head: (3,) the
            head's centre.
        hips, knees, ankles: (2, 3); feet: (2, 3) each shoe's forward direction (unit, may pitch).
        shoulders, elbows, wrists: (2, 3); hands: (2, 3) each hand's direction from the wrist (unit).
    """

    pelvis: np.ndarray
    chest: np.ndarray
    head: np.ndarray
    hips: np.ndarray
    knees: np.ndarray
    ankles: np.ndarray
    feet: np.ndarray
    shoulders: np.ndarray
    elbows: np.ndarray
    wrists: np.ndarray
    hands: np.ndarray


def pose(pelvis, chest, head, ankles, feet, wrists, hands, knee_dir=(1.0, 0.0, 0.0), elbow_dir=(-1.0, 0.0, -0.2),
         hip_half_m: float = 0.09, shoulder_half_m: float = 0.185) -> Pose:
    """A pose from the trunk, the ankles and the wrists; knees and elbows by :func:`bend` (towards ``knee_dir``,
    ``elbow_dir``, one (3,) or (2, 3) per side). The hip and shoulder joints sit across the trunk along y."""
    pelvis, chest = np.asarray(pelvis, float), np.asarray(chest, float)
    across = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    hips = pelvis + hip_half_m * across
    shoulders = chest + shoulder_half_m * across - [0.0, 0.0, 0.02]
    ankles, wrists = np.asarray(ankles, float), np.asarray(wrists, float)
    knee_dir, elbow_dir = np.broadcast_to(knee_dir, (2, 3)), np.broadcast_to(elbow_dir, (2, 3))
    knees = np.array([bend(hips[i], ankles[i], THIGH_M, SHIN_M, knee_dir[i]) for i in range(2)])
    elbows = np.array([bend(shoulders[i], wrists[i], UPPER_ARM_M, FOREARM_M, elbow_dir[i]) for i in range(2)])
    unit = lambda v: np.asarray(v, float) / np.linalg.norm(v, axis=-1, keepdims=True)  # noqa: E731
    return Pose(pelvis, chest, np.asarray(head, float), hips, knees, ankles, unit(feet), shoulders, elbows, wrists,
                unit(hands))


@dataclass(frozen=True)
class Outfit:
    """Materials of a figure's regions and what it wears and carries; ``None`` leaves a part out.

    Attributes:
        top: torso and upper arms; sleeves: forearms (``skin`` for short sleeves); trousers: hips and thighs;
        shins: lower legs (``skin`` for shorts or a skirt); shoes; hair (a cap over the back and top of the head);
        helmet: a full-face helmet with a dark visor (``None``: no helmet); coat_m: a coat in ``top`` down to
        this height above the pelvis (negative: below it), or ``None``; girth: scales limb and torso radii.
        skin: the skin's material; long_hair: hair down to the shoulders; hat: a knitted hat (beanie) in this
        material; hood: a hood lying on the back of the neck, in ``top``; skirt_m: a skirt (in ``trousers``) from the
        waist down to this height above the pelvis (negative), or ``None``; backpack, shoulder_bag, hand_bag: a
        backpack, a bag at the right hip on a strap, a bag carried in the right hand, in these materials;
        head_scale: the head's size relative to an adult's (children's heads are larger for their stature);
        umbrella: an open umbrella held up in the left hand (pose the arm with
        :func:`pipeline.world.gait.umbrella_pose`), its canopy in this material.
    """

    top: str = "paint"
    sleeves: str = "paint"
    trousers: str = "cloth"
    shins: str = "cloth"
    shoes: str = "trim"
    hair: str | None = "trim"
    helmet: str | None = None
    coat_m: float | None = None
    girth: float = 1.0
    skin: str = "skin"
    long_hair: bool = False
    hat: str | None = None
    hood: bool = False
    skirt_m: float | None = None
    backpack: str | None = None
    shoulder_bag: str | None = None
    hand_bag: str | None = None
    head_scale: float = 1.0
    umbrella: str | None = None


def figure(p: Pose, outfit: Outfit = Outfit()) -> list[Part]:
    """The figure's parts: torso, neck, head (hair, hat or helmet), arms with hands, legs with shoes, and what it
    wears over them and carries."""
    g, skin = outfit.girth, outfit.skin
    up = p.chest - p.pelvis
    axis = up / np.linalg.norm(up)
    s, half_w, half_d = (np.array(col) for col in zip(*_TORSO, strict=True))
    centres = p.pelvis + s[:, None] * up
    mid = 0.5 * (s[1:] + s[:-1])
    torso_mats = [outfit.trousers if m < _WAIST_S else outfit.top for m in mid]
    parts = [sweep(centres, g * np.column_stack([half_w, half_d]), torso_mats, n=12)]
    for hem_m, material, flare in ((outfit.coat_m, outfit.top, 0.2), (outfit.skirt_m, outfit.trousers, 0.23)):
        if hem_m is not None:  # a flared coat skirt or a skirt from the waist down
            top_c, foot_c = p.pelvis + (0.3 if material == outfit.top else 0.16) * up, p.pelvis + hem_m * axis
            parts.append(sweep([top_c, 0.5 * (top_c + foot_c), foot_c, foot_c - 0.02 * axis],
                               g * np.array([[0.155, 0.105], [0.175, 0.12], [flare, 0.7 * flare], [0.0, 0.0]]),
                               material, n=14))
    neck_top = p.head - [0.0, 0.0, 0.08]
    parts.append(capsule(p.chest + 0.02 * up, neck_top, 0.05 * g, 0.045 * g, skin, n=8, rings=2))
    parts += _head(p.head, outfit)
    if outfit.hood:  # the hood of a hoodie or parka, lying on the upper back below the head
        parts.append(ellipsoid(p.chest + [-0.1, 0.0, 0.03], (0.07, 0.13, 0.09), outfit.top, n=12, m=6))
    for i in range(2):
        thigh = p.hips[i] + 0.5 * (p.knees[i] - p.hips[i])
        calf = p.knees[i] + 0.35 * (p.ankles[i] - p.knees[i])
        parts.append(limb([p.hips[i] + [0, 0, 0.04], thigh, p.knees[i], calf, p.ankles[i]],
                          g * np.array([0.09, 0.08, 0.058, 0.06, 0.04]),
                          [outfit.trousers, outfit.trousers, outfit.shins, outfit.shins], n=8))
        parts.append(_shoe(p.ankles[i], p.feet[i], outfit.shoes))
        elbow, wrist = p.elbows[i], p.wrists[i]
        parts.append(limb([p.shoulders[i], elbow, wrist], g * np.array([0.058, 0.047, 0.035]),
                          [outfit.top, outfit.sleeves], n=8))
        hand_c = wrist + 0.07 * p.hands[i]
        parts.append(ellipsoid(hand_c, (0.028, 0.045, 0.085), skin, n=8, m=6, axis=p.hands[i], ref=(0, 1, 0)))
    parts += _carried(p, outfit, axis)
    return parts


def _carried(p: Pose, outfit: Outfit, axis: np.ndarray) -> list[Part]:
    """A backpack on the upper back, a bag on a strap at the right hip, a bag hanging from the right hand, an
    umbrella held up in the left."""
    parts = []
    g = outfit.girth
    if outfit.backpack is not None:
        centre = p.pelvis + 0.62 * (p.chest - p.pelvis) + [-(0.11 * g + 0.09), 0.0, 0.0]
        parts.append(ellipsoid(centre, (0.085, 0.15, 0.21), outfit.backpack, n=12, m=6, axis=axis))
    if outfit.shoulder_bag is not None:
        centre = p.hips[1] + [0.0, -0.1 * g - 0.06, 0.08]
        parts.append(ellipsoid(centre, (0.13, 0.045, 0.11), outfit.shoulder_bag, n=12, m=6))
        parts.append(capsule(p.shoulders[0] + [0.0, -0.05, 0.02], centre + [0.0, 0.0, 0.08], 0.012, 0.012,
                             outfit.shoulder_bag, n=6, rings=1))
    if outfit.hand_bag is not None:  # a shopping bag hanging from the fist on its two handles: flat, upright, 0.34 m
        grip = p.wrists[1] + 0.09 * p.hands[1]  # wide, 0.36 m tall
        top, bottom = grip + [0.0, -0.02, -0.1], grip + [0.0, -0.02, -0.46]
        parts.append(sweep([bottom, top], [[0.17, 0.055], [0.17, 0.055]], outfit.hand_bag, n=16, ref=(1.0, 0.0, 0.0)))
        parts += [capsule(grip, top + [dx, 0.0, 0.0], 0.008, 0.008, outfit.hand_bag, n=6, rings=1)
                  for dx in (-0.08, 0.08)]
    if outfit.umbrella is not None:
        parts += _umbrella(p, outfit)
    return parts


# An open umbrella's canopy (8 panels): (height above its rim, radius) from the rim up, metres; a standard umbrella
# of ~1.0 m across, its rim just above the head.
_CANOPY = ((0.0, 0.0), (0.006, 0.5), (0.09, 0.44), (0.17, 0.31), (0.225, 0.15), (0.25, 0.0))
UMBRELLA_RIM_ABOVE_HEAD_M = 0.16  # above the head's centre: 4 cm above its top


def _umbrella(p: Pose, outfit: Outfit) -> list[Part]:
    """The umbrella: a shaft up from the left fist to a dome of 8 panels (flat beneath) over the head."""
    grip = p.wrists[0] + 0.07 * p.hands[0]
    rim = np.array([grip[0], grip[1], p.head[2] + UMBRELLA_RIM_ABOVE_HEAD_M * outfit.head_scale])
    dz, radius = (np.array(col) for col in zip(*_CANOPY, strict=True))
    canopy = sweep(rim + dz[:, None] * [0.0, 0.0, 1.0], radius, outfit.umbrella, n=8, ref=(1.0, 0.0, 0.0))
    shaft = capsule(grip - [0.0, 0.0, 0.12], rim + [0.0, 0.0, 0.27], 0.009, 0.007, "trim", n=6, rings=1)
    return [canopy, shaft]


def _head(centre: np.ndarray, outfit: Outfit) -> list[Part]:
    """Skin head (a bit deeper than wide); a hair cap over its back and top (down to the shoulders for long hair), a
    knitted hat over the hair, or a full-face helmet and visor."""
    k = outfit.head_scale
    parts = [ellipsoid(centre, (0.1 * k, 0.078 * k, 0.117 * k), outfit.skin, n=12, m=8)]
    if outfit.helmet is not None:
        parts.append(ellipsoid(centre + [-0.01, 0.0, 0.025], (0.145, 0.125, 0.145), outfit.helmet, n=14, m=8))
        parts.append(ellipsoid(centre + [0.06, 0.0, 0.035], (0.1, 0.105, 0.055), "glass", n=14, m=6))
        return parts
    if outfit.hair is not None:
        parts.append(ellipsoid(centre + k * np.array([-0.022, 0.0, 0.022]), (0.098 * k, 0.084 * k, 0.108 * k),
                               outfit.hair, n=12, m=8))
        if outfit.long_hair:
            parts.append(ellipsoid(centre + k * np.array([-0.05, 0.0, -0.06]), (0.07 * k, 0.085 * k, 0.15 * k),
                                   outfit.hair, n=12, m=6))
    if outfit.hat is not None:
        parts.append(ellipsoid(centre + k * np.array([-0.012, 0.0, 0.05]), (0.104 * k, 0.09 * k, 0.095 * k),
                               outfit.hat, n=12, m=8))
    return parts


def _shoe(ankle: np.ndarray, forward: np.ndarray, material: str) -> Part:
    """A shoe from 6 cm behind the ankle to 19 cm before it, its sole 8.5 cm below the ankle joint."""
    centre = ankle + 0.065 * forward - [0.0, 0.0, 0.04]
    return ellipsoid(centre, (0.045, 0.05, 0.135), material, n=10, m=8, axis=forward, ref=(0.0, 0.0, 1.0))
