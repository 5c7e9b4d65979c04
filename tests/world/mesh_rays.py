"""What a ray meets first on one mesh (open3d's Embree): the material tests of the procedural bodies."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from pipeline.world.materials import MATERIAL_NAMES
from pipeline.world.mesh import Mesh


class MeshRays:
    """``mesh`` in an Embree scene, built once for all the rays a test casts."""

    def __init__(self, mesh: Mesh) -> None:
        self.mesh = mesh
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                                 o3d.core.Tensor(mesh.triangles.astype(np.uint32)))

    def first(self, origin, direction) -> tuple[str, np.ndarray | None]:
        """The material's name and the point where the ray (origin, unit direction) first meets the mesh; ("", None)
        where it misses."""
        origin, direction = np.asarray(origin, np.float64), np.asarray(direction, np.float64)
        hit = self.scene.cast_rays(o3d.core.Tensor(np.array([[*origin, *direction]], np.float32)))
        t = float(hit["t_hit"].numpy()[0])
        if not np.isfinite(t):
            return "", None
        return MATERIAL_NAMES[int(self.mesh.material[hit["primitive_ids"].numpy()[0]])], origin + t * direction
