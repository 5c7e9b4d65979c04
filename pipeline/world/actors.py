"""Procedural actor meshes: one canonical mesh per :class:`ObjectClass`, scaled and placed per actor.

Conventions:

- The canonical mesh of a class lives in the *unit box frame*: centre at the origin, x forward, y left,
  z up, and its vertices span exactly [-0.5, 0.5] on every axis (it touches all six faces). Placing it
  is the affine map ``p_world = R(yaw) @ diag(length, width, height) @ p_unit + centre``, so the placed
  mesh fills its 3D box exactly and 3D labels and 2D projections agree.
- Shapes are modelled in metres at a typical size of the class and normalised once (cached); scaling
  to another size stretches the parts (a long truck gets longer wheels) — acceptable for detection data.
- Body paint is the material ``paint``; its colour is per actor (:attr:`Actors.color_rgb`), not in the
  material table. Brake lights are lit where :attr:`Actors.brake` is set (the renderer's concern).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actor_shapes import SHAPES
from pipeline.world.mesh import Mesh


@dataclass(frozen=True)
class Actors:
    """The actors of one frame, struct of arrays (N actors).

    Attributes:
        track_id: (N,) int32 unique positive track ids (0 is reserved for "static / nothing").
        object_class: N :class:`ObjectClass` members.
        boxes: (N) world boxes (centre, (length, width, height), yaw), metres / radians.
        color_rgb: (N, 3) float32 paint colour, linear RGB in [0, 1].
        brake: (N,) bool, brake lights lit.
    """

    track_id: np.ndarray
    object_class: tuple[ObjectClass, ...]
    boxes: Boxes3D
    color_rgb: np.ndarray
    brake: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        n = len(self.boxes)
        track_id = np.asarray(self.track_id, dtype=np.int32).reshape(-1)
        classes = tuple(ObjectClass(c) for c in self.object_class)
        color = np.asarray(self.color_rgb, dtype=np.float32).reshape(-1, 3)
        brake = np.zeros(n, bool) if self.brake is None else np.asarray(self.brake, dtype=bool).reshape(-1)
        if not (len(track_id) == len(classes) == len(color) == len(brake) == n):
            raise ValueError(
                f"actor arrays differ in length: track_id {len(track_id)}, object_class {len(classes)}, "
                f"boxes {n}, color_rgb {len(color)}, brake {len(brake)}"
            )
        if n and (track_id.min() <= 0 or len(np.unique(track_id)) != n):
            raise ValueError("track ids must be positive and unique (0 means static / nothing)")
        if n and (color.min() < 0.0 or color.max() > 1.0):
            raise ValueError("color_rgb must be linear RGB in [0, 1]")
        object.__setattr__(self, "track_id", track_id)
        object.__setattr__(self, "object_class", classes)
        object.__setattr__(self, "color_rgb", color)
        object.__setattr__(self, "brake", brake)

    def __len__(self) -> int:
        return len(self.track_id)

    @classmethod
    def empty(cls) -> Actors:
        return cls(np.zeros(0, np.int32), (), Boxes3D(np.zeros((0, 3)), np.ones((0, 3)), np.zeros(0)), np.zeros((0, 3)))

    @property
    def class_codes(self) -> np.ndarray:
        """(N,) int32 index of each actor's class in ``list(ObjectClass)``."""
        order = list(ObjectClass)
        return np.array([order.index(c) for c in self.object_class], dtype=np.int32)


def srgb8_to_linear(rgb8: np.ndarray) -> np.ndarray:
    """(N, 3) uint8 sRGB colours (SUMO's) to (N, 3) float32 linear RGB in [0, 1]."""
    c = np.asarray(rgb8, dtype=np.float32) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def normalise_to_unit_box(mesh: Mesh) -> Mesh:
    """Scale and shift a mesh so that its vertices span exactly [-0.5, 0.5] on x, y and z."""
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    if np.any(hi - lo <= 0):
        raise ValueError("a mesh with zero extent on some axis cannot fill a box")
    unit = (mesh.vertices - 0.5 * (lo + hi)) / (hi - lo)
    # Remove the last ulp of rounding so that min/max are exactly -0.5 / +0.5.
    unit[np.isclose(unit, -0.5, atol=1e-12)] = -0.5
    unit[np.isclose(unit, 0.5, atol=1e-12)] = 0.5
    return Mesh(unit, mesh.triangles, mesh.material, mesh.semantic)


@functools.cache
def canonical_mesh(object_class: ObjectClass) -> Mesh:
    """The built-in procedural mesh of a class in the unit box frame (vertices span exactly [-0.5, 0.5]^3)."""
    return normalise_to_unit_box(SHAPES[ObjectClass(object_class)]())


