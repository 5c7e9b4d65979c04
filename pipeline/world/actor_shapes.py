"""Shape recipes of the procedural actors (body families per class), in metres at a typical size of each.

Frame: x forward, y left, z up, origin on the ground under the box centre (normalisation to the unit box is
:func:`pipeline.world.actors.family_mesh`'s job, placement at each actor's size :mod:`pipeline.world.actors`').

Cars, vans and buses are lofted bodies (:mod:`pipeline.world.loft`: a rounded cross-section swept along a side
profile, with arches, glasshouse and pillars) with wheels (tyre, recessed rim, hub), door mirrors, and lamps,
plates and grille laid onto the end faces as decals; trucks have a lofted cab on boxes (cargo, trailer). Small
parts (mirrors, bumper bars) are convex solids (cuboids, or a convex profile extruded across y), whose outward
winding is fixed per part by facing away from its centre. Pedestrians (:mod:`pipeline.world.people`), bicycles and
motorcycles with their riders (:mod:`pipeline.world.two_wheelers`), prams and pushchairs (:mod:`pipeline.world.prams`)
are smooth closed solids (:mod:`pipeline.world.solids`), people dressed as figures (:mod:`pipeline.world.figures`).
:data:`FAMILIES` lists each class's families; :data:`SUITS_LENGTH_M` the lengths a family suits (a 16 m truck is a
tractor with a semi-trailer).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.loft import BodySpec, decal, loft, side_strip, surface_point
from pipeline.world.loft import wheel as loft_wheel
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.people import PEDESTRIANS
from pipeline.world.prams import STROLLERS
from pipeline.world.solids import Part, merge
from pipeline.world.two_wheelers import BICYCLES, MOTORCYCLES


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


def _mirrors(x: float, z: float, half_w: float, out_m: float = 0.11) -> list[Part]:
    """Door mirrors at the glasshouse's foot: a housing (paint) on each side reaching ``half_w + out_m``."""
    return mirrored(lambda y0, y1: cuboid((x - 0.06, y0, z), (x + 0.06, y1, z + 0.13), "paint"), half_w - 0.02,
                    half_w + out_m)


def _wheels(xs: tuple[float, ...], y_outer: float, radius: float, width: float = 0.22) -> list[Part]:
    return [loft_wheel(x, side * y_outer, radius, width) for x in xs for side in (1.0, -1.0)]


@dataclass(frozen=True)
class Ends:
    """Lamps, plates, grille and air intake on a body's end faces, as :func:`pipeline.world.loft.decal` quads
    (metres; z of centres above the ground; lamps centred at ``lamp_y`` of the half-width on each side). Lamps,
    grille and intake follow the face round its rounded corners (the lamps wrap into the wings, as real clusters
    do), and so does the front plate, standing proud of the intake; the rear plate is flat. A car's face reads by
    its lamps, grille and intake: two wide clusters with a dark grille between them and a dark intake below; thin
    lamps at the outer edges over a dark band read as a rear."""

    head_z: float
    tail_z: float
    plate_front_z: float
    plate_rear_z: float
    head_size: tuple[float, float] = (0.4, 0.15)
    tail_size: tuple[float, float] = (0.42, 0.17)
    lamp_y: float = 0.6
    grille: tuple[float, float] = (0.0, 0.13)  # (width, height) between the headlamps; width 0 = the gap between
    intake: tuple[float, float] | None = None  # (width, height) of a dark intake in the front bumper, round the plate
    bumper_z: float | None = None  # a dark band across the rear bumper's lower part (0.1 m tall)
    rear: bool = True  # False: the body's rear face is hidden (a truck's cab), no rear lamps or plate


LAMP_GRID = (8, 3)  # columns, rows of a conforming end decal (lamps, grille, intake)


def _end_decal(body: Part, y: float, z: float, size: tuple[float, float], material: str, end: str,
               conform: tuple[int, int] | None = LAMP_GRID, lift_m: float = 0.006) -> Part:
    """:func:`pipeline.world.loft.decal` on the body's ``end`` face, ``size`` (width, height); a decal that misses the
    face is an error in the family's numbers."""
    verts, tris, _ = body
    part = decal(verts, tris, y, z, size[0], size[1], material, end, lift_m=lift_m, conform=conform)
    if part is None:
        raise ValueError(f"{material} decal at y={y:.2f}, z={z:.2f} misses the body's {end} face")
    return part


