"""Users' own actor meshes: glTF/GLB/OBJ/PLY/STL files, read through trimesh, as canonical actor models.

Conventions:

- Every node of the file's scene that holds a triangle mesh is placed by its scene-graph transform and merged
  (points, lines and empty nodes are skipped); the file's units do not matter, the result is stretched to the
  unit box (:func:`pipeline.world.actors.normalise_to_unit_box`) and from there to each actor's 3D box.
- The file's axes map to ours (x forward, y left, z up) by the rotation whose rows are the file's forward axis,
  up x forward (left) and up (:func:`axes_rotation`): a proper rotation, so winding and handedness survive.
- Each triangle takes our material by the name of its material in the file (glTF material, OBJ ``usemtl``):
  ``material`` is one of our names for every face, or a mapping {file material name: our name} with ``paint``
  (the actor's own colour) for the faces of other materials. Every name must exist: ours in
  :data:`pipeline.world.materials.MATERIAL_NAMES`, the file's among the file's materials.
- Triangles of zero area (repeated or collinear corners) are dropped (counted in the log); vertices that no kept
  triangle uses are dropped too, so that they do not widen the box.

Errors (:class:`UserMeshError`, a ValueError) name the file, the rig key (``where``) and what was expected. A file
the mesh names that is not there is named as such: an OBJ's ``.mtl`` (``mtllib``; an error when ``material`` maps the
file's material names, a warning when one material covers every face) and a ``.gltf``'s buffer files.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.actors import normalise_to_unit_box
from pipeline.world.materials import MATERIAL_NAMES
from pipeline.world.mesh import Mesh

log = logging.getLogger(__name__)

__all__ = ["UserMeshError", "axes_rotation", "load_user_mesh", "missing_material_libraries", "read_mesh_file"]

SUFFIXES = (".glb", ".gltf", ".obj", ".ply", ".stl")
_AXES = {"x": 0, "y": 1, "z": 2}


class UserMeshError(ValueError):
    """A user's mesh file is unreadable, empty, degenerate or names an unknown material."""


def axes_rotation(forward_axis: str, up_axis: str) -> np.ndarray:
    """(3, 3) float64 rotation taking a file's coordinates to ours (x forward, y left, z up): rows are the file's
    forward axis, left = up x forward, and up (each "+x", "-y", ...)."""
    rows = []
    for name, axis in (("forward_axis", forward_axis), ("up_axis", up_axis)):
        if len(axis) != 2 or axis[0] not in "+-" or axis[1] not in _AXES:
            raise ValueError(f"{name} must be one of +x, -x, +y, -y, +z, -z; got {axis!r}")
        row = np.zeros(3)
        row[_AXES[axis[1]]] = 1.0 if axis[0] == "+" else -1.0
        rows.append(row)
    forward, up = rows
    if forward @ up != 0.0:
        raise ValueError(f"forward_axis {forward_axis} and up_axis {up_axis} must be different axes")
    return np.stack([forward, np.cross(up, forward), up])


def missing_material_libraries(path: Path) -> list[tuple[str, Path]]:
    """The ``.mtl`` files an OBJ's ``mtllib`` lines name that are not there: (the name as written, the path it
    resolves to beside the OBJ). trimesh reads an OBJ without them as if it had no materials, so the faces'
    ``usemtl`` names are lost; this tells that apart from a file that has none."""
    path = Path(path)
    if path.suffix.lower() != ".obj":
        return []
    missing = []
    with open(path, encoding="utf-8", errors="replace") as lines:
        for line in lines:
            words = line.strip()
            if words.startswith("mtllib") and words[6:7].isspace():
                name = words[6:].strip()  # the rest of the line, as trimesh reads it (names may hold spaces)
                if name and not (path.parent / name).is_file():
                    missing.append((name, path.parent / name))
    return missing


def _check_gltf_buffers(path: Path) -> None:
    """A ``.gltf`` keeps its geometry in the buffers its JSON names: each must be beside it (or a data URI)."""
    try:
        buffers = json.loads(path.read_text(encoding="utf-8")).get("buffers", [])
    except (OSError, ValueError, AttributeError):
        return  # not JSON, or no buffers list: trimesh's reading reports it
    for i, buffer in enumerate(buffers if isinstance(buffers, list) else []):
        uri = buffer.get("uri") if isinstance(buffer, dict) else None
        if isinstance(uri, str) and not uri.startswith("data:") and not (path.parent / unquote(uri)).is_file():
            raise UserMeshError(f"{path}: buffers[{i}].uri names {uri!r}, which is missing "
                                f"({path.parent / unquote(uri)}); a .gltf keeps its geometry in its buffer files: "
                                "put them beside it, or use the single-file .glb")


