"""Users' own actor meshes: files the tests write (OBJ + MTL, GLB through trimesh's exporter), read in our axes and
materials, placed to fill their 3D boxes, hit by rays with the actor's id, class and the mapped material."""

from __future__ import annotations

import json
import logging
import re

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.geometry import Boxes3D
from pipeline.world.actor_shapes import FAMILIES
from pipeline.world.actors import ActorMeshes, Actors, Model, place_actors
from pipeline.world.materials import material_index
from pipeline.world.scene import FrameScene, StaticScene
from pipeline.world.user_meshes import UserMeshError, axes_rotation, load_user_mesh, missing_material_libraries
from tests.world.user_assets import UNIT_CABIN_HI, UNIT_CABIN_LO, write_glb, write_obj

GLASS, PAINT = material_index("glass"), material_index("paint")


def cabin_bounds(mesh):
    """(lo, hi) of the vertices of the mesh's glass triangles."""
    corners = mesh.vertices[mesh.triangles[mesh.material == GLASS]].reshape(-1, 3)
    return corners.min(axis=0), corners.max(axis=0)


def vertex_set(mesh) -> np.ndarray:
    return np.unique(np.round(mesh.vertices, 9), axis=0)


def test_axes_rotation_is_proper_and_maps_the_named_axes():
    for forward, up in (("+x", "+z"), ("+y", "+z"), ("+z", "+y"), ("-x", "-y")):
        r = axes_rotation(forward, up)
        assert np.linalg.det(r) == pytest.approx(1.0)
        axis = {"x": 0, "y": 1, "z": 2}
        f = np.eye(3)[axis[forward[1]]] * (1 if forward[0] == "+" else -1)
        u = np.eye(3)[axis[up[1]]] * (1 if up[0] == "+" else -1)
        np.testing.assert_array_equal(r @ f, [1, 0, 0])
        np.testing.assert_array_equal(r @ u, [0, 0, 1])
    with pytest.raises(ValueError, match="different axes"):
        axes_rotation("+y", "-y")


def test_obj_fills_the_unit_box_with_its_cabin_at_the_rear_in_glass(tmp_path):
    mesh = load_user_mesh(write_obj(tmp_path), ObjectClass.CAR, material={"glass": "glass"})
    np.testing.assert_array_equal(mesh.vertices.min(axis=0), [-0.5, -0.5, -0.5])
    np.testing.assert_array_equal(mesh.vertices.max(axis=0), [0.5, 0.5, 0.5])
    assert mesh.semantic == SemanticClass.CAR and len(mesh) == 24
    assert sorted(np.unique(mesh.material).tolist()) == sorted([GLASS, PAINT])  # "body" is not mapped: paint
    lo, hi = cabin_bounds(mesh)
    np.testing.assert_allclose(lo, UNIT_CABIN_LO, atol=1e-9)
    np.testing.assert_allclose(hi, UNIT_CABIN_HI, atol=1e-9)


@pytest.mark.parametrize(("forward", "up"), [("+y", "+z"), ("-x", "+z"), ("+z", "+y"), ("-z", "-x")])
def test_a_mesh_modelled_in_other_axes_faces_forward(tmp_path, forward, up):
    """The same model written with its forward along ``forward`` and read with that forward_axis is the +x one."""
    reference = load_user_mesh(write_obj(tmp_path, "ref"), ObjectClass.CAR, material={"glass": "glass"})
    turned = load_user_mesh(write_obj(tmp_path, "turned", forward, up), ObjectClass.CAR, forward_axis=forward,
                            up_axis=up, material={"glass": "glass"})
    np.testing.assert_allclose(vertex_set(turned), vertex_set(reference), atol=1e-9)
    np.testing.assert_allclose(cabin_bounds(turned)[0], UNIT_CABIN_LO, atol=1e-9)
    np.testing.assert_allclose(cabin_bounds(turned)[1], UNIT_CABIN_HI, atol=1e-9)
    # Read with the default axes instead, the model lies on its side or faces backwards: not the same.
    wrong = load_user_mesh(tmp_path / "turned.obj", ObjectClass.CAR, material={"glass": "glass"})
    assert not np.allclose(cabin_bounds(wrong)[1], UNIT_CABIN_HI, atol=1e-3)