def _side_strip(body: Part, points_xz: np.ndarray, width: float, material: str = "trim",
                lift_m: float = 0.004) -> Part:
    """:func:`pipeline.world.loft.side_strip` on the body's left (+y) side; one that misses the side is an error in
    the family's numbers."""
    verts, tris, _ = body
    strip = side_strip(verts, tris, points_xz, width, material, lift_m=lift_m)
    if strip is None:
        raise ValueError(f"side detail at x, z = {np.round(points_xz[0], 2).tolist()} misses the body's side")
    return strip


def _mirror_y(part: Part) -> Part:
    """The part mirrored across the body's centre plane (y -> -y), its winding reversed so it still faces out."""
    v, t, m = part
    return v * [1.0, -1.0, 1.0], t[:, ::-1], m


def _end_details(body: Part, half_w: float, ends: Ends) -> list[Part]:
    parts = []

    def put(y, z, size, material, end, conform=LAMP_GRID, lift_m=0.006):
        parts.append(_end_decal(body, y, z, size, material, end, conform, lift_m))

    lamp_y = ends.lamp_y * half_w
    for side in (1.0, -1.0):
        put(side * lamp_y, ends.head_z, ends.head_size, "headlight", "front")
        if ends.rear:
            put(side * lamp_y, ends.tail_z, ends.tail_size, "taillight", "rear")
    grille_w = ends.grille[0] or 2.0 * (lamp_y - 0.5 * ends.head_size[0]) - 0.08
    put(0.0, ends.head_z - 0.01, (grille_w, ends.grille[1]), "trim", "front")
    if ends.intake is not None:
        put(0.0, ends.plate_front_z, ends.intake, "trim", "front")
    # The front plate stands proud of the intake round it, following the nose's curve as the intake does (a flat
    # quad would cut behind the intake where the nose bends).
    put(0.0, ends.plate_front_z, (0.52, 0.12), "plate", "front", conform=(3, 3), lift_m=0.012)
    if ends.rear:
        put(0.0, ends.plate_rear_z, (0.52, 0.12), "plate_rear", "rear", conform=None)
    if ends.bumper_z is not None and ends.rear:
        put(0.0, ends.bumper_z, (1.5 * half_w, 0.1), "trim", "rear")
    return parts


@dataclass(frozen=True)
class Sides:
    """What breaks up a body's sides, as strips laid onto the surface (:func:`pipeline.world.loft.side_strip`) on
    both sides: door shut lines (dark gaps from the sill to the beltline; ``seams`` (u, z_low) with u along the body,
    0 rear, 1 front, and the height they start at, None for just above the sill), door handles just ahead of a
    door's rear edge at ``handles_u``, and horizontal ``bands`` (u0, u1, z, height): a van's sliding-door rail and
    rubbing strips. A flat unbroken side read to the detector as a wall or a box, not a car or a van."""

    seams: tuple[tuple[float, float | None], ...] = ()
    handles_u: tuple[float, ...] = ()
    bands: tuple[tuple[float, float, float, float], ...] = ()


SEAM_WIDTH_M = 0.012  # a shut line: a 3-5 mm gap whose shadowed inside reads about a centimetre wide
HANDLE_SIZE_M = (0.17, 0.035)


def _side_details(body: Part, spec: BodySpec, sides: Sides) -> list[Part]:
    verts, tris, _ = body
    belt = np.asarray(spec.belt, np.float64).T
    strips = []

    def put(points_xz, width):
        strips.append(_side_strip(body, points_xz, width))

    for u, z_low in sides.seams:
        x, top = (u - 0.5) * spec.length_m, float(np.interp(u, *belt)) - 0.015
        z0 = spec.sill_z_m + 0.05 if z_low is None else z_low
        # Where the underside rises towards an arch the side ends higher: start at the lowest height it covers.
        while z0 < top - 0.1 and surface_point(verts, tris, np.array([x, 1e3, z0]), np.array([0.0, -1.0, 0.0])) is None:
            z0 += 0.02
        put(np.column_stack([np.full(6, x), np.linspace(z0, top, 6)]), SEAM_WIDTH_M)
    for u in sides.handles_u:
        x, z = (u - 0.5) * spec.length_m, float(np.interp(u, *belt)) - 0.1
        put(np.array([[x - 0.5 * HANDLE_SIZE_M[0], z], [x, z], [x + 0.5 * HANDLE_SIZE_M[0], z]]), HANDLE_SIZE_M[1])
    for u0, u1, z, height in sides.bands:
        put(np.column_stack([(np.linspace(u0, u1, 8) - 0.5) * spec.length_m, np.full(8, z)]), height)
    return strips + [_mirror_y(strip) for strip in strips]


