"""Pedestrian body families: people walking and standing, in a few builds and outfits (:mod:`.figures`).

Frame and conventions as :mod:`pipeline.world.actor_shapes` (x forward, y left, z up, ground at z = 0, metres at
a stature of 1.75 m; normalised to each actor's box later). SUMO's pedestrian box is 0.215 m deep, so a stride
is squeezed along x by the placement; the poses keep strides moderate for that reason.
"""

from __future__ import annotations

from pipeline.core.classes import ObjectClass
from pipeline.world.figures import Outfit, figure, pose
from pipeline.world.mesh import Mesh
from pipeline.world.solids import merge


def _standing(stance_m: float = 0.11, lean: float = 0.0):
    """Upright, feet a little apart and turned out, arms hanging with a slight bend."""
    return pose(pelvis=(0.0, 0.0, 0.92), chest=(lean, 0.0, 1.44), head=(0.015 + 1.2 * lean, 0.0, 1.635),
                ankles=[(0.0, stance_m, 0.085), (0.0, -stance_m, 0.085)],
                feet=[(1.0, 0.18, 0.0), (1.0, -0.18, 0.0)],
                wrists=[(0.03, 0.225, 0.86), (0.03, -0.225, 0.86)],
                hands=[(0.15, 0.02, -1.0), (0.15, -0.02, -1.0)], elbow_dir=(-1.0, 0.3, 0.0))


def _walking(step_m: float = 0.2):
    """Mid-stride (double support just after heel strike): left foot ahead, heel down and toe up; right foot
    behind on its toes, knee bent; arms swinging opposite to the legs."""
    return pose(pelvis=(0.0, 0.0, 0.895), chest=(0.03, 0.0, 1.415), head=(0.05, 0.0, 1.61),
                ankles=[(step_m, 0.085, 0.11), (-step_m, -0.085, 0.165)],
                feet=[(1.0, 0.05, 0.25), (1.0, -0.05, -0.7)],
                wrists=[(-0.13, 0.22, 0.88), (0.2, -0.2, 0.92)],
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
    return merge(figure(_walking(0.17), Outfit(sleeves="skin", shins="skin", girth=0.92)), ObjectClass.PEDESTRIAN)


PEDESTRIANS = (pedestrian, pedestrian_standing, pedestrian_coat, pedestrian_summer)
