"""Lofted vehicle bodies: a closed cross-section swept along the vehicle's length, with materials by region.

Frame: x forward, y left, z up, metres, origin on the ground under the body's centre (as
:mod:`pipeline.world.actor_shapes`). A body is described by its side profile (top and bottom heights along x),
its plan (half-width along x), a beltline (where the glasshouse starts and the sides tuck in towards the roof)
and rounded corners; every station's cross-section has the same number of points, so the surface is one grid of
quads. Materials are given per quad by where it lies (glasshouse band, windscreen, lamps, plates, grille, lower
trim), so parts are regions of one smooth surface, not boxes stuck on a box.

The cross-section (right half, mirrored to the left) runs from the bottom centre outwards: flat underside, a
rounded lower corner, the body side up to the beltline, the glasshouse side tucked in by ``tumblehome``, a
rounded roof corner, the roof to the centre line. Where the roof is below the beltline (bonnet, boot) the
glasshouse segment has no height and the roof corner rounds the body's shoulder.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pipeline.world.materials import material_index

# Points per segment of the half cross-section (bottom, lower corner, side, glasshouse side, roof corner, roof).
SEGMENTS = (("bottom", 2), ("lower_corner", 3), ("side", 4), ("glass_side", 3), ("roof_corner", 3), ("roof", 3))


def _interp(u: np.ndarray, points: tuple[tuple[float, float], ...]) -> np.ndarray:
    """The piecewise-linear function through (u, value) points, at ``u`` (:func:`_smooth` rounds its corners)."""
    p = np.asarray(points, np.float64)
    return np.interp(u, p[:, 0], p[:, 1])


def _smooth(values: np.ndarray, passes: int = 2) -> np.ndarray:
    """A [1, 2, 1] / 4 filter along the stations, ``passes`` times (the end values are kept)."""
    v = values.copy()
    for _ in range(passes):
        v[1:-1] = 0.25 * v[:-2] + 0.5 * v[1:-1] + 0.25 * v[2:]
    return v


@dataclass(frozen=True)
class BodySpec:
    """A body's shape in metres; profile points are (u, z) with u in [0, 1] from the rear (0) to the front (1).

    Attributes:
        length_m, width_m: overall body length and width (the widest cross-section).
        top: (u, z) top-line points (bumper, bonnet, windscreen foot, roof, rear window, boot, bumper).
        sill_z_m: height of the underside between the wheels.
        belt: (u, z) beltline points: the glasshouse starts here.
        tumblehome: the roof's half-width is this much less than the body's, as a share.
        plan_taper: share of half-width lost at the very ends (rounded plan corners): the plan is straight over the
            middle (|2u - 1| <= ``plan_start``, the doors) and narrows towards each end as the ``plan_power`` of the
            distance into the end zone, so the end faces turn into the sides over the last quarter of the length (the
            default plan_start 0.5), as a car's bumpers and wings do, instead of meeting them at a crease.
        wheels_u: the axles' u; wheel_radius_m; arch_clearance_m: the arch's radius beyond the tyre.
        glass_u: (rear, front) u range of the side glass; windscreen / rear window come from the slope.
        pillars_u: u centres of side pillars (B, C...) within the side glass; pillar_w_m their width.
        corner_m: radius of the rounded lower corner and roof corner.
        n_stations: number of stations along x.
    """

    length_m: float
    width_m: float
    top: tuple[tuple[float, float], ...]
    sill_z_m: float
    belt: tuple[tuple[float, float], ...]
    tumblehome: float = 0.22
    plan_taper: float = 0.25
    plan_start: float = 0.5
    plan_power: float = 2.0
    wheels_u: tuple[float, ...] = (0.18, 0.82)
    wheel_radius_m: float = 0.32
    arch_clearance_m: float = 0.05
    glass_u: tuple[float, float] = (0.25, 0.72)
    pillars_u: tuple[float, ...] = ()
    pillar_w_m: float = 0.08
    corner_m: float = 0.12
    n_stations: int = 44
    extra_glass: tuple[tuple[float, float, float, float], ...] = field(default=())  # (u0, u1, z0, z1) side windows


def _stations(spec: BodySpec) -> np.ndarray:
    """u of the stations: 0.35 cosine spacing (dense at the ends, where the profile bends most) blended with 0.65
    even spacing; 0 and 1 included."""
    s = np.linspace(0.0, 1.0, spec.n_stations)
    return 0.35 * 0.5 * (1.0 - np.cos(np.pi * s)) + 0.65 * s


def _bottom(u: np.ndarray, spec: BodySpec) -> np.ndarray:
    """The underside's height along u: the sill, raised over each wheel into an arch, and up at the ends."""
    x = (u - 0.5) * spec.length_m
    z = np.full_like(u, spec.sill_z_m)
    r = spec.wheel_radius_m + spec.arch_clearance_m
    for wu in spec.wheels_u:
        xc = (wu - 0.5) * spec.length_m
        inside = np.abs(x - xc) < r
        arch = spec.wheel_radius_m + np.sqrt(np.clip(r * r - (x - xc) ** 2, 0.0, None))
        z = np.where(inside, np.maximum(z, arch), z)
    end = np.clip(1.0 - np.minimum(u, 1.0 - u) / 0.05, 0.0, 1.0)  # bumpers' undercut in the last 5%
    return z + end * 0.08