def _car_body(spec: BodySpec, mirror_u: float, ends: Ends, sides: Sides = Sides()) -> list[Part]:
    """A lofted car: body, four wheels set in the arches, door mirrors, lamps, plates and grille, door lines."""
    body = loft(spec)
    half = 0.5 * spec.width_m
    xs = tuple((u - 0.5) * spec.length_m for u in spec.wheels_u)
    belt_z = float(np.interp(mirror_u, *np.asarray(spec.belt).T))
    return [body, *_end_details(body, half, ends), *_side_details(body, spec, sides),
            *_wheels(xs, half - 0.03, spec.wheel_radius_m),
            *_mirrors((mirror_u - 0.5) * spec.length_m, belt_z, half * (1.0 - 0.5 * spec.tumblehome))]


def sedan() -> Mesh:
    """4.6 x 1.8 x 1.45 m saloon: three boxes (bonnet, cabin, boot), B and C pillars."""
    spec = BodySpec(4.6, 1.78, top=((0.0, 0.5), (0.006, 0.8), (0.025, 0.95), (0.2, 1.0), (0.27, 1.04),
                                     (0.37, 1.4), (0.43, 1.45), (0.57, 1.45), (0.71, 1.04), (0.76, 0.97),
                                     (0.92, 0.84), (0.98, 0.7), (1.0, 0.5)),
                    sill_z_m=0.3, belt=((0.0, 0.92), (0.35, 0.98), (0.72, 0.98), (1.0, 0.86)),
                    wheels_u=(0.19, 0.8), wheel_radius_m=0.31, glass_u=(0.33, 0.72), pillars_u=(0.53,))
    ends = Ends(head_z=0.68, tail_z=0.86, plate_front_z=0.5, plate_rear_z=0.63, bumper_z=0.47, intake=(1.0, 0.1))
    sides = Sides(seams=((0.712, None), (0.53, None), (0.278, None)), handles_u=(0.565, 0.313))
    return merge(_car_body(spec, 0.71, ends, sides), ObjectClass.CAR)


def hatchback() -> Mesh:
    """4.1 x 1.75 x 1.47 m hatchback: two boxes, a steep tailgate."""
    spec = BodySpec(4.1, 1.74, top=((0.0, 0.5), (0.006, 0.85), (0.02, 1.0), (0.05, 1.25), (0.09, 1.4), (0.16, 1.47),
                                     (0.55, 1.47), (0.69, 1.04), (0.75, 0.96), (0.93, 0.82), (0.98, 0.68),
                                     (1.0, 0.5)),
                    sill_z_m=0.3, belt=((0.0, 0.95), (0.5, 0.98), (1.0, 0.86)),
                    wheels_u=(0.16, 0.83), wheel_radius_m=0.3, glass_u=(0.1, 0.7), pillars_u=(0.47, 0.13))
    ends = Ends(head_z=0.64, tail_z=0.9, plate_front_z=0.49, plate_rear_z=0.68, bumper_z=0.48, intake=(0.95, 0.1))
    sides = Sides(seams=((0.735, None), (0.47, None), (0.255, None)), handles_u=(0.505, 0.29))
    return merge(_car_body(spec, 0.7, ends, sides), ObjectClass.CAR)


def estate() -> Mesh:
    """4.8 x 1.8 x 1.48 m estate: the roof runs to a near-vertical tailgate; three side windows."""
    spec = BodySpec(4.8, 1.8, top=((0.0, 0.5), (0.006, 0.85), (0.02, 1.0), (0.035, 1.25), (0.06, 1.42), (0.12, 1.48),
                                    (0.57, 1.48), (0.71, 1.04), (0.76, 0.97), (0.92, 0.84), (0.98, 0.7),
                                    (1.0, 0.5)),
                    sill_z_m=0.3, belt=((0.0, 0.96), (0.5, 0.98), (1.0, 0.86)),
                    wheels_u=(0.18, 0.81), wheel_radius_m=0.32, glass_u=(0.07, 0.72), pillars_u=(0.52, 0.27))
    ends = Ends(head_z=0.65, tail_z=0.9, plate_front_z=0.5, plate_rear_z=0.68, bumper_z=0.48, intake=(1.0, 0.1))
    sides = Sides(seams=((0.723, None), (0.52, None), (0.267, None)), handles_u=(0.555, 0.3))
    return merge(_car_body(spec, 0.72, ends, sides), ObjectClass.CAR)


