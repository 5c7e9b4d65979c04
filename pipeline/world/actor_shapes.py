"""Shape recipes of the procedural actors, in metres at a typical size of each class.

Frame: x forward, y left, z up, origin on the ground under the box centre (normalisation to the unit
box is :func:`pipeline.world.actors.canonical_mesh`'s job). Every part is a convex solid (cuboid or a
convex profile extruded across y), so outward winding is fixed per part by facing away from its centre.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh

Part = tuple[np.ndarray, np.ndarray, np.ndarray]  # vertices (V, 3), triangles (T, 3), material (T,)


def _outward(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Flip triangles of a convex solid whose normal points towards the solid's centre."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", normal, (a + b + c) / 3.0 - vertices.mean(axis=0)) < 0
    triangles = triangles.copy()
    triangles[inward] = triangles[inward][:, ::-1]
    return triangles


def prism_y(profile_xz: list[tuple[float, float]], y0: float, y1: float, cap: str, sides: str | list[str]) -> Part:
    """A convex (x, z) profile extruded from y0 to y1; ``sides`` is one material or one per profile edge."""
    prof = np.asarray(profile_xz, dtype=np.float64)
    p = len(prof)
    verts = np.concatenate([np.column_stack([prof[:, 0], np.full(p, y), prof[:, 1]]) for y in (y0, y1)])
    fan = [(0, i, i + 1) for i in range(1, p - 1)]
    caps = [*fan, *[(p + a, p + b, p + c) for a, b, c in fan]]
    quads = [t for i in range(p) for t in ((i, (i + 1) % p, p + (i + 1) % p), (i, p + (i + 1) % p, p + i))]
    tris = np.array(caps + quads, dtype=np.int64)
    side_names = [sides] * p if isinstance(sides, str) else list(sides)
    if len(side_names) != p:
        raise ValueError(f"{len(side_names)} side materials for a profile of {p} edges")
    mats = [material_index(cap)] * len(caps) + [material_index(n) for n in side_names for _ in range(2)]
    return verts, _outward(verts, tris), np.array(mats, dtype=np.int32)


def cuboid(lo: tuple[float, float, float], hi: tuple[float, float, float], material: str) -> Part:
    """Axis-aligned box from corner ``lo`` to corner ``hi``."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    return prism_y([(x0, z0), (x1, z0), (x1, z1), (x0, z1)], y0, y1, material, material)


def wheel(x: float, z: float, radius: float, y0: float, y1: float, material: str = "rubber", n: int = 12) -> Part:
    """A cylinder about the y axis (a wheel), as an n-gon prism."""
    ang = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return prism_y(list(zip(x + radius * np.cos(ang), z + radius * np.sin(ang), strict=True)), y0, y1, material,
                   material)


def mirrored(part_fn: Callable[[float, float], Part], y0: float, y1: float) -> list[Part]:
    """A part at y in [y0, y1] and its mirror image at [-y1, -y0]."""
    return [part_fn(y0, y1), part_fn(-y1, -y0)]


def merge(parts: list[Part], semantic_class: ObjectClass) -> Mesh:
    offsets = np.cumsum([0] + [len(v) for v, _, _ in parts[:-1]])
    return Mesh(
        np.concatenate([v for v, _, _ in parts]),
        np.concatenate([t + o for (_, t, _), o in zip(parts, offsets, strict=True)]),
        np.concatenate([m for _, _, m in parts]),
        semantic_class.semantic,
    )


def _lights(x_front: float, x_rear: float, y_in: float, y_out: float, z_head: tuple[float, float],
            z_tail: tuple[float, float], plate_z: tuple[float, float], plate_half_w: float) -> list[Part]:
    """Head lights, tail lights and plates as 2 cm thick plaques proud of the front and rear faces."""
    d = 0.02
    parts = []
    for y0, y1 in ((y_in, y_out), (-y_out, -y_in)):
        parts.append(cuboid((x_front - d, y0, z_head[0]), (x_front + d, y1, z_head[1]), "headlight"))
        parts.append(cuboid((x_rear - d, y0, z_tail[0]), (x_rear + d, y1, z_tail[1]), "taillight"))
    for x in (x_front, x_rear):
        parts.append(cuboid((x - d, -plate_half_w, plate_z[0]), (x + d, plate_half_w, plate_z[1]), "plate"))
    return parts


