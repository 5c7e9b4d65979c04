"""The renderer's sensors and actor meshes of a validated rig config (pipeline.core.config)."""

from __future__ import annotations

from pathlib import Path

from pipeline.core.config import RigConfig
from pipeline.core.digests import path_sha256
from pipeline.sensors.camera import Camera
from pipeline.sensors.lidar import Lidar
from pipeline.world.actors import DEFAULT_MESHES, ActorMeshes, Model, umbrella_families, umbrella_meshes


def build_sensors(rig: RigConfig) -> tuple[list[Camera], list[Lidar]]:
    """The rig's cameras and LiDARs, each built from its validated config."""
    return [Camera(c) for c in rig.cameras], [Lidar(lidar) for lidar in rig.lidars]


def build_actor_meshes(rig: RigConfig, umbrellas: bool = False) -> ActorMeshes:
    """The actor models of a rig: its ``actor_meshes`` files (pipeline.world.user_meshes) replacing or joining
    their classes' built-in body families, the built-in library (shared) where it names none. Each model is named
    by its file's stem. ``umbrellas``: the people's families with their umbrella poses (a rain that asks for them)."""
    if not rig.actor_meshes:
        return umbrella_meshes() if umbrellas else DEFAULT_MESHES
    from pipeline.world.user_meshes import load_user_mesh

    replace: dict = {}
    extra: dict = {}
    for i, entry in enumerate(rig.actor_meshes):
        if path_sha256(entry.file) != entry.sha256:  # the config (so the record's meta) must describe these bytes
            raise ValueError(f"{entry.file}: actor_meshes[{i}]: the file changed since the rig was read "
                             f"(sha256 {entry.sha256})")
        mesh = load_user_mesh(entry.file, entry.cls, forward_axis=entry.forward_axis, up_axis=entry.up_axis,
                              material=entry.material, where=f"actor_meshes[{i}]")
        (replace if entry.replace else extra).setdefault(entry.cls, []).append(Model(Path(entry.path).stem, mesh))
    return ActorMeshes(replace, extra, umbrella_families() if umbrellas else None)