def suv() -> Mesh:
    """4.7 x 1.9 x 1.72 m SUV: tall and boxy, high ground clearance, big wheels."""
    spec = BodySpec(4.7, 1.88, top=((0.0, 0.72), (0.015, 1.1), (0.04, 1.5), (0.08, 1.67), (0.14, 1.72),
                                     (0.6, 1.72), (0.71, 1.26), (0.76, 1.16), (0.93, 1.04), (0.985, 0.86),
                                     (1.0, 0.62)),
                    sill_z_m=0.42, belt=((0.0, 1.12), (0.5, 1.14), (1.0, 1.04)), tumblehome=0.14,
                    wheels_u=(0.17, 0.82), wheel_radius_m=0.37, glass_u=(0.08, 0.71), pillars_u=(0.5, 0.25),
                    corner_m=0.14)
    ends = Ends(head_z=0.88, tail_z=1.02, plate_front_z=0.64, plate_rear_z=0.84, bumper_z=0.62, intake=(1.1, 0.14))
    sides = Sides(seams=((0.721, None), (0.5, None), (0.269, None)), handles_u=(0.535, 0.3))
    return merge(_car_body(spec, 0.71, ends, sides), ObjectClass.CAR)


def coupe() -> Mesh:
    """4.4 x 1.82 x 1.32 m coupé: low, a long sloping rear window, no B pillar."""
    spec = BodySpec(4.4, 1.8, top=((0.0, 0.48), (0.006, 0.76), (0.03, 0.88), (0.22, 0.93), (0.38, 1.28),
                                    (0.47, 1.32), (0.56, 1.31), (0.69, 0.96), (0.75, 0.9), (0.93, 0.76),
                                    (0.98, 0.64), (1.0, 0.48)),
                    sill_z_m=0.28, belt=((0.0, 0.86), (0.5, 0.9), (1.0, 0.8)), tumblehome=0.26,
                    wheels_u=(0.19, 0.81), wheel_radius_m=0.32, glass_u=(0.36, 0.7))
    ends = Ends(head_z=0.6, tail_z=0.78, plate_front_z=0.46, plate_rear_z=0.58, bumper_z=0.44, intake=(1.0, 0.09))
    sides = Sides(seams=((0.716, None), (0.42, None)), handles_u=(0.455,))
    return merge(_car_body(spec, 0.69, ends, sides), ObjectClass.CAR)


# A van's cab door (its front edge above the front arch), a sliding door behind it with its rail running back at the
# beltline, handles, and a black rubbing strip between the arches.
VAN_SIDES = Sides(seams=((0.885, 0.76), (0.74, None), (0.455, None)), handles_u=(0.77, 0.69),
                  bands=((0.3, 0.455, 1.12, 0.035), (0.26, 0.74, 0.62, 0.1)))


def van() -> Mesh:
    """5.2 x 2.0 x 2.1 m panel van: one box, a short sloped bonnet and a steep windscreen; cab windows only."""
    spec = BodySpec(5.2, 1.96, top=((0.0, 0.6), (0.01, 1.9), (0.03, 2.08), (0.74, 2.1), (0.8, 1.8),
                                    (0.87, 1.22), (0.94, 1.08), (0.985, 0.88), (1.0, 0.6)),
                    sill_z_m=0.38, belt=((0.0, 1.1), (1.0, 1.1)), tumblehome=0.06, plan_taper=0.05,
                    wheels_u=(0.17, 0.83), wheel_radius_m=0.34, glass_u=(0.74, 0.86), corner_m=0.16)
    ends = Ends(head_z=0.9, tail_z=0.98, plate_front_z=0.6, plate_rear_z=0.72, head_size=(0.3, 0.2),
                tail_size=(0.2, 0.3), lamp_y=0.8, intake=(1.2, 0.14))
    return merge(_car_body(spec, 0.84, ends, VAN_SIDES), ObjectClass.VAN)


def minibus() -> Mesh:
    """5.3 x 2.0 x 2.2 m passenger van: the panel van with a band of side windows."""
    spec = BodySpec(5.3, 1.96, top=((0.0, 0.6), (0.01, 1.95), (0.03, 2.15), (0.74, 2.18), (0.8, 1.85),
                                    (0.87, 1.24), (0.94, 1.08), (0.985, 0.88), (1.0, 0.6)),
                    sill_z_m=0.38, belt=((0.0, 1.12), (1.0, 1.12)), tumblehome=0.06, plan_taper=0.05,
                    wheels_u=(0.17, 0.83), wheel_radius_m=0.34, glass_u=(0.74, 0.86),
                    extra_glass=((0.05, 0.7, 1.25, 1.85),), pillars_u=(0.28, 0.5), corner_m=0.16)
    ends = Ends(head_z=0.9, tail_z=0.98, plate_front_z=0.6, plate_rear_z=0.72, head_size=(0.3, 0.2),
                tail_size=(0.2, 0.3), lamp_y=0.8, intake=(1.2, 0.14))
    return merge(_car_body(spec, 0.84, ends, VAN_SIDES), ObjectClass.VAN)


