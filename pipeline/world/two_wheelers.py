"""Bicycle and motorcycle body families, each with its rider (:mod:`.figures`), whose triangles are marked as the
rider's (:attr:`pipeline.world.mesh.Mesh.part`): one actor, cycle and rider, as KITTI's Cyclist and nuScenes box it;
the camera's labels give the rider a row of its own, as COCO's annotators box a rider as a person.

Frame and conventions as :mod:`pipeline.world.actor_shapes` (x forward, y left, z up, ground at z = 0, metres at
a typical size). Wheels are tori (tyre, ``rubber``; rim) about y with a hub; a bicycle's are thin with a few
spokes, so the ground shows through them. Frames, forks and bars are thin tubes between points; tanks, fairings,
seats and lamps are ellipsoids, so no two parts share a flat face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.figures import Outfit, figure, pose
from pipeline.world.mesh import Mesh
from pipeline.world.solids import Part, capsule, cylinder, ellipsoid, limb, merge, torus

Y = (0.0, 1.0, 0.0)


def _wheel(x: float, radius: float, tyre_m: float, spokes: int, rim_m: float) -> list[Part]:
    """A wheel standing on the ground at x: tyre torus of tube radius ``tyre_m``, rim torus inside it, a hub along
    y, and ``spokes`` bars (0: a solid rim disc of the rim's radius, as a motorcycle's cast wheel)."""
    centre = np.array([x, 0.0, radius])
    rim_r = radius - 2.0 * tyre_m
    parts = [torus(centre, radius - tyre_m, tyre_m, "rubber", 24, 8),
             torus(centre, rim_r, rim_m, "rim", 20, 4),
             cylinder(centre - [0, 0.06, 0], centre + [0, 0.06, 0], 0.03 if spokes else 0.06, "trim", 10)]
    if spokes:
        ang = np.linspace(0.0, np.pi, spokes, endpoint=False) + 0.2
        parts += [cylinder(centre - rim_r * np.array([np.cos(a), 0, np.sin(a)]),
                           centre + rim_r * np.array([np.cos(a), 0, np.sin(a)]), 0.006, "metal", 5, ref=Y)
                  for a in ang]
    else:
        parts.append(cylinder(centre - [0, rim_m, 0], centre + [0, rim_m, 0], rim_r, "trim", 20))  # dark cast wheel
    return parts


def _tubes(points: dict[str, tuple[float, float, float]], pairs: list[tuple[str, str]], radius: float,
           material: str) -> list[Part]:
    return [capsule(points[a], points[b], radius, radius, material, n=8, rings=1) for a, b in pairs]


DEVELOPMENT_M = 5.0  # distance a bicycle travels per crank turn: a mid gear (e.g. 42/18 on a 2.1 m tyre: 4.9 m)
CRANK_M = 0.17  # crank arm length
CRANK_PHASES = 8  # poses per crank turn (:class:`BicycleFamily`)


def _bicycle(sport: bool, crank_rad: float = np.radians(25.0),
             rider: Outfit | None = None) -> tuple[list[Part], list[Part]]:
    """A 1.75 m bicycle: 0.34 m wheels 1.06 m apart, diamond (sport) or step-through (city) frame in paint, saddle,
    bars, cranks at ``crank_rad`` (the right crank, from forward, counter-clockwise seen from the left), a white lamp
    on the bars and a red lamp and reflector under the saddle (lit with the lights at night, as the law asks, e.g.
    StVZO 67 and UK RVLR 1989), pedal reflectors; and its rider, feet on the pedals, upright (city) or leaning low
    over drop bars (sport, with a helmet). Returns the bicycle's parts and the rider's."""
    ax = 0.53
    pts = {"bb": (-0.05, 0.0, 0.3), "rear": (-ax, 0.0, 0.34), "front": (ax, 0.0, 0.34),
           "st": (-0.2, 0.0, 0.82 if sport else 0.72), "ht": (0.36, 0.0, 0.84 if sport else 0.8),
           "hb": (0.41, 0.0, 0.64), "low": (-0.14, 0.0, 0.55)}
    top = [("st", "ht")] if sport else [("low", "ht")]
    frame = _tubes(pts, [("bb", "st"), ("bb", "hb"), ("ht", "hb"), *top], 0.024, "paint")
    for s in (1.0, -1.0):  # chain and seat stays, fork blades, each side
        off = np.array([0.0, s * 0.045, 0.0])
        frame += [capsule(np.add(pts[a], off * (0.3 if a != "rear" and a != "front" else 1.0)),
                          np.add(pts[b], off), 0.012, 0.01, "paint" if b == "rear" else "metal", n=8, rings=1)
                  for a, b in (("bb", "rear"), ("st", "rear"), ("hb", "front"))]
    saddle_z = 0.98 if sport else 0.93
    bar_x, bar_z = (0.44, 0.93) if sport else (0.27, 1.04)
    parts = [*_wheel(-ax, 0.34, 0.022, 6, 0.011), *_wheel(ax, 0.34, 0.022, 6, 0.011), *frame,
             cylinder(pts["st"], (-0.23, 0.0, saddle_z - 0.02), 0.014, "metal", 8),
             ellipsoid((-0.22, 0.0, saddle_z), (0.13, 0.075, 0.03), "trim", 10, 6),
             capsule(pts["ht"], (0.34 if sport else 0.31, 0.0, bar_z + 0.02), 0.016, 0.016, "metal", 8, 1),
             cylinder((-0.05, -0.08, 0.3), (-0.05, 0.08, 0.3), 0.1, "metal", 16),  # chainring and axle
             ellipsoid((0.415, 0.0, 0.72), (0.035, 0.04, 0.03), "headlight", 10, 6),  # front lamp on the head tube
             ellipsoid((-0.25, 0.0, saddle_z - 0.09), (0.02, 0.035, 0.025), "taillight", 10, 6),  # on the seat post
             ellipsoid((-0.245, 0.0, saddle_z - 0.16), (0.012, 0.04, 0.03), "reflector_red", 10, 6)]
    if sport:
        bar = [(bar_x - 0.1, 0.2, bar_z - 0.12), (bar_x + 0.02, 0.2, bar_z - 0.08), (bar_x - 0.06, 0.2, bar_z),
               (bar_x - 0.08, 0.0, bar_z + 0.01), (bar_x - 0.06, -0.2, bar_z), (bar_x + 0.02, -0.2, bar_z - 0.08),
               (bar_x - 0.1, -0.2, bar_z - 0.12)]
    else:
        bar = [(bar_x - 0.12, 0.3, bar_z), (bar_x - 0.02, 0.24, bar_z), (bar_x + 0.04, 0.0, bar_z + 0.01),
               (bar_x - 0.02, -0.24, bar_z), (bar_x - 0.12, -0.3, bar_z)]
    parts.append(limb(bar, np.full(len(bar), 0.013), "trim", n=8, ref=(1.0, 0.0, 0.0)))
    hips = (-0.22, 0.0, saddle_z + 0.07)
    pedals = []
    for side, angle in ((1.0, crank_rad + np.pi), (-1.0, crank_rad)):  # left crank opposite the right one
        pedal = np.array([-0.05 + CRANK_M * np.cos(angle), side * 0.13, 0.3 + CRANK_M * np.sin(angle)])
        parts.append(capsule((-0.05, side * 0.1, 0.3), pedal - [0.0, side * 0.03, 0.0], 0.012, 0.012, "metal", 6, 1))
        parts.append(ellipsoid(pedal, (0.05, 0.045, 0.012), "trim", 8, 4))
        parts.append(ellipsoid(pedal + [0.0, side * 0.047, 0.0], (0.025, 0.006, 0.008), "reflector_white", 8, 4))
        pedals.append(pedal)
    lean = np.radians(48.0 if sport else 18.0)
    chest = np.add(hips, 0.52 * np.array([np.sin(lean), 0.0, np.cos(lean)]))
    head = chest + ([0.13, 0.0, 0.14] if sport else [0.05, 0.0, 0.19])
    grip = (bar_x - 0.04, 0.2, bar_z) if sport else (bar_x - 0.1, 0.28, bar_z)
    # The ball of the foot on the pedal: the ankle above and behind it, the sole pitched with the crank's angle.
    ankles = [p + [-0.07, 0.0, 0.075] for p in pedals]
    rider_pose = pose(hips, chest, head, ankles=ankles, feet=[(1.0, 0.0, -0.25), (1.0, 0.0, -0.25)],
                      wrists=[np.add(grip, (-0.05, 0.0, 0.02)), np.add(grip, (-0.05, -2 * grip[1], 0.02))],
                      hands=[(1.0, 0.0, -0.3), (1.0, 0.0, -0.3)], elbow_dir=(-0.3, 0.0, -1.0))
    if rider is None:
        rider = Outfit(top="garment", sleeves="skin", trousers="fabric_black", shins="skin") if sport else \
            Outfit(top="garment", sleeves="garment", trousers="denim", shins="denim")
    person = figure(rider_pose, rider)
    if sport:
        person.append(ellipsoid(head + [-0.02, 0.0, 0.045], (0.15, 0.105, 0.1), "paint", 12, 6))
    return parts, person


@dataclass(frozen=True)
class BicycleFamily:
    """A bicycle and its rider through a crank turn: calling it with pose k builds the crank at k / CRANK_PHASES of
    a turn (:func:`crank_poses` picks the pose from the distance ridden)."""

    name: str
    sport: bool
    rider: Outfit

    poses = CRANK_PHASES
    development_m = DEVELOPMENT_M

    @property
    def __name__(self) -> str:
        return self.name

    def __call__(self, pose: int = 0) -> Mesh:
        crank = 2.0 * np.pi * (pose % CRANK_PHASES) / CRANK_PHASES
        parts, rider = _bicycle(self.sport, crank, self.rider)
        return merge(parts, ObjectClass.BICYCLE, rider)


def bicycle() -> Mesh:
    """A city bicycle (step-through frame, upright bars) with an upright rider in a garment top and jeans."""
    parts, rider = _bicycle(sport=False)
    return merge(parts, ObjectClass.BICYCLE, rider)


def bicycle_sport() -> Mesh:
    """A road bicycle (diamond frame, drop bars) with a rider low over the bars, in a helmet and shorts."""
    parts, rider = _bicycle(sport=True)
    return merge(parts, ObjectClass.BICYCLE, rider)


def _motorcycle_rider(hips, lean_deg: float, ankles, grips, jacket: str) -> list[Part]:
    lean = np.radians(lean_deg)
    chest = np.add(hips, 0.52 * np.array([np.sin(lean), 0.0, np.cos(lean)]))
    head = chest + [0.1, 0.0, 0.17]
    rider = pose(hips, chest, head, ankles=ankles, feet=[(1.0, 0.0, -0.3), (1.0, 0.0, -0.3)],
                 wrists=[np.add(g, (-0.06, 0.0, 0.02)) for g in grips], hands=[(1.0, 0.0, -0.3), (1.0, 0.0, -0.3)],
                 knee_dir=[(1.0, 0.5, 0.3), (1.0, -0.5, 0.3)], elbow_dir=[(-0.3, 0.6, -1.0), (-0.3, -0.6, -1.0)])
    return figure(rider, Outfit(top=jacket, sleeves=jacket, trousers="cloth", shins="cloth", helmet="paint"))


def motorcycle() -> Mesh:
    """A 2.1 m sport motorcycle: fat tyres on cast rims, engine, tank, fairing with headlamp and screen, tail
    with lamp and plate, exhaust; a helmeted rider leaning forward onto clip-on bars."""
    ax = 0.72
    parts = [*_wheel(-ax, 0.31, 0.065, 0, 0.035), *_wheel(ax, 0.31, 0.065, 0, 0.035),
             ellipsoid((0.0, 0.0, 0.45), (0.33, 0.16, 0.19), "trim", 10, 6),
             ellipsoid((0.05, 0.0, 0.52), (0.16, 0.2, 0.12), "metal", 10, 6),
             ellipsoid((0.12, 0.0, 0.8), (0.32, 0.19, 0.15), "paint", 12, 6),
             ellipsoid((0.32, 0.0, 0.6), (0.3, 0.2, 0.17), "paint", 12, 6, axis=(0.5, 0.0, 1.0)),
             ellipsoid((0.56, 0.0, 0.75), (0.16, 0.2, 0.3), "paint", 12, 6, axis=(0.45, 0.0, 1.0)),
             ellipsoid((0.58, 0.0, 1.02), (0.05, 0.16, 0.13), "glass", 12, 6, axis=(0.7, 0.0, 1.0)),
             ellipsoid((0.71, 0.0, 0.74), (0.05, 0.08, 0.06), "headlight", 12, 6),
             ellipsoid((-0.33, 0.0, 0.82), (0.3, 0.14, 0.06), "trim", 10, 4),
             ellipsoid((-0.58, 0.0, 0.84), (0.27, 0.11, 0.09), "paint", 12, 6),
             ellipsoid((0.7, 0.0, 0.6), (0.22, 0.07, 0.03), "paint", 10, 4, axis=(0.5, 0.0, 1.0)),
             capsule((-0.3, 0.0, 0.45), (-0.45, 0.0, 0.78), 0.035, 0.035, "metal", 8, 1),
             ellipsoid((-0.9, 0.0, 0.88), (0.03, 0.07, 0.04), "taillight", 10, 6),
             ellipsoid((-0.88, 0.0, 0.7), (0.012, 0.1, 0.07), "plate", 10, 6),
             capsule((-0.15, -0.17, 0.3), (-0.78, -0.17, 0.55), 0.05, 0.055, "metal", 8, 2),
             cylinder((0.5, -0.33, 0.96), (0.5, 0.33, 0.96), 0.017, "trim", 8)]
    parts += [capsule((ax, s, 0.31), (0.5, s, 0.95), 0.028, 0.028, "metal", 8, 1) for s in (0.09, -0.09)]
    parts += [capsule((-ax, s, 0.31), (-0.05, s, 0.42), 0.035, 0.035, "trim", 8, 1) for s in (0.09, -0.09)]
    rider = _motorcycle_rider((-0.3, 0.0, 0.93), 45.0, [(-0.2, 0.19, 0.42), (-0.2, -0.19, 0.42)],
                              [(0.5, 0.28, 0.96), (0.5, -0.28, 0.96)], "trim")
    return merge(parts, ObjectClass.MOTORCYCLE, rider)


def scooter() -> Mesh:
    """A 1.9 m scooter: small wheels, a leg shield and step-through floor, a bulbous rear body under a long seat;
    an upright helmeted rider with the feet on the floor."""
    ax = 0.66
    parts = [*_wheel(-ax, 0.24, 0.055, 0, 0.03), *_wheel(ax, 0.24, 0.055, 0, 0.03),
             ellipsoid((0.52, 0.0, 0.62), (0.1, 0.22, 0.42), "paint", 12, 6, axis=(-0.25, 0.0, 1.0)),
             ellipsoid((0.08, 0.0, 0.33), (0.34, 0.17, 0.05), "trim", 12, 6),
             ellipsoid((-0.4, 0.0, 0.52), (0.45, 0.19, 0.22), "paint", 12, 6),
             ellipsoid((-0.3, 0.0, 0.76), (0.38, 0.15, 0.06), "trim", 12, 6),
             ellipsoid((0.56, 0.0, 1.0), (0.1, 0.12, 0.08), "paint", 12, 6),
             ellipsoid((0.64, 0.0, 0.99), (0.035, 0.07, 0.05), "headlight", 10, 6),
             ellipsoid((-0.84, 0.0, 0.66), (0.03, 0.08, 0.04), "taillight", 10, 6),
             ellipsoid((-0.8, 0.0, 0.48), (0.012, 0.09, 0.06), "plate", 10, 6),
             cylinder((0.44, -0.33, 1.02), (0.44, 0.33, 1.02), 0.017, "trim", 8),
             capsule((ax, 0.0, 0.24), (0.55, 0.0, 0.9), 0.035, 0.035, "trim", 8, 1)]
    rider = _motorcycle_rider((-0.2, 0.0, 0.86), 20.0, [(0.14, 0.15, 0.44), (0.14, -0.15, 0.44)],
                              [(0.4, 0.28, 1.02), (0.4, -0.28, 1.02)], "cloth")
    return merge(parts, ObjectClass.MOTORCYCLE, rider)


BICYCLES = (
    BicycleFamily("bicycle_city", False, Outfit(top="garment", sleeves="garment", trousers="denim", shins="denim")),
    BicycleFamily("bicycle_city_jacket", False, Outfit(
        top="fabric_beige", sleeves="fabric_beige", trousers="fabric_black", shins="fabric_black", hair="hair_brown",
        long_hair=True, backpack="fabric_grey")),
    BicycleFamily("bicycle_sport", True, Outfit(top="garment", sleeves="skin", trousers="fabric_black", shins="skin")),
    BicycleFamily("bicycle_commuter", True, Outfit(top="fabric_navy", sleeves="fabric_navy", trousers="fabric_grey",
                                                   shins="fabric_grey", skin="skin_medium", backpack="fabric_black")),
)
MOTORCYCLES = (motorcycle, scooter)
