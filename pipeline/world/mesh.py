"""Triangle meshes with per-triangle materials: the interchange between world builders and the renderer.

Every builder (static road scene, procedural actors) produces :class:`Mesh` objects; the renderer
turns them into Embree geometry. Materials are looked up by name in :data:`pipeline.world.materials`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.core.jit import as_input, kernel

BODY, RIDER = 0, 1
"""A triangle's :attr:`Mesh.part`: the actor's body, or the person riding it."""


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh of one semantic class.

    Attributes:
        vertices: (V, 3) float64 positions, metres, in the frame of whoever built it (world for static
            geometry, the actor's box frame — centre at origin, x forward, z up — for actors).
        triangles: (T, 3) int32 vertex indices, counter-clockwise seen from outside.
        material: (T,) int32 material index per triangle (into the material table in use).
        semantic: the semantic class of every triangle, but a rider's (``part``).
        part: (T,) uint8 which part of the actor each triangle belongs to: :data:`BODY` (0, the default), or
            :data:`RIDER`, the person riding a bicycle or motorcycle (semantic class RIDER in the label images and
            the LiDAR's points, a label row of its own in the camera's labels).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    material: np.ndarray
    semantic: SemanticClass
    part: np.ndarray | None = None

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        triangles = np.asarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        material = np.broadcast_to(np.asarray(self.material, dtype=np.int32), (len(triangles),)).copy()
        part = np.broadcast_to(np.asarray(BODY if self.part is None else self.part, np.uint8), (len(triangles),))
        if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(vertices)):
            raise ValueError(f"triangle indices out of range for {len(vertices)} vertices")
        if not np.isin(part, (BODY, RIDER)).all():
            raise ValueError(f"triangle parts must be {BODY} (body) or {RIDER} (rider), got {sorted(set(part))}")
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "triangles", triangles)
        object.__setattr__(self, "material", material)
        object.__setattr__(self, "part", part.copy())

    @property
    def triangle_semantic(self) -> np.ndarray:
        """(T,) uint8 each triangle's semantic class: the mesh's, RIDER on a rider's triangles."""
        return np.where(self.part == RIDER, np.uint8(SemanticClass.RIDER), np.uint8(self.semantic))

    def rider_vertices(self) -> np.ndarray:
        """(R, 3) float64 the vertices of the rider's triangles (none: (0, 3))."""
        return self.vertices[np.unique(self.triangles[self.part == RIDER])]

    def __len__(self) -> int:
        return len(self.triangles)

    def on_ground(self, clearance_m: float = 0.0) -> Mesh:
        """The mesh moved along z so that its lowest vertex is ``clearance_m`` above z = 0 (a model standing on the
        ground, or a runner's float above it)."""
        lowest = self.vertices[:, 2].min() - clearance_m
        return Mesh(self.vertices - [0.0, 0.0, lowest], self.triangles, self.material, self.semantic, self.part)

    @staticmethod
    def concatenate(meshes: list[Mesh], semantic: SemanticClass | None = None) -> Mesh:
        """Merge meshes into one (of ``semantic``, or the first mesh's class)."""
        if not meshes:
            raise ValueError("cannot concatenate an empty list of meshes")
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
        return Mesh(
            np.concatenate([m.vertices for m in meshes]),
            np.concatenate([m.triangles + off for m, off in zip(meshes, offsets, strict=True)]),
            np.concatenate([m.material for m in meshes]),
            meshes[0].semantic if semantic is None else semantic,
            np.concatenate([m.part for m in meshes]),
        )


def triangle_bounds(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi), each (T, C) float64: per triangle, the least and greatest of each coordinate of its three corners
    among ``points`` (V, C) (e.g. vertices, or their projections). One compiled pass: numpy's gather and min/max
    over the corners made several triangle-sized temporaries."""
    return _triangle_bounds(as_input(points, np.float64), as_input(np.reshape(triangles, (-1, 3)), np.int64))


@kernel("Tuple((float64[:, ::1], float64[:, ::1]))(float64[:, ::1], int64[:, ::1])")
def _triangle_bounds(points, triangles):
    lo = np.empty((triangles.shape[0], points.shape[1]))
    hi = np.empty((triangles.shape[0], points.shape[1]))
    for t in range(triangles.shape[0]):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        for k in range(points.shape[1]):
            lo[t, k] = min(points[a, k], points[b, k], points[c, k])
            hi[t, k] = max(points[a, k], points[b, k], points[c, k])
    return lo, hi