def pickup() -> Mesh:
    """5.4 x 1.95 x 1.85 m pickup: cab, a load bed under a black tonneau cover, high clearance."""
    spec = BodySpec(5.4, 1.92, top=((0.0, 0.7), (0.01, 1.08), (0.4, 1.1), (0.415, 1.78), (0.44, 1.85),
                                    (0.62, 1.85), (0.71, 1.3), (0.76, 1.2), (0.94, 1.08), (0.99, 0.88),
                                    (1.0, 0.62)),
                    sill_z_m=0.45, belt=((0.0, 1.08), (0.5, 1.16), (1.0, 1.1)), tumblehome=0.1, plan_taper=0.05,
                    wheels_u=(0.17, 0.8), wheel_radius_m=0.38, glass_u=(0.43, 0.71), pillars_u=(0.56,))
    ends = Ends(head_z=0.92, tail_z=0.95, plate_front_z=0.64, plate_rear_z=0.8, head_size=(0.3, 0.15),
                tail_size=(0.18, 0.25), lamp_y=0.78, bumper_z=0.66, intake=(1.1, 0.14))
    cover = cuboid(((0.03 - 0.5) * 5.4, -0.7, 1.1), ((0.39 - 0.5) * 5.4, 0.7, 1.12), "trim")  # black tonneau cover
    sides = Sides(seams=((0.71, None), (0.56, None), (0.43, None)), handles_u=(0.595, 0.465))
    return merge([*_car_body(spec, 0.71, ends, sides), cover], ObjectClass.CAR)


def _truck_rear(x: float, z_lamp: float, half_w: float) -> list[Part]:
    """A truck's rear: a bumper bar (trim), tail lamps and a plate on it, facing -x at ``x``."""
    return [cuboid((x - 0.1, -half_w + 0.05, z_lamp - 0.16), (x, half_w - 0.05, z_lamp - 0.04), "trim"),
            *[cuboid((x - 0.04, y0, z_lamp - 0.04), (x + 0.02, y1, z_lamp + 0.1), "taillight")
              for y0, y1 in ((half_w - 0.45, half_w - 0.1), (-half_w + 0.1, -half_w + 0.45))],
            cuboid((x - 0.14, -0.26, z_lamp - 0.15), (x - 0.1, 0.26, z_lamp - 0.04), "plate_rear")]


def _cab(length_m: float, width_m: float, height_m: float, x_front: float) -> list[Part]:
    """A cab-over truck cab: lofted with a big windscreen, lamps, grille and plate in front, at x up to
    ``x_front``."""
    h = height_m
    spec = BodySpec(length_m, width_m, top=((0.0, h - 0.15), (0.55, h), (0.8, h - 0.1), (0.93, h - 0.85),
                                            (0.97, h - 1.55), (1.0, h - 1.95)),
                    sill_z_m=0.55, belt=((0.0, h - 1.2), (1.0, h - 1.2)), tumblehome=0.04, plan_taper=0.04,
                    wheels_u=(0.55,), wheel_radius_m=0.5, glass_u=(0.4, 0.8), corner_m=0.2, arch_clearance_m=0.08)
    v, t, m = loft(spec)
    shift = np.array([x_front - 0.5 * length_m, 0.0, 0.0])
    ends = Ends(head_z=0.9, tail_z=0.0, plate_front_z=0.68, plate_rear_z=0.0, head_size=(0.3, 0.15), lamp_y=0.78,
                grille=(1.0, 0.24), rear=False)
    return [(p[0] + shift, p[1], p[2]) for p in [(v, t, m), *_end_details((v, t, m), 0.5 * width_m, ends)]]


