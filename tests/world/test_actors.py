"""Procedural actor meshes: they fill their boxes exactly, are placed by an affine map, and validate input."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actors import (
    ActorMeshes,
    Actors,
    canonical_mesh,
    normalise_to_unit_box,
    place_actors,
    srgb8_to_linear,
    unit_to_world,
)
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh


@pytest.mark.parametrize("object_class", list(ObjectClass))
def test_canonical_mesh_spans_the_unit_box_exactly(object_class):
    mesh = canonical_mesh(object_class)
    np.testing.assert_array_equal(mesh.vertices.min(axis=0), [-0.5, -0.5, -0.5])
    np.testing.assert_array_equal(mesh.vertices.max(axis=0), [0.5, 0.5, 0.5])
    assert mesh.semantic == object_class.semantic
    # Outward winding: every part is a closed convex solid, so the signed volume is positive.
    v = mesh.vertices[mesh.triangles]
    assert np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0 > 0.05


def _coplanar_overlaps(mesh: Mesh) -> list[tuple[int, int]]:
    """Pairs of triangles of different materials that lie in one plane and overlap with positive area (separating
    axis test on the in-plane edge normals)."""
    v = mesh.vertices[mesh.triangles]
    normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    plane = np.round(np.column_stack([normal, np.einsum("ij,ij->i", normal, v[:, 0])]), 9)
    pairs = []
    for i in range(len(v)):
        for j in np.flatnonzero(np.all(plane[i + 1:] == plane[i], axis=1)) + i + 1:
            if mesh.material[i] == mesh.material[j]:
                continue
            edges = np.concatenate([np.roll(v[k], -1, axis=0) - v[k] for k in (i, j)])
            axes = np.cross(edges, normal[i])  # in-plane normals of all six edges
            pi, pj = v[i] @ axes.T, v[j] @ axes.T
            if np.all(np.minimum(pi.max(0), pj.max(0)) - np.maximum(pi.min(0), pj.min(0)) > 1e-9):
                pairs.append((i, j))
    return pairs


@pytest.mark.parametrize("object_class", list(ObjectClass))
def test_no_two_materials_share_a_surface(object_class):
    # Where two coplanar triangles overlap, a ray hits both at the same t and Embree reports either, depending on
    # the BVH: the pixel's material would depend on which other actors are in the frame's scene.
    mesh = canonical_mesh(object_class)
    assert _coplanar_overlaps(mesh) == []


def test_the_coplanar_check_finds_an_overlap():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    shifted = square + [0.5, 0.5, 0.0]
    apart = square + [1.0, 0.0, 0.0]  # shares an edge only
    for other, expected in ((shifted, [(0, 2), (1, 3)]), (apart, [])):  # triangles across the diagonal only touch
        mesh = Mesh(np.concatenate([square, other]), np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]]),
                    np.array([0, 0, 1, 1], np.int32), ObjectClass.CAR.semantic)
        assert sorted(_coplanar_overlaps(mesh)) == expected


@pytest.mark.parametrize("object_class", [ObjectClass.CAR, ObjectClass.VAN, ObjectClass.TRUCK, ObjectClass.BUS])
def test_vehicles_have_glass_wheels_lights_and_paint(object_class):
    materials = set(canonical_mesh(object_class).material.tolist())
    for name in ("paint", "glass", "rubber", "headlight", "taillight", "plate"):
        assert material_index(name) in materials, name


def test_placed_mesh_touches_all_six_faces_of_its_box():
    rng = np.random.default_rng(0)
    n = 14
    classes = [list(ObjectClass)[i % 7] for i in range(n)]
    boxes = Boxes3D(rng.uniform(-50, 50, (n, 3)), rng.uniform(0.4, 12.0, (n, 3)), rng.uniform(-np.pi, np.pi, n))
    actors = Actors(np.arange(10, 10 + n), classes, boxes, rng.uniform(0, 1, (n, 3)))
    geo = place_actors(actors)
    assert len(geo.triangles) == sum(len(canonical_mesh(c)) for c in classes)
    for k in range(n):
        v = geo.vertices[geo.vertex_actor == k].astype(np.float64) - boxes.center[k]
        c, s = np.cos(boxes.yaw_rad[k]), np.sin(boxes.yaw_rad[k])
        local = np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]])
        tol = 1e-5 * (1.0 + np.abs(boxes.center[k]).max())  # float32 vertices
        np.testing.assert_allclose(local.min(axis=0), -0.5 * boxes.size[k], atol=tol)
        np.testing.assert_allclose(local.max(axis=0), 0.5 * boxes.size[k], atol=tol)
        tri_owner = geo.vertex_actor[geo.triangles[geo.triangle_actor == k]]
        assert np.all(tri_owner == k)
        assert np.all(geo.triangle_semantic[geo.triangle_actor == k] == classes[k].semantic)


def test_unit_to_world_maps_unit_corners_to_box_corners():
    boxes = Boxes3D([[3.0, -2.0, 0.8]], [[4.5, 1.8, 1.6]], [0.7])
    signs = np.array(
        [[1, 1, -1], [-1, 1, -1], [-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1], [-1, -1, 1], [1, -1, 1]]
    )
    a = unit_to_world(boxes)[0]
    np.testing.assert_allclose(0.5 * signs @ a[:, :3].T + a[:, 3], boxes.corners()[0], atol=1e-12)


def test_actor_validation():
    boxes = Boxes3D(np.zeros((2, 3)), np.ones((2, 3)), np.zeros(2))
    with pytest.raises(ValueError, match="unique"):
        Actors([3, 3], ["car", "car"], boxes, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="positive"):
        Actors([0, 1], ["car", "car"], boxes, np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        Actors([1, 2], ["car", "car"], boxes, np.full((2, 3), 255.0))
    with pytest.raises(ValueError, match="differ"):
        Actors([1], ["car", "car"], boxes, np.zeros((2, 3)))
    with pytest.raises(ValueError):
        Actors([1, 2], ["car", "spaceship"], boxes, np.zeros((2, 3)))
    assert len(Actors.empty()) == 0 and len(place_actors(Actors.empty()).triangles) == 0


def test_mesh_overrides_must_fill_the_unit_box():
    tri = Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 1]], [[0, 1, 2]], 0, ObjectClass.CAR.semantic)
    with pytest.raises(ValueError, match="exactly"):
        ActorMeshes({ObjectClass.CAR: tri})
    unit = normalise_to_unit_box(tri)
    assert ActorMeshes({ObjectClass.CAR: unit})[ObjectClass.CAR] is unit


def test_srgb8_to_linear():
    np.testing.assert_allclose(srgb8_to_linear([[0, 255, 188]]), [[0.0, 1.0, 0.5029]], atol=1e-3)