def test_glb_nodes_are_merged_with_their_transforms(tmp_path):
    """A GLB (trimesh's exporter; y up, +z forward, the cabin a node translated into place) reads as the OBJ."""
    reference = load_user_mesh(write_obj(tmp_path), ObjectClass.CAR, material={"glass": "glass"})
    glb = load_user_mesh(write_glb(tmp_path), ObjectClass.CAR, forward_axis="+z", up_axis="+y",
                         material={"glass": "glass", "body": "metal"})
    np.testing.assert_allclose(vertex_set(glb), vertex_set(reference), atol=1e-6)  # GLB stores float32
    np.testing.assert_allclose(cabin_bounds(glb)[0], UNIT_CABIN_LO, atol=1e-6)
    np.testing.assert_allclose(cabin_bounds(glb)[1], UNIT_CABIN_HI, atol=1e-6)
    assert sorted(np.unique(glb.material).tolist()) == sorted([GLASS, material_index("metal")])


def test_one_material_for_every_face_and_degenerate_faces_dropped(tmp_path):
    # A face with a repeated corner and a collinear one (its vertex far outside the model) are dropped, and
    # the far vertex with them: the box stays the model's.
    path = write_obj(tmp_path, extra_lines="v 0 -0.9 50\nf 1 1 2\nf 1 2 17\n")
    mesh = load_user_mesh(path, ObjectClass.VAN, material="cargo")
    assert len(mesh) == 24 and np.all(mesh.material == material_index("cargo"))
    assert mesh.semantic == SemanticClass.VAN
    np.testing.assert_allclose(cabin_bounds(load_user_mesh(path, ObjectClass.VAN, material={"glass": "glass"}))[1],
                               UNIT_CABIN_HI, atol=1e-9)


def test_placed_user_mesh_fills_its_sumo_box_and_rays_hit_it_as_the_actor(tmp_path):
    mesh = load_user_mesh(write_obj(tmp_path), ObjectClass.CAR, material={"glass": "glass"})
    meshes = ActorMeshes({ObjectClass.CAR: [Model("wedge", mesh)]})
    centre, size, yaw = np.array([20.0, 3.0, 0.75]), np.array([4.5, 1.8, 1.5]), 0.4
    actors = Actors([9], [ObjectClass.CAR], Boxes3D([centre], [size], [yaw]), [[0.8, 0.1, 0.1]])
    assert meshes.model_names[meshes.model_codes(actors)[0]] == "wedge"
    geo = place_actors(actors, meshes)
    c, s = np.cos(yaw), np.sin(yaw)
    d = geo.vertices - centre
    local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    np.testing.assert_allclose(local.min(axis=0), -size / 2, atol=1e-9)
    np.testing.assert_allclose(local.max(axis=0), size / 2, atol=1e-9)

    scene = FrameScene(StaticScene([]), actors, meshes)
    forward, left = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
    cabin_x = 0.5 * (UNIT_CABIN_LO[0] + UNIT_CABIN_HI[0]) * size[0]  # the cabin's middle, along the car
    rear_x = -0.25 * size[0]  # the body behind the cabin
    top = centre[2] + size[2] / 2
    body_top = centre[2] - size[2] / 2 + (1.0 - 0.2) / 1.3 * size[2]  # z 1.0 of the model, in the box
    origins = np.array([centre + cabin_x * forward + [0, 0, 10.0], centre + rear_x * forward + [0, 0, 10.0],
                        centre + 0.2 * left + cabin_x * forward + [0, 0, 10.0]])
    hits = scene.cast(origins, np.tile([0.0, 0.0, -1.0], (3, 1)))
    assert hits.hit.all() and hits.instance_id.tolist() == [9, 9, 9]
    assert hits.semantic.tolist() == [SemanticClass.CAR] * 3
    assert hits.material.tolist() == [GLASS, PAINT, GLASS]
    np.testing.assert_allclose(hits.t_m, [10.0 + centre[2] - top, 10.0 + centre[2] - body_top,
                                          10.0 + centre[2] - top], atol=1e-4)
    np.testing.assert_allclose(hits.color[1], [0.8, 0.1, 0.1])  # paint takes the actor's colour


def test_extra_models_join_the_built_in_families(tmp_path):
    mesh = load_user_mesh(write_obj(tmp_path), ObjectClass.CAR)
    meshes = ActorMeshes(extra={ObjectClass.CAR: [Model("a", mesh), Model("b", mesh)]})
    names = [n for n, c in zip(meshes.model_names, meshes.model_class, strict=True) if c == ObjectClass.CAR]
    assert names == [f.__name__ for f in FAMILIES[ObjectClass.CAR]] + ["a", "b"]
    n = 300
    boxes = Boxes3D(np.zeros((n, 3)), np.tile([4.5, 1.8, 1.5], (n, 1)), np.zeros(n))
    actors = Actors(np.arange(1, n + 1), ["car"] * n, boxes, np.zeros((n, 3)), variant=np.arange(n))
    picked = {meshes.model_names[c] for c in meshes.model_codes(actors)}
    assert {"a", "b"} <= picked and len(picked) > 2  # user models among the suitable built-in families