def _cargo_details(x_rear: float, x_front: float, half_w: float, z0: float, z1: float) -> list[Part]:
    """What makes a cargo box read as one: on its rear face (at ``x_rear``, facing -x) an aluminium frame, the seam
    between two doors and four locking bars (standing further out), red clearance lamps at the top corners and
    retroreflective tape (red and white, as ECE R48/R104 require) along the bottom and up the corners; along each
    side a rub rail at the bottom, a rail at the top, white tape segments and amber marker lamps."""
    d, e, w = 0.015, 0.035, 0.08
    rear = [cuboid((x_rear - d, -half_w, z0), (x_rear, half_w, z0 + w), "metal"),
            cuboid((x_rear - d, -half_w, z1 - w), (x_rear, half_w, z1), "metal"),
            *mirrored(lambda y0, y1: cuboid((x_rear - d, y0, z0 + w), (x_rear, y1, z1 - w), "metal"), half_w - w,
                      half_w),
            cuboid((x_rear - d, -0.02, z0 + w), (x_rear, 0.02, z1 - w), "trim")]
    bars = [cuboid((x_rear - e, y - 0.02, z0 + 0.2), (x_rear - d, y + 0.02, z1 - 0.2), "metal")
            for y in (-0.72 * half_w, -0.28 * half_w, 0.28 * half_w, 0.72 * half_w)]
    rails = [part for z_lo, z_hi in ((z0, z0 + 0.1), (z1 - 0.07, z1))
             for part in mirrored(lambda y0, y1, z_lo=z_lo, z_hi=z_hi: cuboid((x_rear, y0, z_lo), (x_front, y1, z_hi),
                                                                               "trim"), half_w, half_w + d)]
    lamps = mirrored(lambda y0, y1: cuboid((x_rear - 2 * d, y0, z1 - 0.16), (x_rear - d, y1, z1 - 0.1), "taillight"),
                     half_w - 0.2, half_w - 0.06)
    tape = []
    n = max(2, int(2 * half_w / 0.3))  # across the bottom of the rear: alternating 0.3 m segments
    ys = np.linspace(-half_w + w, half_w - w, n + 1)
    tape += [cuboid((x_rear - 2 * d, ys[k], z0 + w + 0.02), (x_rear - d, ys[k + 1], z0 + w + 0.07),
                    "reflector_red" if k % 2 else "reflector_white") for k in range(n)]
    zs = np.linspace(z0 + w + 0.1, z1 - w - 0.2, 6)  # up the rear corners, beside the frame
    tape += [part for k in range(5) for part in mirrored(
        lambda y0, y1, k=k: cuboid((x_rear - 2 * d, y0, zs[k]), (x_rear - d, y1, zs[k + 1]),
                                   "reflector_white" if k % 2 else "reflector_red"), half_w - w - 0.05, half_w - w)]
    xs = np.arange(x_rear + 0.3, x_front - 0.3, 0.9)  # white segments along each side's bottom rail
    tape += [part for x in xs for part in mirrored(
        lambda y0, y1, x=x: cuboid((x, y0, z0 + 0.12), (x + 0.45, y1, z0 + 0.17), "reflector_white"), half_w,
        half_w + d)]
    # amber side marker lamps along each side's bottom rail, at most 3 m apart (ECE R48)
    count = max(2, int(np.ceil((x_front - x_rear) / 3.0)) + 1)
    markers = [part for x in np.linspace(x_rear + 0.25, x_front - 0.25, count) for part in mirrored(
        lambda y0, y1, x=x: cuboid((x - 0.06, y0, z0 + 0.02), (x + 0.06, y1, z0 + 0.09), "marker_lamp"), half_w + d,
        half_w + 2 * d)]
    return [*rear, *bars, *rails, *lamps, *tape, *markers]


def _chassis_guards(x_front: float, x_rear: float, half_w: float, rear_axle_x: float, tyre_r: float) -> list[Part]:
    """Side underrun guards (two rails between the axles, from ``x_front`` back to ``x_rear``) and mud flaps
    behind the rearmost axle."""
    rails = [part for z_lo, z_hi in ((0.42, 0.5), (0.72, 0.78))
             for part in mirrored(lambda y0, y1, z_lo=z_lo, z_hi=z_hi: cuboid((x_rear, y0, z_lo), (x_front, y1, z_hi),
                                                                               "metal"), half_w - 0.08, half_w - 0.03)]
    flaps = mirrored(lambda y0, y1: cuboid((rear_axle_x - tyre_r - 0.06, y0, 0.18), (rear_axle_x - tyre_r - 0.04, y1,
                                                                                      0.2 + tyre_r * 1.3), "rubber"),
                     half_w - 0.55, half_w - 0.05)
    return [*rails, *flaps]


