"""Hand-made scenes for the sensor tests: box-shaped actors, walls, an empty world (real Embree, no mocks)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.config import ConditionConfig
from pipeline.core.config.sensors import CameraConfig, LidarConfig
from pipeline.core.geometry import Boxes3D
from pipeline.sensors.conditions import Condition
from pipeline.world.actors import ActorMeshes, Actors
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh

CUBE_VERTICES = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
# Outward (counter-clockwise seen from outside) faces of the cube above, two triangles each.
CUBE_TRIANGLES = np.array([
    [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
    [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
])


def wall_mesh(x_m: float, half_size_m: float = 500.0, material: str = "concrete") -> Mesh:
    """A square wall in the plane x = x_m, facing -x, of the given half size (world frame)."""
    h = half_size_m
    v = np.array([[x_m, -h, -h], [x_m, h, -h], [x_m, h, h], [x_m, -h, h]])
    return Mesh(v, np.array([[0, 2, 1], [0, 3, 2]]), material_index(material), SemanticClass.BUILDING)


@pytest.fixture(scope="session")
def box_meshes() -> ActorMeshes:
    """Every class drawn as its exact 3D box (painted), so projections have closed forms."""
    paint = material_index("paint")
    return ActorMeshes({c: Mesh(CUBE_VERTICES, CUBE_TRIANGLES, paint, c.semantic) for c in ObjectClass})


def make_actors(centers, sizes, yaws=None, classes=None, colors=None, brake=None, lights_on=None) -> Actors:
    """Actors with track ids 1..N (defaults: cars, yaw 0, grey, lights on)."""
    centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    n = len(centers)
    return Actors(
        np.arange(1, n + 1),
        tuple(classes) if classes is not None else (ObjectClass.CAR,) * n,
        Boxes3D(centers, np.asarray(sizes, dtype=np.float64).reshape(-1, 3), np.zeros(n) if yaws is None else yaws),
        np.full((n, 3), 0.5) if colors is None else colors,
        brake,
        lights_on=lights_on,
    )


@pytest.fixture(scope="session")
def actors_factory():
    """:func:`make_actors`, as a fixture."""
    return make_actors


@pytest.fixture(scope="session")
def wall():
    """:func:`wall_mesh`, as a fixture."""
    return wall_mesh


def camera_config(**fields) -> CameraConfig:
    """A validated camera config named "front", mounted at the ego's origin unless ``fields`` say otherwise."""
    return CameraConfig(**{"name": "front", "mount": {"xyz_m": (0.0, 0.0, 0.0)}, **fields})


def lidar_config(**fields) -> LidarConfig:
    """A validated LiDAR config named "top", mounted at the ego's origin unless ``fields`` say otherwise."""
    return LidarConfig(**{"name": "top", "mount": {"xyz_m": (0.0, 0.0, 0.0)}, **fields})


def condition(**sections) -> Condition:
    """A condition named "test" from config sections (``sun={"elevation_deg": 10.0}``, ...); the rest default."""
    return Condition(ConditionConfig(name="test", **sections))
