"""Smooth shading normals (pipeline.world.smooth_normals): closed forms on a sphere and a cube, through real casts."""

from __future__ import annotations

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actors import ActorMeshes, Actors, normalise_to_unit_box
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene
from pipeline.world.smooth_normals import corner_normals, interpolate, interpolated


def uv_sphere(rings: int = 12, segments: int = 24) -> Mesh:
    """A unit-radius sphere as a closed triangle mesh (outward winding), poles included."""
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    body = np.column_stack([(np.sin(t) * np.cos(p)).ravel(), (np.sin(t) * np.sin(p)).ravel(), np.cos(t).ravel()])
    v = np.vstack([[0.0, 0.0, 1.0], body, [0.0, 0.0, -1.0]])
    south = len(v) - 1
    tris = []
    for j in range(segments):
        k = (j + 1) % segments
        tris.append([0, 1 + j, 1 + k])
        for r in range(rings - 2):
            a, b = 1 + r * segments + j, 1 + r * segments + k
            tris += [[a, a + segments, b], [b, a + segments, b + segments]]
        last = 1 + (rings - 2) * segments
        tris.append([last + j, south, last + k])
    return Mesh(v, np.array(tris), material_index("paint"), ObjectClass.CAR.semantic)


def test_a_cubes_corners_keep_their_faces_normals():
    cube = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    tris = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                     [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    corners = corner_normals(cube, tris, np.array([4.5, 1.8, 1.5]))
    face = np.cross(cube[tris[:, 1]] - cube[tris[:, 0]], cube[tris[:, 2]] - cube[tris[:, 0]])
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    np.testing.assert_allclose(corners, np.repeat(face[:, None], 3, axis=1), atol=1e-7)


def test_sphere_hits_get_the_spheres_own_normal():
    """Rays at a sphere (radius 1, placed with a unit-box size of 2): the shading normal is within 1.5 degrees of
    the true normal p / |p| everywhere, where the facets' own normals are off by several degrees."""
    sphere = normalise_to_unit_box(uv_sphere())
    meshes = ActorMeshes({ObjectClass.CAR: sphere})
    actors = Actors([1], [ObjectClass.CAR], Boxes3D([[10.0, 0.0, 0.0]], [[2.0, 2.0, 2.0]], [0.0]), [[0.5, 0.5, 0.5]])
    scene = FrameScene(StaticScene([]), actors, meshes)
    rng = np.random.default_rng(0)
    targets = rng.uniform(-0.7, 0.7, (2000, 2))
    origins = np.column_stack([np.zeros(len(targets)), targets])
    hits = scene.cast(origins, np.tile([1.0, 0.0, 0.0], (len(targets), 1)))
    assert hits.hit.sum() > 1500
    point = origins[hits.hit] + hits.t_m[hits.hit, None] * np.array([1.0, 0.0, 0.0])
    true = (point - [10.0, 0.0, 0.0]) / np.linalg.norm(point - [10.0, 0.0, 0.0], axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", hits.normal[hits.hit], true), -1, 1)))
    assert angle.max() < 1.5
    flat = FrameScene(StaticScene([]), actors, meshes)
    flat.meshes._corners[0] = np.repeat(  # the facets' own normals, for contrast
        np.cross(sphere.vertices[sphere.triangles[:, 1]] - sphere.vertices[sphere.triangles[:, 0]],
                 sphere.vertices[sphere.triangles[:, 2]] - sphere.vertices[sphere.triangles[:, 0]])[:, None], 3, axis=1)
    faceted = flat.cast(origins, np.tile([1.0, 0.0, 0.0], (len(targets), 1)))
    flat_angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", faceted.normal[hits.hit], true), -1, 1)))
    assert flat_angle.max() > 4.0


def test_corner_normals_equal_a_loop_over_each_vertexs_triangles():
    """The compiled grouping against its definition written out: each corner's normal is the sum, in triangle order,
    of the area-weighted normals of the triangles at its vertex within the crease of its own, scaled to the unit box
    and normalised; on a sphere (smooth) and a cube (every edge a crease) sharing no vertex (within a float32 ulp or
    two: the test's own norms may round otherwise)."""
    sphere = uv_sphere(6, 10)
    cube = np.array([[x, y, z] for x in (2.0, 3.0) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    cube_tris = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                          [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    vertices = np.vstack([sphere.vertices, cube])
    tris = np.vstack([sphere.triangles, cube_tris + len(sphere.vertices)])[np.random.default_rng(3).permutation(
        len(sphere.triangles) + len(cube_tris))]
    extent = np.array([4.0, 2.0, 1.5])
    metric = vertices * extent
    face = np.cross(metric[tris[:, 1]] - metric[tris[:, 0]], metric[tris[:, 2]] - metric[tris[:, 0]])
    unit = face / np.linalg.norm(face, axis=1, keepdims=True)
    expected = np.zeros((len(tris), 3, 3))
    for t, tri in enumerate(tris):
        for k, v in enumerate(tri):
            total = np.zeros(3)
            for u in np.flatnonzero((tris == v).any(axis=1)):
                if unit[t] @ unit[u] >= np.cos(np.radians(35.0)):
                    total = total + face[u]
            expected[t, k] = total * extent / np.linalg.norm(total * extent)
    got = corner_normals(vertices, tris, extent)
    np.testing.assert_allclose(got, expected, rtol=0, atol=2.5e-7)
    assert corner_normals(vertices, tris[:0], extent).shape == (0, 3, 3)


def test_compiled_interpolation_gives_the_numpy_definitions_bits():
    """interpolated (the renderer's compiled pass over a table of corner normals) against interpolate (numpy) on the
    gathered rows: the same float32 bits, with zero corner normals (the 1e-12 floor), barycentrics outside the
    triangle, and rays grazing the face (where the flip test's sign is decided by the last bits)."""
    rng = np.random.default_rng(3)
    table = rng.normal(size=(300, 3, 3)).astype(np.float32)
    table /= np.linalg.norm(table, axis=2, keepdims=True)
    table[:20] = 0.0
    k = 50_000
    rows = rng.integers(0, len(table), k).astype(np.int64)
    uv = rng.uniform(-0.2, 1.0, (k, 2)).astype(np.float32)
    face = rng.normal(size=(k, 3)).astype(np.float32)
    face /= np.linalg.norm(face, axis=1, keepdims=True)
    d = rng.normal(size=(k, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[: k // 2] -= np.sum(d[: k // 2] * face[: k // 2], axis=1, keepdims=True) * face[: k // 2] * np.float32(0.99999)
    expected = interpolate(table[rows], uv, face, d)
    got = interpolated(table, rows, uv, face, d)
    assert np.array_equal(expected.view(np.uint32), got.view(np.uint32))
    assert np.any(np.all(got == face, axis=1)) and not np.all(np.all(got == face, axis=1))  # both branches taken