def car() -> Mesh:
    """4.5 x 1.8 x 1.5 m saloon: body, glass cabin with painted roof, four wheels, lights, plates."""
    body = prism_y([(-2.25, 0.30), (2.25, 0.30), (2.25, 0.72), (1.9, 0.86), (-2.25, 0.90)], -0.9, 0.9, "paint",
                   "paint")
    cabin = prism_y([(-1.95, 0.85), (0.95, 0.85), (0.15, 1.5), (-1.55, 1.5)], -0.78, 0.78, "glass",
                    ["paint", "glass", "paint", "glass"])
    wheels = [wheel(x, 0.32, 0.32, y0, y1) for x in (1.4, -1.35) for y0, y1 in ((0.62, 0.86), (-0.86, -0.62))]
    return merge([body, cabin, *wheels, *_lights(2.25, -2.25, 0.5, 0.8, (0.55, 0.68), (0.66, 0.8), (0.36, 0.48),
                                                  0.26)], ObjectClass.CAR)


def van() -> Mesh:
    """5.0 x 2.0 x 2.2 m van: boxy body with a sloped windscreen, side windows at the cab."""
    body = prism_y([(-2.5, 0.32), (2.5, 0.32), (2.5, 0.95), (1.75, 1.25), (-2.5, 1.25)], -1.0, 1.0, "paint", "paint")
    upper = prism_y([(-2.5, 1.24), (1.75, 1.24), (1.0, 2.2), (-2.5, 2.2)], -1.0, 1.0, "paint",
                    ["paint", "glass", "paint", "paint"])
    windows = mirrored(lambda y0, y1: cuboid((0.45, y0, 1.35), (1.25, y1, 1.95), "glass"), 0.98, 1.01)
    wheels = [wheel(x, 0.34, 0.34, y0, y1) for x in (1.6, -1.7) for y0, y1 in ((0.7, 0.95), (-0.95, -0.7))]
    return merge([body, upper, *windows, *wheels, *_lights(2.5, -2.5, 0.55, 0.9, (0.7, 0.85), (0.8, 1.1),
                                                           (0.4, 0.52), 0.26)], ObjectClass.VAN)


def truck() -> Mesh:
    """8.0 x 2.5 x 3.5 m rigid truck: chassis, painted cab with windscreen, cargo box, six wheels."""
    chassis = cuboid((-4.0, -1.0, 0.45), (3.99, 1.0, 0.95), "rubber")  # not flush with the cab's front (no tie)
    cab = cuboid((2.1, -1.25, 0.6), (4.0, 1.25, 3.0), "paint")
    screen = cuboid((3.98, -1.1, 1.85), (4.02, 1.1, 2.8), "glass")
    side = mirrored(lambda y0, y1: cuboid((2.6, y0, 1.85), (3.7, y1, 2.7), "glass"), 1.23, 1.27)
    cargo = cuboid((-4.0, -1.25, 0.95), (1.95, 1.25, 3.5), "cargo")
    wheels = [wheel(x, 0.5, 0.5, y0, y1) for x in (3.1, -1.6, -2.8) for y0, y1 in ((0.9, 1.22), (-1.22, -0.9))]
    return merge([chassis, cab, screen, *side, cargo, *wheels,
                  *_lights(4.0, -4.0, 0.7, 1.1, (0.75, 0.94), (0.6, 0.8), (0.5, 0.66), 0.28)], ObjectClass.TRUCK)


def bus() -> Mesh:
    """12 x 2.55 x 3.2 m bus: painted body, window bands, windscreen, four wheels."""
    body = cuboid((-6.0, -1.275, 0.35), (6.0, 1.275, 3.2), "paint")
    band = mirrored(lambda y0, y1: cuboid((-5.6, y0, 1.45), (5.2, y1, 2.75), "glass"), 1.255, 1.295)
    screen = cuboid((5.98, -1.15, 1.0), (6.02, 1.15, 2.95), "glass")
    rear = cuboid((-6.02, -1.0, 1.9), (-5.98, 1.0, 2.8), "glass")
    wheels = [wheel(x, 0.5, 0.5, y0, y1) for x in (4.1, -3.4) for y0, y1 in ((0.9, 1.2), (-1.2, -0.9))]
    return merge([body, *band, screen, rear, *wheels,
                  *_lights(6.0, -6.0, 0.75, 1.15, (0.5, 0.7), (0.6, 0.85), (0.45, 0.6), 0.28)], ObjectClass.BUS)


