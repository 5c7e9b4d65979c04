"""Smooth closed solids for procedural actors: swept tubes (tapered capsules, limbs, frames), ellipsoids, tori.

Frame: whatever the caller's (metres, x forward, y left, z up for actors). Every solid is a closed, consistently
oriented triangle surface facing outwards (each directed edge appears once, its reverse once), so parts can
interpenetrate freely: a ray tracer takes the first hit. A part is ``(vertices (V, 3) float64, triangles (T, 3)
int64, material (T,) int32)``, as :mod:`pipeline.world.actor_shapes`' parts; :func:`merge` joins parts into a
:class:`~pipeline.world.mesh.Mesh`.

The core is :func:`sweep`: an elliptical cross-section carried along a polyline of centres. Its frame at each
station is (u, v, t): t the polyline's tangent, u the caller's ``ref`` direction made normal to t (semi-axis a
lies along u, b along v = t x u). A station of zero radius is a single pole vertex, so a sweep whose radii fall to
zero at both ends is closed without caps (an ellipsoid, a rounded capsule); otherwise the ends get flat caps.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.materials import material_index
from pipeline.world.mesh import RIDER, Mesh

Part = tuple[np.ndarray, np.ndarray, np.ndarray]  # vertices (V, 3), triangles (T, 3), material (T,)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def sweep(centres, radii, material: str | Sequence[str], n: int = 10, ref=(0.0, 1.0, 0.0), loop: bool = False
          ) -> Part:
    """An elliptical cross-section swept through ``centres`` (K, 3).

    Args:
        radii: (K,) circular radii or (K, 2) semi-axes (a along ``ref``, b across); 0 makes the station a pole.
        material: one name, or one per interval between stations (K - 1; K with ``loop``); caps take their
            interval's.
        n: points around each cross-section.
        ref: (3,) the direction of semi-axis a (made normal to the tangent; it must never be parallel to it).
        loop: the last station joins the first (a torus); no caps.
    """
    c = np.asarray(centres, np.float64)
    r = np.asarray(radii, np.float64)
    r = np.column_stack([r, r]) if r.ndim == 1 else r
    k = len(c)
    names = [material] * (k if loop else k - 1) if isinstance(material, str) else list(material)
    if len(names) != (k if loop else k - 1) or len(r) != k:
        raise ValueError(f"{k} stations need {k if loop else k - 1} interval materials and {k} radii")
    tangent = _unit(np.roll(c, -1, 0) - np.roll(c, 1, 0)) if loop else _unit(np.gradient(c, axis=0))
    ref = np.asarray(ref, np.float64)
    u = _unit(ref - (tangent @ ref)[:, None] * tangent)
    v = np.cross(tangent, u)
    ang = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    ring = (c[:, None] + r[:, 0, None, None] * np.cos(ang)[None, :, None] * u[:, None]
            + r[:, 1, None, None] * np.sin(ang)[None, :, None] * v[:, None])
    pole = np.all(r <= 0.0, axis=1)
    verts, index = [], np.zeros((k, n), np.int64)
    for i in range(k):
        index[i] = len(verts) if pole[i] else len(verts) + np.arange(n)
        verts.extend([c[i]] if pole[i] else ring[i])
    j, j1 = np.arange(n), (np.arange(n) + 1) % n
    tris, mats = [], []
    codes = [material_index(name) for name in names]  # looked up once per interval, not per triangle
    for i in range(k if loop else k - 1):
        a, b, cc, d = index[i, j], index[i, j1], index[(i + 1) % k, j], index[(i + 1) % k, j1]
        tris += [np.stack([a, b, cc], -1), np.stack([b, d, cc], -1)]
        mats += [codes[i]] * (2 * n)
    if not loop:
        for i, name, order in ((0, codes[0], (j1, j)), (k - 1, codes[-1], (j, j1))):
            if not pole[i]:
                verts.append(c[i])
                tris.append(np.stack([np.full(n, len(verts) - 1), index[i, order[0]], index[i, order[1]]], -1))
                mats += [name] * n
    verts = np.asarray(verts)
    tris = np.concatenate(tris)
    mat = np.array(mats, np.int32)
    keep = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    tris, mat = tris[keep], mat[keep]
    if signed_volume(verts, tris) < 0:  # a left-handed path frame (never for (u, v, t) as built; kept as a guard)
        tris = tris[:, ::-1]
    return verts, tris, mat


def signed_volume(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """The volume a closed surface encloses, positive where its triangles face outwards."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _dome(p0: np.ndarray, p1: np.ndarray, r0: float, r1: float, rings: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres and radii of a tapered capsule from p0 to p1: hemispherical ends of radii r0, r1 beyond them."""
    axis = _unit(p1 - p0)
    phi = np.linspace(0.0, 0.5 * np.pi, rings + 1)  # pole to equator
    start = [(p0 - r0 * np.cos(f) * axis, r0 * np.sin(f)) for f in phi]
    end = [(p1 + r1 * np.cos(f) * axis, r1 * np.sin(f)) for f in phi[::-1]]
    pts = start + end
    return np.array([p for p, _ in pts]), np.array([r for _, r in pts])