def _ladder_frame(x_rear: float, x_front: float, z_top: float, axles_x: tuple[float, ...]) -> list[Part]:
    """What a rigid truck carries under its body: two frame rails (0.86 m apart outside, as truck ladder frames
    are) from the box's rear end, where they meet the rear underrun bar, and an axle housing with its differential
    at each rear axle. Seen from behind, the road shows between them under the box; a solid dark block the box's
    width there, with lamps and a plate on its bar, read to the detector as the rear of a car."""
    rails = mirrored(lambda y0, y1: cuboid((x_rear, y0, z_top - 0.3), (x_front, y1, z_top), "trim"), 0.28, 0.43)
    axles = [part for x in axles_x for part in (cuboid((x - 0.08, -0.95, 0.44), (x + 0.08, 0.95, 0.56), "trim"),
                                                 cuboid((x - 0.22, -0.18, 0.36), (x + 0.18, 0.18, 0.66), "trim"))]
    return [*rails, *axles]


def box_truck() -> Mesh:
    """8.0 x 2.5 x 3.5 m rigid truck: a rounded cab with a big windscreen, a cargo box on a ladder frame, six
    wheels."""
    cargo = cuboid((-4.0, -1.25, 0.95), (1.85, 1.25, 3.5), "cargo")
    wheels = _wheels((4.0 - 2.1 + 0.55 * 2.1, -1.6, -2.8), 1.22, 0.5, 0.3)
    frame = _ladder_frame(-4.0, 2.0, 0.95, (-1.6, -2.8))
    return merge([*_cab(2.1, 2.4, 2.95, 4.0), *frame, cargo, *_cargo_details(-4.0, 1.85, 1.25, 0.95, 3.5),
                  *_truck_rear(-4.0, 0.7, 1.22), *wheels, *_chassis_guards(2.35, -1.0, 1.25, -2.8, 0.5)],
                 ObjectClass.TRUCK)


def _articulated(trailer_material: str, sides: list[Part]) -> Mesh:
    """16 x 2.55 x 4.0 m tractor with a semi-trailer: cab over engine with a roof fairing up to the trailer's height
    (as long-haul tractors have), a gap, the trailer (its body of ``trailer_material``, with ``sides`` laid on it)
    on three axles."""
    frame = cuboid((3.0, -0.85, 0.55), (6.9, 0.85, 1.0), "trim")
    fairing = prism_y([(5.75, 3.1), (7.3, 3.1), (6.05, 3.95), (5.75, 3.95)], -1.15, 1.15, "paint", "paint")
    trailer = cuboid((-8.0, -1.275, 1.25), (4.6, 1.275, 4.0), trailer_material)
    chassis = _ladder_frame(-8.0, 4.6, 1.25, (-5.2, -6.3, -7.4))
    wheels = _wheels((8.0 - 2.3 + 0.55 * 2.3, 4.0, 2.7, -5.2, -6.3, -7.4), 1.24, 0.52, 0.32)
    return merge([*_cab(2.3, 2.45, 3.2, 8.0), frame, fairing, trailer, *chassis,
                  *_cargo_details(-8.0, 4.6, 1.275, 1.25, 4.0), *sides, *_truck_rear(-8.0, 1.05, 1.25), *wheels,
                  *_chassis_guards(2.1, -4.6, 1.275, -7.4, 0.52)],
                 ObjectClass.TRUCK)


def semi_trailer() -> Mesh:
    """16 x 2.55 x 4.0 m tractor with a box semi-trailer (smooth aluminium-skinned panels)."""
    return _articulated("cargo", [])


def curtain_trailer() -> Mesh:
    """16 x 2.55 x 4.0 m tractor with a curtainsider semi-trailer, the commonest European trailer: matte curtains
    pulled tight by straps every 0.55 m, each with a metal buckle above the bottom rail."""
    x_rear, x_front, half_w, z0, z1 = -8.0, 4.6, 1.275, 1.25, 4.0
    xs = np.arange(x_rear + 0.4, x_front - 0.2, 0.55)
    straps = [part for x in xs for part in mirrored(
        lambda y0, y1, x=x: cuboid((x - 0.022, y0, z0 + 0.105), (x + 0.022, y1, z1 - 0.08), "trim"), half_w - 0.002,
        half_w + 0.008)]  # (their inner faces inside the curtain, the buckles' inside the straps: none coplanar)
    buckles = [part for x in xs for part in mirrored(
        lambda y0, y1, x=x: cuboid((x - 0.03, y0, z0 + 0.19), (x + 0.03, y1, z0 + 0.33), "metal"), half_w + 0.004,
        half_w + 0.014)]
    return _articulated("tarpaulin", [*straps, *buckles])


