"""Users' own actor meshes in a rig (``actor_meshes:``): mesh files drawn for the actors of one class.

Conventions:

- ``path`` is relative to the YAML file that names it (to the current folder for a config validated from data
  without a file); the config keeps it as written, so the record's ``meta.json`` is the same on any machine.
- The file's sha256 is read when the config is validated and kept in the config (so in the record's
  ``meta.json`` and its config hash): a changed asset changes the hash and the render's resume key. A config
  that states ``sha256`` pins the file: validation fails when the file no longer matches.
- ``forward_axis`` and ``up_axis`` name the file's axes that point forward and up; ours are x forward, y left,
  z up (glTF files are y up and, by the glTF spec, +z forward: ``forward_axis: +z, up_axis: +y``).
- ``material`` is one of our material names for every face, or a mapping from the file's material names
  (glTF materials, OBJ ``usemtl``) to ours, faces of other materials taking ``paint`` (the actor's colour).
  Our names are checked where the mesh is read (pipeline.world.user_meshes), which knows the table.
- ``replace``: the class's meshes replace its built-in body families (true) or join them (false); every
  entry of one class must say the same.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, PrivateAttr, ValidationInfo, model_validator

from pipeline.core.classes import ObjectClass
from pipeline.core.config.base import ConfigModel
from pipeline.core.digests import path_sha256

__all__ = ["MESH_SUFFIXES", "ActorMeshConfig", "Axis"]

Axis = Literal["+x", "-x", "+y", "-y", "+z", "-z"]
MESH_SUFFIXES = (".glb", ".gltf", ".obj", ".ply", ".stl")
_NAME = r"^[A-Za-z0-9_]+$"  # our material names


class ActorMeshConfig(ConfigModel):
    """One mesh file drawn (stretched to each actor's 3D box) for actors of class ``cls``."""

    cls: ObjectClass = Field(description="the actor class drawn with this mesh")
    path: str = Field(min_length=1, description="glTF/GLB/OBJ/PLY/STL file, relative to the YAML file")
    sha256: str | None = Field(None, pattern=r"^[0-9a-f]{64}$",
                               description="the file's digest: filled in when left out, checked when given")
    forward_axis: Axis = Field("+x", description="the file's axis that points forward")
    up_axis: Axis = Field("+z", description="the file's axis that points up")
    material: str | dict[str, str] = Field(
        "paint", description="our material for every face, or {file material name: our material name}")
    replace: bool = Field(True, description="replace the class's built-in body families (or join them)")
    _file: Path = PrivateAttr(default_factory=Path)

    @model_validator(mode="before")
    @classmethod
    def _read_digest(cls, data: Any, info: ValidationInfo) -> Any:
        if not isinstance(data, dict) or not isinstance(data.get("path"), str) or not data["path"]:
            return data  # field validation reports it
        file = _resolve(data["path"], info.context)
        if file.suffix.lower() not in MESH_SUFFIXES:
            raise ValueError(f"path {data['path']!r}: expected a mesh file ({', '.join(MESH_SUFFIXES)})")
        if not file.is_file():
            raise ValueError(f"path {data['path']!r}: no such file {file}")
        digest = path_sha256(file)
        if data.get("sha256") is not None and data["sha256"] != digest:
            raise ValueError(f"sha256: {file} has digest {digest}, the config pins {data['sha256']!r} "
                             "(the asset changed)")
        return {**data, "sha256": digest}

    @model_validator(mode="after")
    def _check(self) -> ActorMeshConfig:
        if self.forward_axis[1] == self.up_axis[1]:
            raise ValueError(f"forward_axis {self.forward_axis} and up_axis {self.up_axis} must be different axes")
        names = [self.material] if isinstance(self.material, str) else list(self.material.values())
        if isinstance(self.material, dict) and not self.material:
            raise ValueError("material: an empty mapping; give our material name or {file material: ours}")
        bad = [n for n in names if not re.fullmatch(_NAME, n)]
        if bad:
            raise ValueError(f"material: {bad[0]!r} is not a material name (letters, digits, _)")
        return self

    def model_post_init(self, context: Any, /) -> None:
        self._file = _resolve(self.path, context)

    @property
    def file(self) -> Path:
        """The mesh file, resolved against the YAML file's folder (absolute)."""
        return self._file


def _resolve(path: str, context: Any) -> Path:
    """``path`` against the folder of the config file named in the validation context (else the current one)."""
    source = context.get("config_file") if isinstance(context, dict) else None
    base = Path(source).resolve().parent if source else Path.cwd()
    return (base / Path(path).expanduser()).resolve()