def plan_half_width(u: np.ndarray, spec: BodySpec) -> np.ndarray:
    """The body's half-width along u (plan view): straight where |2u - 1| <= ``plan_start``, then narrowing by
    ``plan_taper`` x s^``plan_power`` with s running 0 -> 1 from there to each end."""
    s = np.clip((np.abs(2.0 * np.asarray(u) - 1.0) - spec.plan_start) / (1.0 - spec.plan_start), 0.0, 1.0)
    return 0.5 * spec.width_m * (1.0 - spec.plan_taper * s ** spec.plan_power)


def _half_section(w: float, zb: float, zbelt: float, zt: float, w_roof: float, r: float) -> np.ndarray:
    """(P, 2) (y, z) points of the right half cross-section from the bottom centre to the roof centre."""
    r_low = min(r, 0.45 * (zbelt - zb), 0.45 * w)
    r_top = min(r, 0.45 * max(zt - zb, 1e-3), 0.45 * w_roof)
    zbelt = min(max(zbelt, zb + r_low), zt - r_top)
    pts = []
    n = dict(SEGMENTS)
    pts += [(y, zb) for y in np.linspace(0.0, w - r_low, n["bottom"], endpoint=False)]
    a = np.linspace(-np.pi / 2, 0.0, n["lower_corner"], endpoint=False)
    pts += list(zip(w - r_low + r_low * np.cos(a), zb + r_low + r_low * np.sin(a), strict=True))
    pts += [(w, z) for z in np.linspace(zb + r_low, zbelt, n["side"], endpoint=False)]
    # Glasshouse side: from (w, zbelt) in to (w_roof + r_top-ish, zt - r_top).
    g = np.linspace(0.0, 1.0, n["glass_side"], endpoint=False)
    y_end = w_roof
    pts += list(zip(w + (y_end - w) * g, zbelt + (zt - r_top - zbelt) * g, strict=True))
    a = np.linspace(0.0, np.pi / 2, n["roof_corner"], endpoint=False)
    pts += list(zip(y_end - r_top + r_top * np.cos(a), zt - r_top + r_top * np.sin(a), strict=True))
    pts += [(y, zt) for y in np.linspace(y_end - r_top, 0.0, n["roof"])]
    return np.asarray(pts, np.float64)


def _segment_of_edge(points_half: int) -> np.ndarray:
    """(P,) index into SEGMENTS of each edge j -> j + 1 of a full cross-section (P = 2 * points_half - 2 points:
    the right half from the bottom centre to the roof centre, then the left half mirrored back down); a left edge
    has the segment of the right edge it mirrors."""
    seg = np.concatenate([np.full(k, i) for i, (_, k) in enumerate(SEGMENTS)])
    j = np.arange(2 * points_half - 2)
    return np.where(j <= points_half - 2, seg[np.minimum(j, points_half - 1)],
                    seg[np.clip(2 * points_half - 3 - j, 0, points_half - 1)])