def capsule(p0, p1, r0: float, r1: float, material: str, n: int = 10, rings: int = 3, ref=(0.0, 1.0, 0.0)) -> Part:
    """A tapered capsule: a frustum from p0 (radius r0) to p1 (radius r1) with round ends."""
    centres, radii = _dome(np.asarray(p0, float), np.asarray(p1, float), r0, r1, rings)
    return sweep(centres, radii, material, n, ref)


def limb(points, radii, materials: str | Sequence[str], n: int = 10, rings: int = 2, ref=(0.0, 1.0, 0.0)) -> Part:
    """A round-ended tube through ``points`` (K, 3) with ``radii`` (K,); ``materials`` per segment (K - 1)."""
    p = np.asarray(points, np.float64)
    r = np.asarray(radii, np.float64)
    names = [materials] * (len(p) - 1) if isinstance(materials, str) else list(materials)
    head_c, head_r = _dome(p[0], p[1], r[0], r[1], rings)
    tail_c, tail_r = _dome(p[-2], p[-1], r[-2], r[-1], rings)
    centres = np.concatenate([head_c[:rings], p, tail_c[-rings:]])
    rad = np.concatenate([head_r[:rings], r, tail_r[-rings:]])
    mats = [names[0]] * rings + names + [names[-1]] * rings
    return sweep(centres, rad, mats, n, ref)


def ellipsoid(centre, semi, material: str | Sequence[str], n: int = 12, m: int = 8, axis=(0.0, 0.0, 1.0),
              ref=(1.0, 0.0, 0.0)) -> Part:
    """An ellipsoid with semi-axes ``semi`` = (a along ``ref``, b across, c along ``axis``); ``material`` one name
    or one per band from the bottom pole to the top (m bands)."""
    axis = _unit(np.asarray(axis, np.float64))
    theta = np.linspace(0.0, np.pi, m + 1)  # bottom pole (along -axis) to top pole
    centres = np.asarray(centre, np.float64) - semi[2] * np.cos(theta)[:, None] * axis
    radii = np.column_stack([semi[0] * np.sin(theta), semi[1] * np.sin(theta)])
    radii[[0, -1]] = 0.0
    return sweep(centres, radii, material, n, ref)


def torus(centre, major: float, minor: float, material: str, n_major: int = 24, n_minor: int = 8,
          normal=(0.0, 1.0, 0.0), ref=(1.0, 0.0, 0.0)) -> Part:
    """A ring of tube radius ``minor`` round a circle of radius ``major`` about ``normal`` (a tyre about y)."""
    normal = _unit(np.asarray(normal, np.float64))
    e1 = _unit(np.asarray(ref, np.float64) - (np.asarray(ref) @ normal) * normal)
    e2 = np.cross(normal, e1)
    ang = np.linspace(0.0, 2.0 * np.pi, n_major, endpoint=False)
    centres = np.asarray(centre, np.float64) + major * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    return sweep(centres, np.full(n_major, minor), material, n_minor, normal, loop=True)


def cylinder(p0, p1, radius: float, material: str, n: int = 10, ref=(1.0, 0.0, 0.0)) -> Part:
    """A flat-ended cylinder from p0 to p1 (hubs, bars, spokes)."""
    return sweep([p0, p1], [radius, radius], material, n, ref)


def merge(parts: list[Part], semantic_class: ObjectClass, rider: list[Part] = ()) -> Mesh:
    """Parts joined into one mesh of the class's semantic; the ``rider``'s parts after them, marked as the rider's
    (:attr:`Mesh.part`)."""
    parts = [*parts, *rider]
    offsets = np.cumsum([0] + [len(v) for v, _, _ in parts[:-1]])
    ridden = sum(len(t) for _, t, _ in rider)
    material = np.concatenate([m for _, _, m in parts])
    part = np.zeros(len(material), np.uint8)
    part[len(material) - ridden:] = RIDER
    return Mesh(
        np.concatenate([v for v, _, _ in parts]),
        np.concatenate([t + o for (_, t, _), o in zip(parts, offsets, strict=True)]),
        material,
        semantic_class.semantic,
        part,
    )