def read_mesh_file(path: Path) -> tuple[np.ndarray, np.ndarray, list[str | None]]:
    """A mesh file's triangles, every node's geometry in the file's root frame.

    Returns:
        vertices (V, 3) float64, triangles (T, 3) int64, and each triangle's material name in the file (T items;
        None where the geometry has no named material: PLY, STL, unnamed glTF materials).
    """
    import trimesh  # heavy: only a render with user meshes needs it

    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise UserMeshError(f"{path}: expected a mesh file ({', '.join(SUFFIXES)})")
    if path.suffix.lower() == ".gltf":
        _check_gltf_buffers(path)
    try:
        scene = trimesh.load_scene(path, process=False)
    except Exception as exc:  # trimesh raises many kinds (ValueError, KeyError, struct.error, ...) on bad files
        raise UserMeshError(f"{path}: cannot read it as {path.suffix.lower()[1:]}: {exc}") from exc
    vertices, triangles, names = [], [], []
    offset = 0
    for node in sorted(scene.graph.nodes_geometry):
        transform, geometry_name = scene.graph[node]
        geometry = scene.geometry[geometry_name]
        if not isinstance(geometry, trimesh.Trimesh) or not len(geometry.faces):
            continue
        points = np.asarray(geometry.vertices, np.float64)
        vertices.append(points @ transform[:3, :3].T + transform[:3, 3])
        triangles.append(np.asarray(geometry.faces, np.int64) + offset)
        material = getattr(getattr(geometry, "visual", None), "material", None)
        names += [getattr(material, "name", None)] * len(geometry.faces)
        offset += len(points)
    if not triangles:
        raise UserMeshError(f"{path}: no triangles (expected a mesh; found {len(scene.geometry)} geometries "
                            "without faces)")
    return np.concatenate(vertices), np.concatenate(triangles), names


def _face_materials(names: list[str | None], material: str | Mapping[str, str], path: Path,
                    where: str) -> np.ndarray:
    """(T,) int32 our material index per triangle (see the module docstring)."""
    mapping = {None: material} if isinstance(material, str) else {None: "paint", **material}
    for ours in mapping.values():
        if ours not in MATERIAL_NAMES:
            raise UserMeshError(f"{path}: {where}.material: unknown material {ours!r}; "
                                f"known: {', '.join(MATERIAL_NAMES)}")
    if isinstance(material, str):
        return np.full(len(names), MATERIAL_NAMES.index(material), np.int32)
    present = sorted({n for n in names if n is not None})
    missing = sorted(set(material) - set(present))
    if missing:
        raise UserMeshError(f"{path}: {where}.material names {', '.join(map(repr, missing))}, which the file "
                            f"does not have; its materials: {', '.join(map(repr, present)) or '(none named)'}")
    index = {name: MATERIAL_NAMES.index(ours) for name, ours in mapping.items()}
    return np.array([index.get(n, index[None]) for n in names], np.int32)


def load_user_mesh(path: Path, object_class: ObjectClass, *, forward_axis: str = "+x", up_axis: str = "+z",
                   material: str | Mapping[str, str] = "paint", where: str = "actor_meshes") -> Mesh:
    """A user's mesh file as a canonical model of ``object_class``: in our axes, with our materials, degenerate
    triangles dropped, spanning exactly [-0.5, 0.5] on every axis. ``where`` names the config entry in errors."""
    path = Path(path)
    rotation = axes_rotation(forward_axis, up_axis)
    vertices, triangles, names = read_mesh_file(path)
    for name, resolved in missing_material_libraries(path):
        text = f"{path}: its mtllib line names {name!r}, and that .mtl file is missing ({resolved})"
        if not isinstance(material, str):  # the mapping needs the file's material names, which the .mtl defines
            raise UserMeshError(f"{text}; {where}.material maps the file's materials by name, which that file "
                                "defines: put it beside the .obj")
        log.warning("%s; every face is %s (%s.material), so the mesh is read without it", text, material, where)
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        raise UserMeshError(f"{path}: {bad} vertices are not finite (inf or NaN); expected finite coordinates")
    materials = _face_materials(names, material, path, where)
    vertices = vertices @ rotation.T
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    extent = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    keep = area2 > 1e-12 * extent**2
    if not keep.any():
        raise UserMeshError(f"{path}: all {len(triangles)} triangles have zero area; expected a solid")
    if not keep.all():
        log.info("%s: dropped %d of %d triangles of zero area", path, int((~keep).sum()), len(triangles))
    used, triangles = np.unique(triangles[keep], return_inverse=True)
    mesh = Mesh(vertices[used], triangles.reshape(-1, 3), materials[keep], ObjectClass(object_class).semantic)
    try:
        return normalise_to_unit_box(mesh)
    except ValueError:
        size = np.ptp(mesh.vertices, axis=0)
        raise UserMeshError(f"{path}: the mesh is flat (extent {size.tolist()} along our x, y, z); expected a "
                            "solid with a length, width and height") from None