def test_errors_name_the_file_and_what_was_expected(tmp_path):
    obj = write_obj(tmp_path)
    with pytest.raises(UserMeshError, match=r"wedge\.obj: actor_meshes\[3\]\.material: unknown material 'glas'"):
        load_user_mesh(obj, ObjectClass.CAR, material={"glass": "glas"}, where="actor_meshes[3]")
    with pytest.raises(UserMeshError, match=r"does not have; its materials: 'body', 'glass'"):
        load_user_mesh(obj, ObjectClass.CAR, material={"windscreen": "glass"})
    (tmp_path / "empty.obj").write_text("# nothing\nv 0 0 0\n")
    with pytest.raises(UserMeshError, match=r"empty\.obj: no triangles"):
        load_user_mesh(tmp_path / "empty.obj", ObjectClass.CAR)
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(UserMeshError, match=r"flat\.obj: the mesh is flat"):
        load_user_mesh(tmp_path / "flat.obj", ObjectClass.CAR)
    (tmp_path / "line.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    with pytest.raises(UserMeshError, match=r"line\.obj: all 1 triangles have zero area"):
        load_user_mesh(tmp_path / "line.obj", ObjectClass.CAR)
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 nan\nv 0 1 1\nf 1 2 3\n")
    with pytest.raises(UserMeshError, match=r"nan\.obj: 1 vertices are not finite"):
        load_user_mesh(tmp_path / "nan.obj", ObjectClass.CAR)
    (tmp_path / "broken.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    with pytest.raises(UserMeshError, match=r"broken\.glb: cannot read it as glb"):
        load_user_mesh(tmp_path / "broken.glb", ObjectClass.CAR)


def test_an_obj_whose_mtl_file_is_missing_names_both_files(tmp_path, caplog):
    obj = write_obj(tmp_path)
    (tmp_path / "wedge.mtl").unlink()
    with pytest.raises(UserMeshError, match=rf"wedge\.obj: its mtllib line names 'wedge\.mtl', and that \.mtl file "
                                            rf"is missing \({re.escape(str(tmp_path / 'wedge.mtl'))}\); "
                                            r"actor_meshes\[0\]\.material maps the file's materials by name"):
        load_user_mesh(obj, ObjectClass.CAR, material={"glass": "glass"}, where="actor_meshes[0]")
    # one material for every face: the .mtl is not needed, so it is read without it, with a warning naming both
    caplog.set_level(logging.WARNING, "pipeline.world.user_meshes")
    mesh = load_user_mesh(obj, ObjectClass.CAR, material="paint")
    assert (mesh.material == PAINT).all()
    assert "wedge.obj: its mtllib line names 'wedge.mtl', and that .mtl file is missing" in caplog.text


def test_an_mtl_name_with_spaces_is_read_whole_and_a_present_mtl_is_not_reported(tmp_path):
    obj = write_obj(tmp_path)
    assert missing_material_libraries(obj) == []
    text = obj.read_text().replace("mtllib wedge.mtl", "mtllib my wedge.mtl")
    obj.write_text(text)
    assert missing_material_libraries(obj) == [("my wedge.mtl", tmp_path / "my wedge.mtl")]
    (tmp_path / "wedge.mtl").rename(tmp_path / "my wedge.mtl")
    assert missing_material_libraries(obj) == []
    mesh = load_user_mesh(obj, ObjectClass.CAR, material={"glass": "glass"})
    assert (mesh.material == GLASS).any() and (mesh.material == PAINT).any()


def test_a_gltf_whose_buffer_file_is_missing_names_it(tmp_path):
    import trimesh

    files = trimesh.creation.box().export(file_type="gltf")
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    gltf = tmp_path / "model.gltf"
    assert load_user_mesh(gltf, ObjectClass.CAR).vertices.shape == (8, 3)
    buffer = json.loads(gltf.read_text())["buffers"][0]["uri"]
    (tmp_path / buffer).unlink()
    with pytest.raises(UserMeshError, match=rf"model\.gltf: buffers\[0\]\.uri names '{re.escape(buffer)}', which is "
                                            rf"missing \({re.escape(str(tmp_path / buffer))}\)"):
        load_user_mesh(gltf, ObjectClass.CAR)
