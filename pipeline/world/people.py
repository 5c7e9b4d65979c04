"""Pedestrian body families: people walking and standing, in a few builds and outfits (:mod:`.figures`).

Frame and conventions as :mod:`pipeline.world.actor_shapes` (x forward, y left, z up, ground at z = 0, metres at
a stature of 1.75 m; normalised to each actor's box later). SUMO's pedestrian box is 0.215 m deep; the render
gives each person the depth of its own model at its height instead (:meth:`pipeline.world.actors.ActorMeshes.
body_lengths`), so a stride is not squeezed.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.figures import SHIN_M, THIGH_M, Outfit, figure, pose
from pipeline.world.mesh import Mesh
from pipeline.world.solids import merge


def _standing(stance_m: float = 0.11, lean: float = 0.0):
    """Upright, feet a little apart and turned out, arms hanging with a slight bend."""
    return pose(pelvis=(0.0, 0.0, 0.92), chest=(lean, 0.0, 1.44), head=(0.015 + 1.2 * lean, 0.0, 1.635),
                ankles=[(0.0, stance_m, 0.085), (0.0, -stance_m, 0.085)],
                feet=[(1.0, 0.18, 0.0), (1.0, -0.18, 0.0)],
                wrists=[(0.03, 0.225, 0.86), (0.03, -0.225, 0.86)],
                hands=[(0.15, 0.02, -1.0), (0.15, -0.02, -1.0)], elbow_dir=(-1.0, 0.3, 0.0))


def _leg(thigh_deg: float, knee_deg: float) -> np.ndarray:
    """(x, z) of the ankle from the hip joint, the thigh ``thigh_deg`` forward of vertical and the knee bent by
    ``knee_deg`` (the shin swings back by that much)."""
    t, s = np.radians(thigh_deg), np.radians(thigh_deg - knee_deg)
    return np.array([THIGH_M * np.sin(t) + SHIN_M * np.sin(s), -THIGH_M * np.cos(t) - SHIN_M * np.cos(s)])


def _walking(thigh_deg: float = 18.0, trail_deg: float = -9.0):
    """Mid-stride at double support, just after the left heel strikes: the left leg ahead and almost straight, its
    foot toe up; the right leg behind, knee bent, on its toes; arms swinging opposite to the legs; the pelvis at its
    lowest (the leading ankle 10 cm up)."""
    lead, trail = _leg(thigh_deg, 4.0), _leg(trail_deg, 32.0)
    hip_z = 0.1 - lead[1]
    return pose(pelvis=(0.0, 0.0, hip_z), chest=(0.03, 0.0, hip_z + 0.52), head=(0.05, 0.0, hip_z + 0.715),
                ankles=[(lead[0], 0.085, hip_z + lead[1]), (trail[0], -0.085, hip_z + trail[1])],
                feet=[(1.0, 0.05, 0.3), (1.0, -0.05, -0.75)],
                wrists=[(-0.14, 0.22, hip_z - 0.02), (0.2, -0.2, hip_z + 0.03)],
                hands=[(-0.3, 0.0, -1.0), (0.5, 0.0, -1.0)],
                knee_dir=(1.0, 0.0, 0.0), elbow_dir=[(-1.0, 0.3, 0.0), (-1.0, -0.2, -0.5)])


def pedestrian() -> Mesh:
    """A person walking mid-stride: long-sleeved top (paint), trousers (cloth), dark shoes and hair."""
    return merge(figure(_walking()), ObjectClass.PEDESTRIAN)


def pedestrian_standing() -> Mesh:
    """A person standing, feet apart: top (paint), trousers, shoes, hair."""
    return merge(figure(_standing()), ObjectClass.PEDESTRIAN)


def pedestrian_coat() -> Mesh:
    """A heavier-built person standing in a thigh-length coat (paint) over dark trousers."""
    return merge(figure(_standing(0.1, lean=0.01), Outfit(trousers="trim", shins="trim", shoes="rubber",
                                                           coat_m=-0.3, girth=1.12)), ObjectClass.PEDESTRIAN)


def pedestrian_summer() -> Mesh:
    """A slim person walking in short sleeves and shorts: forearms and shins bare (skin)."""
    return merge(figure(_walking(15.0, -8.0), Outfit(sleeves="skin", shins="skin", girth=0.92)), ObjectClass.PEDESTRIAN)


PEDESTRIANS = (pedestrian, pedestrian_standing, pedestrian_coat, pedestrian_summer)