def _rider(x_seat: float, z_seat: float, x_hands: float, z_hands: float) -> list[Part]:
    """A seated rider: legs, torso (shirt in the actor's paint), arms, helmeted head."""
    return [
        *mirrored(lambda y0, y1: cuboid((x_seat - 0.1, y0, z_seat - 0.55), (x_seat + 0.3, y1, z_seat), "cloth"),
                  0.04, 0.17),
        cuboid((x_seat - 0.15, -0.2, z_seat), (x_seat + 0.12, 0.2, z_seat + 0.55), "paint"),
        *mirrored(lambda y0, y1: cuboid((x_seat, y0, z_hands), (x_hands, y1, z_seat + 0.5), "paint"), 0.17, 0.25),
        cuboid((x_seat - 0.1, -0.11, z_seat + 0.58), (x_seat + 0.14, 0.11, z_seat + 0.85), "rubber"),
    ]


def motorcycle() -> Mesh:
    """2.2 x 0.8 x 1.5 m motorcycle with rider."""
    wheels = [wheel(x, 0.32, 0.32, -0.07, 0.07) for x in (0.78, -0.78)]
    body = prism_y([(-0.7, 0.45), (0.6, 0.4), (0.62, 0.85), (-0.75, 0.8)], -0.18, 0.18, "paint", "paint")
    bars = cuboid((0.48, -0.4, 0.9), (0.56, 0.4, 0.96), "metal")
    lights = [cuboid((0.6, -0.08, 0.72), (0.66, 0.08, 0.82), "headlight"),
              cuboid((-0.81, -0.08, 0.7), (-0.75, 0.08, 0.78), "taillight"),
              cuboid((-0.83, -0.09, 0.52), (-0.79, 0.09, 0.64), "plate")]
    # Hands just above the bars' underside: coplanar faces of two materials would make the hit's material a tie.
    return merge([*wheels, body, bars, *lights, *_rider(-0.2, 0.85, 0.5, 0.91)], ObjectClass.MOTORCYCLE)


def bicycle() -> Mesh:
    """1.8 x 0.6 x 1.75 m bicycle with rider."""
    wheels = [wheel(x, 0.34, 0.34, -0.02, 0.02, n=16) for x in (0.52, -0.52)]
    frame = [cuboid((-0.5, -0.03, 0.3), (0.5, 0.03, 0.38), "metal"),
             cuboid((-0.25, -0.03, 0.38), (-0.18, 0.03, 0.95), "metal"),
             cuboid((0.38, -0.03, 0.38), (0.45, 0.03, 1.05), "metal"),
             cuboid((0.36, -0.3, 1.02), (0.46, 0.3, 1.08), "metal")]
    legs = mirrored(lambda y0, y1: cuboid((-0.3, y0, 0.45), (0.0, y1, 0.95), "cloth"), 0.04, 0.15)
    return merge([*wheels, *frame, *_rider(-0.22, 0.95, 0.42, 1.05)[2:], *legs], ObjectClass.BICYCLE)


def pedestrian() -> Mesh:
    """0.5 x 0.6 x 1.75 m walking person: legs mid-stride, torso (paint), arms, head."""
    return merge([
        cuboid((0.03, 0.02, 0.0), (0.25, 0.15, 0.88), "cloth"),
        cuboid((-0.25, -0.15, 0.0), (-0.03, -0.02, 0.88), "cloth"),
        cuboid((-0.12, -0.2, 0.86), (0.12, 0.2, 1.45), "paint"),
        *mirrored(lambda y0, y1: cuboid((-0.08, y0, 0.8), (0.08, y1, 1.43), "paint"), 0.2, 0.3),
        cuboid((-0.05, -0.06, 1.44), (0.05, 0.06, 1.52), "skin"),
        cuboid((-0.11, -0.1, 1.52), (0.11, 0.1, 1.75), "skin"),
    ], ObjectClass.PEDESTRIAN)


SHAPES: dict[ObjectClass, Callable[[], Mesh]] = {
    ObjectClass.CAR: car,
    ObjectClass.VAN: van,
    ObjectClass.TRUCK: truck,
    ObjectClass.BUS: bus,
    ObjectClass.MOTORCYCLE: motorcycle,
    ObjectClass.BICYCLE: bicycle,
    ObjectClass.PEDESTRIAN: pedestrian,
}
