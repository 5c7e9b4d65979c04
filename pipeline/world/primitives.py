"""Mesh primitives for the static world, vectorised over many instances, and a builder that collects
pieces of one semantic class into a :class:`~pipeline.world.mesh.Mesh`.

All primitives take (N, ...) arrays and return one vertex (V, 3) float64 / triangle (T, 3) int32 pair for
all N instances, triangles counter-clockwise seen from outside. Metres, world frame, yaw CCW from +x.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh

# Unit cube corners (x, y, z in {-0.5, 0.5}), bottom 0-3 then top 4-7, each ring CCW from above.
_CUBE = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                  [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=np.float64) / 2
_CUBE_TRIS = np.array([
    [0, 2, 1], [0, 3, 2],  # bottom (faces down)
    [4, 5, 6], [4, 6, 7],  # top
    [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
], dtype=np.int32)


class PartBuilder:
    """Collects (vertices, triangles, material) pieces and concatenates them into one Mesh."""

    def __init__(self, semantic: SemanticClass) -> None:
        self.semantic = semantic
        self._verts: list[np.ndarray] = []
        self._tris: list[np.ndarray] = []
        self._mats: list[np.ndarray] = []
        self._count = 0

    def add(self, vertices: np.ndarray, triangles: np.ndarray, material: str | np.ndarray) -> None:
        """Append a piece; ``material`` is a name (all triangles) or (T,) int32 material indices."""
        if not len(triangles):
            return
        mat = np.full(len(triangles), material_index(material), np.int32) if isinstance(material, str) else material
        self._verts.append(np.asarray(vertices, dtype=np.float64))
        self._tris.append(np.asarray(triangles, dtype=np.int32) + self._count)
        self._mats.append(np.asarray(mat, dtype=np.int32))
        self._count += len(vertices)

    @property
    def num_triangles(self) -> int:
        return sum(len(t) for t in self._tris)

    def build(self) -> Mesh | None:
        """The collected mesh, or None when nothing was added."""
        if not self._tris:
            return None
        return Mesh(np.concatenate(self._verts), np.concatenate(self._tris), np.concatenate(self._mats), self.semantic)


def _place(local: np.ndarray, centre: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Rotate local points (N, K, 3) by yaw (N,) about z and translate by centre (N, 3) -> (N*K, 3)."""
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x = local[..., 0] * c - local[..., 1] * s
    y = local[..., 0] * s + local[..., 1] * c
    return (np.stack([x, y, local[..., 2]], -1) + centre[:, None, :]).reshape(-1, 3)


def _instance_tris(tris: np.ndarray, count: int, stride: int) -> np.ndarray:
    return (tris[None] + (np.arange(count) * stride)[:, None, None]).reshape(-1, 3).astype(np.int32)


def boxes(centre: np.ndarray, size: np.ndarray, yaw: np.ndarray, bottom: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Oriented boxes: centre (N, 3), size (N, 3) as (length along yaw, width, height), yaw (N,) rad.

    Returns (8N, 3) vertices and (12N or 10N, 3) triangles (``bottom=False`` drops the bottom faces).
    """
    centre, size = np.atleast_2d(centre), np.atleast_2d(size)
    verts = _place(_CUBE[None] * size[:, None, :], centre, np.asarray(yaw, dtype=np.float64).reshape(-1))
    return verts, _instance_tris(_CUBE_TRIS if bottom else _CUBE_TRIS[2:], len(centre), 8)


def prisms(base: np.ndarray, radius: np.ndarray, height: np.ndarray, sides: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Vertical regular prisms (poles, trunks): base centre (N, 3), radius (N,), height (N,); open bottom.

    Returns ((2*sides + 1)*N, 3) vertices (per instance: the bottom ring, the top ring, the top centre) and
    (3*sides*N, 3) triangles (sides and top cap).
    """
    base = np.atleast_2d(base)
    n = len(base)
    ang = np.arange(sides) * 2 * np.pi / sides
    ring = np.stack([np.cos(ang), np.sin(ang), np.zeros(sides)], 1)
    r = np.reshape(radius, (-1, 1, 1)) * np.ones((n, 1, 1))
    h = np.reshape(height, (-1, 1)) * np.ones((n, 1))
    bottom = ring[None] * r
    top = bottom + np.stack([np.zeros_like(h), np.zeros_like(h), h], -1)
    cap = np.stack([np.zeros_like(h), np.zeros_like(h), h], -1)
    local = np.concatenate([bottom, top, cap], axis=1)
    i = np.arange(sides)
    j = (i + 1) % sides
    side = np.concatenate([np.stack([i, j, j + sides], 1), np.stack([i, j + sides, i + sides], 1)])
    top_tris = np.stack([i + sides, j + sides, np.full(sides, 2 * sides)], 1)
    tris = np.concatenate([side, top_tris])
    return (local + base[:, None, :]).reshape(-1, 3), _instance_tris(tris, n, 2 * sides + 1)


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    p = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, p, 0], [1, p, 0], [-1, -p, 0], [1, -p, 0], [0, -1, p], [0, 1, p],
                  [0, -1, -p], [0, 1, -p], [p, 0, -1], [p, 0, 1], [-p, 0, -1], [-p, 0, 1]], dtype=np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]], dtype=np.int32)
    return v / np.linalg.norm(v, axis=1, keepdims=True), f