def bus() -> Mesh:
    """12 x 2.55 x 3.2 m city bus: boxy rounded body, a window band, a deep windscreen, two axles."""
    spec = BodySpec(12.0, 2.55, top=((0.0, 3.0), (0.02, 3.18), (0.97, 3.2), (0.995, 3.0), (1.0, 2.8)),
                    sill_z_m=0.35, belt=((0.0, 1.25), (1.0, 1.2)), tumblehome=0.03, plan_taper=0.02,
                    wheels_u=(0.22, 0.82), wheel_radius_m=0.5, glass_u=(2.0, 2.0),
                    extra_glass=((0.03, 0.965, 1.3, 2.75), (0.97, 1.01, 1.0, 2.95)),
                    pillars_u=(0.12, 0.24, 0.36, 0.48, 0.6, 0.72, 0.84), pillar_w_m=0.12, corner_m=0.25,
                    arch_clearance_m=0.06,
                    n_stations=40)
    ends = Ends(head_z=0.7, tail_z=1.05, plate_front_z=0.5, plate_rear_z=0.6, head_size=(0.3, 0.18),
                tail_size=(0.22, 0.75), lamp_y=0.86, grille=(0.9, 0.25), bumper_z=0.42)
    parts = _car_body(spec, 0.985, ends)
    return merge([*parts, *_bus_ends(parts[0], 0.5 * 2.55), *_bus_doors(parts[0], spec)], ObjectClass.BUS)


def _bus_doors(body: Part, spec: BodySpec) -> list[Part]:
    """Two glazed double doors on the kerb (right, -y) side, from just above the sill to the top of the window band:
    one ahead of the front axle, one in the middle, each split down its centre."""
    parts = []
    for u0, u1 in ((0.875, 0.965), (0.49, 0.59)):
        x0, x1 = (u0 - 0.5) * spec.length_m, (u1 - 0.5) * spec.length_m
        column = np.column_stack([np.full(27, 0.5 * (x0 + x1)), np.linspace(spec.sill_z_m + 0.12, 2.72, 27)])
        for width, material, lift_m in ((x1 - x0, "glass", 0.006), (0.04, "trim", 0.01)):
            parts.append(_mirror_y(_side_strip(body, column, width, material, lift_m)))  # laid on the left side
    return parts


def _bus_ends(body: Part, half_w: float) -> list[Part]:
    """What a city bus shows at its ends besides lamps and plates: at the rear a window over the engine bay, the
    engine's louvres below it and a route-number display above; at the front the windscreen (the body's glass band
    wraps round the front corners only) and above it a destination display (a dark panel with amber LED lettering,
    lit at night like the markers). Without them both ends were blank painted panels, and seen from behind, a bus
    with two small lamps was missed by the detector."""
    def put(z, size, material, end, y=0.0, lift_m=0.006):
        return _end_decal(body, y, z, size, material, end, lift_m=lift_m)

    width = 2.0 * half_w
    rear = [put(2.37, (width - 0.3, 0.85), "glass", "rear"),
            put(2.9, (0.5, 0.12), "trim", "rear"),
            *[put(z, (0.55 * width, 0.05), "trim", "rear") for z in np.linspace(0.85, 1.45, 5)]]
    front = [put(1.85, (width - 0.2, 1.6), "glass", "front"),
             put(2.8, (width - 0.5, 0.24), "trim", "front"),
             *[put(2.8, (w, 0.09), "marker_lamp", "front", y, 0.012) for y, w in ((-0.45, 0.5), (0.35, 0.8))]]
    return [*rear, *front]


# Body families per class, in a fixed order (an actor's variant picks one among those that suit its length).
FAMILIES: dict[ObjectClass, tuple[Callable[[], Mesh], ...]] = {
    ObjectClass.CAR: (sedan, hatchback, estate, suv, coupe, pickup),
    ObjectClass.VAN: (van, minibus),
    ObjectClass.TRUCK: (box_truck, semi_trailer, curtain_trailer),
    ObjectClass.BUS: (bus,),
    ObjectClass.MOTORCYCLE: MOTORCYCLES,
    ObjectClass.BICYCLE: BICYCLES,
    ObjectClass.PEDESTRIAN: PEDESTRIANS,
    ObjectClass.STROLLER: STROLLERS,
}
# The length range (metres) each family suits; a family outside its range is chosen only when none suits.
SUITS_LENGTH_M: dict[Callable[[], Mesh], tuple[float, float]] = {
    hatchback: (0.0, 4.4), sedan: (4.2, 99.0), estate: (4.4, 99.0), suv: (4.2, 99.0), coupe: (4.0, 4.9),
    pickup: (4.9, 99.0), box_truck: (0.0, 11.0), semi_trailer: (11.0, 99.0), curtain_trailer: (11.0, 99.0),
}
