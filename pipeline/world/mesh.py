"""Triangle meshes with per-triangle materials: the interchange between world builders and the renderer.

Every builder (static road scene, procedural actors) produces :class:`Mesh` objects; the renderer
turns them into Embree geometry. Materials are looked up by name in :data:`pipeline.world.materials`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import SemanticClass


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh of one semantic class.

    Attributes:
        vertices: (V, 3) float64 positions, metres, in the frame of whoever built it (world for static
            geometry, the actor's box frame — centre at origin, x forward, z up — for actors).
        triangles: (T, 3) int32 vertex indices, counter-clockwise seen from outside.
        material: (T,) int32 material index per triangle (into the material table in use).
        semantic: the semantic class of every triangle.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    material: np.ndarray
    semantic: SemanticClass

    def __post_init__(self) -> None:
        vertices = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        triangles = np.asarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        material = np.broadcast_to(np.asarray(self.material, dtype=np.int32), (len(triangles),)).copy()
        if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(vertices)):
            raise ValueError(f"triangle indices out of range for {len(vertices)} vertices")
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "triangles", triangles)
        object.__setattr__(self, "material", material)

    def __len__(self) -> int:
        return len(self.triangles)

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
        )