ICO_VERTICES, ICO_FACES = _icosahedron()  # the unit icosahedron: (12, 3) float64 on the unit sphere, (20, 3) int32


def blobs(centre: np.ndarray, radii: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ellipsoid-like icosahedra (tree crowns): centre (N, 3), radii (N, 3), yaw (N,). 20 triangles each."""
    centre, radii = np.atleast_2d(centre), np.atleast_2d(radii)
    verts = _place(ICO_VERTICES[None] * radii[:, None, :], centre, np.asarray(yaw, dtype=np.float64).reshape(-1))
    return verts, _instance_tris(ICO_FACES, len(centre), len(ICO_VERTICES))


def quads(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat quads from corners (N, 4, 3) given in CCW order seen from the front -> (4N, 3), (2N, 3)."""
    tris = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    return corners.reshape(-1, 3), _instance_tris(tris, len(corners), 4)


# The faces of _CUBE_TRIS by name, in a box's own frame (x along, y across, z up): pairs of triangle rows.
BOX_SIDES = {"bottom": (0, 1), "top": (2, 3), "back": (4, 5), "end": (6, 7), "front": (8, 9), "start": (10, 11)}


def _frame_points(local: np.ndarray, origin: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Points (N, K, 3) given as (along, across, z) in per-item frames -> (N*K, 3) world: ``origin`` (N, 3), ``axis``
    (N, 2) the unit horizontal 'along' direction; 'across' is its left (a right-handed frame with z up)."""
    ax, ay = axis[:, None, 0], axis[:, None, 1]
    x = origin[:, None, 0] + local[..., 0] * ax - local[..., 1] * ay
    y = origin[:, None, 1] + local[..., 0] * ay + local[..., 1] * ax
    return np.stack([x, y, origin[:, None, 2] + local[..., 2]], -1).reshape(-1, 3)


def frame_boxes(origin: np.ndarray, axis: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                sides: tuple[str, ...] = tuple(BOX_SIDES)) -> tuple[np.ndarray, np.ndarray]:
    """Boxes given by their bounds ``lo``, ``hi`` (N, 3) as (along, across, z) in per-box frames (``origin`` (N, 3),
    unit horizontal ``axis`` (N, 2), across = its left), with only the named ``sides`` (of BOX_SIDES: "front" faces
    +across, "back" -across, "end" +along, "start" -along). Returns (8N, 3) vertices, (2 len(sides) N, 3)
    triangles, counter-clockwise seen from outside."""
    local = lo[:, None, :] + (hi - lo)[:, None, :] * (_CUBE[None] + 0.5)
    rows = [r for s in sides for r in BOX_SIDES[s]]
    return _frame_points(local, origin, axis), _instance_tris(_CUBE_TRIS[rows], len(lo), 8)


def frame_quads(origin: np.ndarray, axis: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertical rectangles facing +across in per-item frames (as :func:`frame_boxes`): ``lo``, ``hi`` (N, 3) with
    equal 'across' (the plane's offset). Returns (4N, 3) vertices, (2N, 3) triangles (counter-clockwise seen from
    +across)."""
    # The front face of _CUBE (y = +0.5): corners 2, 3, 7, 6 -> (hi x, lo z), (lo x, lo z), (lo x, hi z), (hi x, hi z).
    corners = np.stack([np.stack([hi[:, 0], lo[:, 0], lo[:, 0], hi[:, 0]], 1), np.repeat(lo[:, 1:2], 4, 1),
                        np.stack([lo[:, 2], lo[:, 2], hi[:, 2], hi[:, 2]], 1)], -1)
    return _frame_points(corners, origin, axis), _instance_tris(np.array([[0, 1, 2], [0, 2, 3]], np.int32), len(lo), 4)