def loft(spec: BodySpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The body as (vertices (V, 3), triangles (T, 3), material (T,)): a closed surface with outward winding."""
    u = _stations(spec)
    x = (u - 0.5) * spec.length_m
    top = _smooth(_interp(u, spec.top))
    belt = _smooth(np.minimum(_interp(u, spec.belt), top))
    bottom = _smooth(_bottom(u, spec), 1)
    half = plan_half_width(u, spec)
    sections = []
    for i in range(len(u)):
        w_roof = half[i] * (1.0 - spec.tumblehome * np.clip((top[i] - belt[i]) / 0.45, 0.0, 1.0))
        right = _half_section(half[i], bottom[i], belt[i], top[i], w_roof, spec.corner_m)
        left = right[-2:0:-1] * np.array([-1.0, 1.0])  # mirrored, without the two centre points
        sections.append(np.vstack([right, left]))
    sec = np.stack(sections)  # (S, P, 2) going around: bottom centre -> right -> roof centre -> left
    s, p = sec.shape[:2]
    verts = np.concatenate([np.column_stack([np.full(p, x[i]), sec[i]]) for i in range(s)])
    # Quads between stations i and i+1, points j and j+1 (wrapping).
    i, j = np.meshgrid(np.arange(s - 1), np.arange(p), indexing="ij")
    a, b = i * p + j, i * p + (j + 1) % p
    c, d = a + p, b + p
    tris = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    quad_station = np.concatenate([i.reshape(-1), i.reshape(-1)])
    quad_point = np.concatenate([j.reshape(-1), j.reshape(-1)])
    # End caps: fans to each end section's centroid.
    caps = []
    for k, end in ((0, "rear"), (s - 1, "front")):
        centre = len(verts)
        verts = np.vstack([verts, [[x[k], 0.0, sec[k][:, 1].mean()]]])
        ring = k * p + np.arange(p)
        fan = np.stack([np.full(p, centre), ring, np.roll(ring, -1)], -1)
        caps.append(fan if end == "front" else fan[:, ::-1])
    tris = _outward_loft(verts, tris, np.vstack(caps), x)
    material = _materials(spec, verts, tris, u, top, belt, bottom, half, quad_station, quad_point, p)
    # Drop the triangles of no area (where a segment has no height, e.g. the glasshouse over the bonnet).
    area = np.linalg.norm(np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]]),
                          axis=1)
    keep = area > 1e-9
    return verts, tris[keep], material[keep]


def _outward_loft(verts: np.ndarray, quads: np.ndarray, caps: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The quads' and caps' triangles, each turned to face away from the body's axis (its station's centre)."""
    tris = np.vstack([quads, caps])
    a, b, c = (verts[tris[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    centroid = (a + b + c) / 3.0
    axis = np.column_stack([np.clip(centroid[:, 0], x[0] + 1e-6, x[-1] - 1e-6), np.zeros(len(tris)),
                            np.full(len(tris), verts[:, 2].mean())])
    outward = centroid - axis
    ends = np.arange(len(tris)) >= len(quads)
    outward[ends] = np.column_stack([np.sign(centroid[ends, 0]), np.zeros(ends.sum()), np.zeros(ends.sum())])
    flip = np.einsum("ij,ij->i", normal, outward) < 0
    tris = tris.copy()
    tris[flip] = tris[flip][:, ::-1]
    return tris


def _materials(spec: BodySpec, verts, tris, u, top, belt, bottom, half, quad_station, quad_point, p) -> np.ndarray:
    """Per-triangle material of the lofted body (quads first, then the end caps). Quads are classified whole (both
    triangles alike), by their station's profile and their cross-section segment, so regions have clean edges."""
    n_quads = len(quad_station)
    centroid = verts[tris].mean(axis=1)
    # A quad's centre: the mean of its four corners (stations i, i+1; points j, j+1).
    i, j = quad_station, quad_point
    corners = [verts[i * p + j], verts[i * p + (j + 1) % p], verts[(i + 1) * p + j], verts[(i + 1) * p + (j + 1) % p]]
    centroid[:n_quads] = sum(corners) / 4.0
    cu = centroid[:, 0] / spec.length_m + 0.5
    cz = centroid[:, 2]
    names = np.array([name for name, _ in SEGMENTS])[_segment_of_edge((p + 2) // 2)[quad_point]]
    names = np.concatenate([names, np.full(len(tris) - n_quads, "cap")])
    at_top, at_belt = (np.interp(cu, u, v) for v in (top, belt))
    # The top line's slope per station interval: windscreen and rear window are where it climbs steeply.
    x = (u - 0.5) * spec.length_m
    steep_station = np.abs(np.diff(top) / np.diff(x)) > 0.45
    steep = np.zeros(len(tris), bool)
    steep[:n_quads] = steep_station[quad_station]
    mat = np.full(len(tris), material_index("paint"), np.int32)
    # Side glass: the glasshouse side above the belt, within glass_u, less the pillars.
    g0, g1 = spec.glass_u
    side_glass = (names == "glass_side") & (cu > g0) & (cu < g1) & (cz > at_belt + 0.03) & (cz < at_top - 0.03)
    for pu in spec.pillars_u:
        side_glass &= np.abs((cu - pu) * spec.length_m) > 0.5 * spec.pillar_w_m
    # Windscreen and rear window: the roof segment (the roof corners stay paint: the A and C pillars) where the top
    # line climbs steeply above the belt.
    screen = (names == "roof") & steep & (at_top > at_belt + 0.1) & (cz > at_belt + 0.06)
    mat[side_glass | screen] = material_index("glass")
    for u0, u1, z0, z1 in spec.extra_glass:
        extra = np.isin(names, ["side", "glass_side"]) & (cu > u0) & (cu < u1) & (cz > z0) & (cz < z1)
        for pu in spec.pillars_u:
            extra &= np.abs((cu - pu) * spec.length_m) > 0.5 * spec.pillar_w_m
        mat[extra] = material_index("glass")
    # Lower trim: the bumpers' lower band and the sills (black plastic), below ~the wheel centre, and the underside.
    low = (cz < spec.wheel_radius_m * 0.95) & np.isin(names, ["side", "lower_corner", "cap"])
    mat[low & (mat == material_index("paint"))] = material_index("trim")
    mat[names == "bottom"] = material_index("trim")
    return mat


def wheel(x: float, y_outer: float, radius: float, width: float, n: int = 24) -> tuple[np.ndarray, ...]:
    """A wheel on the ground at (x, y): tyre tread and sidewalls (rubber), a rim disc (rim) recessed into the outer
    sidewall with a darker hub; ``y_outer`` is the outer face's y (its sign says the side)."""
    side = np.sign(y_outer) if y_outer != 0 else 1.0
    y_in = y_outer - side * width
    ang = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ring = np.column_stack([x + radius * np.cos(ang), radius + radius * np.sin(ang)])
    rim_r = 0.62 * radius
    rim = np.column_stack([x + rim_r * np.cos(ang), radius + rim_r * np.sin(ang)])
    hub = np.column_stack([x + 0.18 * radius * np.cos(ang), radius + 0.18 * radius * np.sin(ang)])
    y_rim = y_outer - side * 0.025
    verts = np.vstack([
        np.column_stack([ring[:, 0], np.full(n, y_outer), ring[:, 1]]),  # 0: outer tyre edge
        np.column_stack([ring[:, 0], np.full(n, y_in), ring[:, 1]]),  # n: inner tyre edge
        np.column_stack([rim[:, 0], np.full(n, y_outer), rim[:, 1]]),  # 2n: sidewall's inner edge
        np.column_stack([rim[:, 0], np.full(n, y_rim), rim[:, 1]]),  # 3n: rim's rim (recessed)
        np.column_stack([hub[:, 0], np.full(n, y_rim), hub[:, 1]]),  # 4n: hub edge
        [[x, y_rim, radius], [x, y_in, radius]],  # 5n: hub centre, 5n+1: inner centre
    ])
    k = np.arange(n)
    k1 = (k + 1) % n
    tread = np.concatenate([np.stack([k, n + k, k1], -1), np.stack([k1, n + k, n + k1], -1)])
    sidewall = np.concatenate([np.stack([k, k1, 2 * n + k], -1), np.stack([k1, 2 * n + k1, 2 * n + k], -1)])
    lip = np.concatenate([np.stack([2 * n + k, 2 * n + k1, 3 * n + k], -1),
                          np.stack([2 * n + k1, 3 * n + k1, 3 * n + k], -1)])
    rim_face = np.concatenate([np.stack([3 * n + k, 3 * n + k1, 4 * n + k], -1),
                               np.stack([3 * n + k1, 4 * n + k1, 4 * n + k], -1)])
    hub_face = np.stack([4 * n + k, 4 * n + k1, np.full(n, 5 * n)], -1)
    inner = np.stack([n + k1, n + k, np.full(n, 5 * n + 1)], -1)
    tris = np.concatenate([tread, sidewall, lip, rim_face, hub_face, inner])
    mats = np.concatenate([np.full(len(tread) + len(sidewall), material_index("rubber")),
                           np.full(len(lip) + len(rim_face), material_index("rim")),
                           np.full(len(hub_face), material_index("trim")),
                           np.full(len(inner), material_index("rubber"))])
    return verts, _face_away(verts, tris, np.array([x, y_in + side * 0.5 * width, radius])), mats.astype(np.int32)


def _face_away(verts: np.ndarray, tris: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Triangles turned to face away from ``centre`` along their normal's dominant direction (a wheel's parts are
    each planar or a cylinder about ``centre``'s axis)."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    out = (a + b + c) / 3.0 - centre
    flip = np.einsum("ij,ij->i", normal, out) < 0
    tris = tris.copy()
    tris[flip] = tris[flip][:, ::-1]
    return tris


def surface_point(verts: np.ndarray, tris: np.ndarray, origin: np.ndarray, direction: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """The nearest point where the ray (origin, direction) meets the mesh, and the unit normal there facing the
    ray's origin; None where it misses (Moller-Trumbore over all triangles, double precision)."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - a
    bu = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    bv = (q @ direction) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (t > 0)
    if not hit.any():
        return None
    k = np.flatnonzero(hit)[np.argmin(t[hit])]
    n = np.cross(e1[k], e2[k])
    n /= np.linalg.norm(n)
    if n @ direction > 0:
        n = -n
    return origin + t[k] * direction, n


def decal(verts: np.ndarray, tris: np.ndarray, y: float, z: float, width: float, height: float, material: str,
          end: str, lift_m: float = 0.006, conform: tuple[int, int] | None = None
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A quad of ``material`` laid onto the body's ``end`` ("front" or "rear") face, ``width`` along y and
    ``height`` up the face, ``lift_m`` off it; None where a ray misses.

    Flat (``conform`` None): centred where a ray along x meets the surface at (y, z), in the plane of the surface
    there (tilted with it, upright otherwise); a plate. Conforming (``conform`` = (columns, rows)): a grid of that
    many points across the (y, z) rectangle, each where a ray along x meets the surface, lifted along the normal
    there, so the quad follows the face round a rounded corner (lamps that wrap into the wings)."""
    sign = 1.0 if end == "front" else -1.0
    if conform is not None:
        cols, rows = conform
        ys, zs = np.linspace(y - 0.5 * width, y + 0.5 * width, cols), np.linspace(z - 0.5 * height, z + 0.5 * height,
                                                                                  rows)
        grid = []
        for zz in zs:
            for yy in ys:
                found = surface_point(verts, tris, np.array([sign * 1e3, yy, zz]), np.array([-sign, 0.0, 0.0]))
                if found is None:
                    return None
                grid.append(found[0] + lift_m * found[1])
        k = np.arange((rows - 1) * cols).reshape(rows - 1, cols)[:, :-1].reshape(-1)
        quads = np.concatenate([np.stack([k, k + 1, k + cols + 1], -1), np.stack([k, k + cols + 1, k + cols], -1)])
        if sign < 0:  # seen from behind, y runs the other way: keep the winding facing out
            quads = quads[:, ::-1]
        return np.asarray(grid), quads, np.full(len(quads), material_index(material), np.int32)
    origin = np.array([sign * 1e3, y, z])
    found = surface_point(verts, tris, origin, np.array([-sign, 0.0, 0.0]))
    if found is None:
        return None
    point, normal = found
    along = np.array([0.0, 1.0, 0.0]) - normal[1] * normal  # y direction projected into the tangent plane
    along /= np.linalg.norm(along)
    up = np.cross(normal, along)
    if up[2] < 0:
        up = -up
    centre = point + lift_m * normal
    corners = np.array([centre + sx * 0.5 * width * along + sz * 0.5 * height * up
                        for sx, sz in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    quad = np.array([[0, 1, 2], [0, 2, 3]])
    return corners, quad, np.full(2, material_index(material), np.int32)


def side_strip(verts: np.ndarray, tris: np.ndarray, points_xz: np.ndarray, width: float, material: str,
               lift_m: float = 0.004) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A thin ribbon (``width`` across, of ``material``) laid along the body's left side (+y) through the points
    (k, 2) of x and z (k >= 2): each point is where a ray along -y at that (x, z) meets the surface, lifted
    ``lift_m`` along the normal there, so the strip follows the side's curvature (door shut lines, handles,
    rubbing strips). None where a ray misses. Mirror it (y -> -y, winding reversed) for the right side."""
    points_xz = np.asarray(points_xz, np.float64)
    found = [surface_point(verts, tris, np.array([x, 1e3, z]), np.array([0.0, -1.0, 0.0])) for x, z in points_xz]
    if any(f is None for f in found):
        return None
    centre = np.array([p + lift_m * n for p, n in found])
    normal = np.array([n for _, n in found])
    along = np.gradient(centre, axis=0)
    across = np.cross(normal, along)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    k = len(centre)
    v = np.concatenate([centre - 0.5 * width * across, centre + 0.5 * width * across])
    quads = [t for i in range(k - 1) for t in ((i, i + 1, k + i + 1), (i, k + i + 1, k + i))]
    t = np.array(quads, np.int64)
    # Face outwards (+y side): flip the winding where the normal of the first triangle points inwards.
    a, b, c = v[t[0]]
    if np.cross(b - a, c - a) @ normal[0] < 0:
        t = t[:, ::-1]
    return v, t, np.full(len(t), material_index(material), np.int32)