class ActorMeshes:
    """The canonical mesh of every class (the built-in procedural ones unless overridden).

    Args:
        overrides: class -> mesh in the unit box frame; each must span exactly [-0.5, 0.5] on every axis
            (use :func:`normalise_to_unit_box`), so that placed meshes fill their 3D boxes.

    Attributes:
        scene_cache: per-class Embree scenes and triangle tables, owned by the renderer (pipeline.world.scene).
    """

    def __init__(self, overrides: dict[ObjectClass, Mesh] | None = None) -> None:
        self._meshes = {c: canonical_mesh(c) for c in ObjectClass}
        for object_class, mesh in (overrides or {}).items():
            lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
            if not (np.all(lo == -0.5) and np.all(hi == 0.5)):
                raise ValueError(f"mesh for {object_class!s} must span exactly [-0.5, 0.5]^3, got {lo} .. {hi}")
            self._meshes[ObjectClass(object_class)] = mesh
        self.scene_cache: dict[object, object] = {}  # ObjectClass -> Embree scene; "tables" -> triangle tables

    def __getitem__(self, object_class: ObjectClass) -> Mesh:
        return self._meshes[ObjectClass(object_class)]


DEFAULT_MESHES = ActorMeshes()


def unit_to_world(boxes: Boxes3D) -> np.ndarray:
    """(N, 3, 4) float64 affine maps from each actor's unit box frame to the world: [R diag(size) | centre]."""
    c, s = np.cos(boxes.yaw_rad), np.sin(boxes.yaw_rad)
    out = np.zeros((len(boxes), 3, 4))
    out[:, 0, 0], out[:, 0, 1] = c * boxes.size[:, 0], -s * boxes.size[:, 1]
    out[:, 1, 0], out[:, 1, 1] = s * boxes.size[:, 0], c * boxes.size[:, 1]
    out[:, 2, 2] = boxes.size[:, 2]
    out[:, :, 3] = boxes.center
    return out


@dataclass(frozen=True)
class ActorGeometry:
    """All actors of a frame merged into one triangle soup, with per-triangle attributes.

    Attributes:
        vertices: (V, 3) float64 world positions, metres (Embree gets a float32 copy).
        triangles: (T, 3) uint32 vertex indices.
        vertex_actor: (V,) int32 dense actor index (position in :class:`Actors`) of each vertex.
        triangle_actor: (T,) int32 dense actor index of each triangle.
        triangle_material: (T,) int32 material index.
        triangle_semantic: (T,) uint8 :class:`SemanticClass` value.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    vertex_actor: np.ndarray
    triangle_actor: np.ndarray
    triangle_material: np.ndarray
    triangle_semantic: np.ndarray


def place_actors(actors: Actors, meshes: ActorMeshes = DEFAULT_MESHES, where: np.ndarray | None = None
                 ) -> ActorGeometry:
    """Scale and place every actor's canonical mesh (vectorised per class) and merge them; with ``where`` (A,) bool,
    only those actors' (their indices stay positions in ``actors``)."""
    codes = actors.class_codes
    if where is not None:
        where = np.asarray(where, bool)
        if where.shape != (len(actors),):
            raise ValueError(f"where must be ({len(actors)},) bool, one per actor; got shape {where.shape}")
        codes = np.where(where, codes, -1)
    parts: list[tuple[np.ndarray, ...]] = []
    vertex_offset = 0
    for code, object_class in enumerate(ObjectClass):
        idx = np.flatnonzero(codes == code)
        if not len(idx):
            continue
        mesh = meshes[object_class]
        affine = unit_to_world(Boxes3D(actors.boxes.center[idx], actors.boxes.size[idx], actors.boxes.yaw_rad[idx]))
        # verts[n, v] = A_n @ vertex_v + t_n; as one stacked matmul (~10x faster than the same einsum).
        verts = np.matmul(mesh.vertices, affine[:, :, :3].transpose(0, 2, 1)) + affine[:, None, :, 3]
        nv, nt = len(mesh.vertices), len(mesh.triangles)
        offsets = vertex_offset + nv * np.arange(len(idx), dtype=np.int64)
        tris = mesh.triangles[None, :, :] + offsets[:, None, None]
        parts.append(
            (
                verts.reshape(-1, 3),
                tris.reshape(-1, 3),
                np.repeat(idx, nv),
                np.repeat(idx, nt),
                np.tile(mesh.material, len(idx)),
                np.full(nt * len(idx), int(mesh.semantic), np.uint8),
            )
        )
        vertex_offset += nv * len(idx)
    if not parts:
        z = np.zeros
        return ActorGeometry(z((0, 3)), z((0, 3), np.uint32), z(0, np.int32), z(0, np.int32),
                             z(0, np.int32), z(0, np.uint8))
    cols = list(zip(*parts, strict=True))
    return ActorGeometry(
        np.concatenate(cols[0]),
        np.concatenate(cols[1]).astype(np.uint32),
        np.concatenate(cols[2]).astype(np.int32),
        np.concatenate(cols[3]).astype(np.int32),
        np.concatenate(cols[4]).astype(np.int32),
        np.concatenate(cols[5]),
    )
