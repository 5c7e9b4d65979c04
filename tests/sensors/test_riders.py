"""The rider of a bicycle or motorcycle in the camera's ground truth, on a closed-form model: a cycle drawn as its box
whose upper half is the rider's (:attr:`pipeline.world.mesh.Mesh.part`). The cycle's row is as before (cycle and
rider together, as KITTI's Cyclist); the rider gets a row of its own (its pixels, amodal box, 3D box, occlusion) and
its pixels the semantic class RIDER; and on the library's real bicycles and motorcycles the rider is the figure
riding it."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.geometry import Boxes3D, Transform
from pipeline.core.record_writers.camera import camera_label_rows
from pipeline.sensors.camera import Camera
from pipeline.sensors.render import render_camera
from pipeline.world.actors import DEFAULT_MESHES, ActorMeshes, rider_boxes
from pipeline.world.materials import MATERIAL_NAMES, material_index
from pipeline.world.mesh import BODY, RIDER, Mesh
from pipeline.world.scene import FrameScene, StaticScene
from pipeline.world.two_wheelers import BICYCLES, MOTORCYCLES
from tests.sensors.conftest import CUBE_TRIANGLES, CUBE_VERTICES, camera_config, make_actors

FX = CX = 400.0  # 800 x 600, hfov 90 deg, looking along +x from the origin
CY = 300.0


def _half(lo: float, hi: float) -> np.ndarray:
    v = CUBE_VERTICES.copy()
    v[:, 2] = np.where(v[:, 2] < 0, lo, hi)
    return v


@pytest.fixture(scope="module")
def ridden() -> ActorMeshes:
    """Bicycles drawn as their box: the lower half the cycle's, the upper half the rider's; cars as their box."""
    paint = material_index("paint")
    cycle = Mesh(np.concatenate([_half(-0.5, 0.0), _half(0.0, 0.5)]),
                 np.concatenate([CUBE_TRIANGLES, CUBE_TRIANGLES + 8]), paint, SemanticClass.BICYCLE,
                 np.repeat([BODY, RIDER], len(CUBE_TRIANGLES)))
    return ActorMeshes({ObjectClass.BICYCLE: cycle,
                        ObjectClass.CAR: Mesh(CUBE_VERTICES, CUBE_TRIANGLES, paint, SemanticClass.CAR)})


def _render(meshes, centers, sizes, classes):
    actors = make_actors(centers, sizes, classes=classes)
    return render_camera(FrameScene(StaticScene([]), actors, meshes), Camera(camera_config()), Transform.identity())


def _project(x, y, z):
    return CX - FX * np.asarray(y) / np.asarray(x), CY - FX * np.asarray(z) / np.asarray(x)


def test_the_rider_has_its_own_row_pixels_and_boxes(ridden):
    # The cycle spans x 19..21, y -0.5..0.5, z -1..1; its rider the upper half, z 0..1.
    frame = _render(ridden, [[20.0, 0.0, 0.0]], [[2.0, 1.0, 2.0]], [ObjectClass.BICYCLE])
    lab = frame.labels
    assert lab.rider.tolist() == [False, True] and lab.track_id.tolist() == [1, 1]
    cycle, rider = 0, 1
    mine = frame.instance_id == 1
    on_rider = mine & (frame.semantic == SemanticClass.RIDER)
    assert on_rider.any() and (mine & (frame.semantic == SemanticClass.BICYCLE)).any()
    assert lab.visible_px[cycle] == mine.sum() and lab.visible_px[rider] == on_rider.sum()
    u, v = _project([19.0, 19.0, 21.0, 21.0], [-0.5, 0.5, -0.5, 0.5], [1.0, 1.0, 1.0, 1.0])
    amodal = [u.min(), v.min(), u.max(), CY]  # the rider's bottom edge lies on the horizon (z = 0)
    np.testing.assert_allclose(lab.box_amodal[rider], amodal, atol=1e-6)
    np.testing.assert_allclose(lab.box_tight[rider], amodal, atol=1.0)
    rows, cols = np.nonzero(on_rider)
    assert (rows.min(), rows.max() + 1, cols.min(), cols.max() + 1) == tuple(
        lab.box_tight[rider][[1, 3, 0, 2]].astype(int))
    np.testing.assert_allclose(lab.box_amodal[cycle][[0, 2]], lab.box_amodal[rider][[0, 2]], atol=1e-6)
    assert lab.box_amodal[cycle][3] > CY + 15  # the cycle's holds the lower half too
    # Without its rider (as COCO boxes a bicycle): the lower half, z -1..0, whose top edge is the horizon.
    u, v = _project([19.0, 19.0, 21.0, 21.0], [-0.5, 0.5, -0.5, 0.5], [-1.0, -1.0, -1.0, -1.0])
    np.testing.assert_allclose(lab.box_cycle_amodal[cycle], [u.min(), CY, u.max(), v.max()], atol=1e-6)
    rows, cols = np.nonzero(mine & ~on_rider)
    assert (rows.min(), rows.max() + 1, cols.min(), cols.max() + 1) == tuple(
        lab.box_cycle[cycle][[1, 3, 0, 2]].astype(int))
    assert np.isnan(lab.box_cycle[rider]).all() and np.isnan(lab.box_cycle_amodal[rider]).all()
    assert lab.occlusion[rider] == 0.0 and lab.truncation[rider] == 0.0
    assert lab.unoccluded_px[rider] == lab.visible_px[rider]
    # 3D: the rider's box is the upper half (optical frame: x = -y, y = -z, z = x).
    np.testing.assert_allclose(lab.center_cam[rider], [0.0, -0.5, 20.0], atol=1e-9)
    np.testing.assert_allclose(lab.size[rider], [2.0, 1.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(lab.rotation_cam[rider], lab.rotation_cam[cycle])


def test_a_car_in_front_occludes_the_rider_by_the_closed_form_share(ridden):
    # The rider's silhouette rows run from v = CY - FX / 19 (its near top edge) to the horizon; a wall-like car at
    # x 9.5..10.5 from z = 0.25 up hides the rays above v = CY - FX * 0.25 / 9.5.
    frame = _render(ridden, [[20.0, 0.0, 0.0], [10.0, 0.0, 2.625]], [[2.0, 1.0, 2.0], [1.0, 10.0, 4.75]],
                    [ObjectClass.BICYCLE, ObjectClass.CAR])
    lab = frame.labels
    (rider,) = np.flatnonzero(lab.rider)
    top, edge = CY - FX / 19.0, CY - FX * 0.25 / 9.5
    assert lab.occlusion[rider] == pytest.approx((edge - top) / (CY - top), abs=0.03)
    assert lab.box_tight[rider][1] == pytest.approx(edge, abs=1.0)
    np.testing.assert_allclose(lab.box_amodal[rider][1], top, atol=1e-6)  # the amodal box is the whole rider's


def test_a_rider_cut_by_the_image_border_is_truncated_and_its_row_written_as_a_person(ridden):
    # Half the cycle lies left of the image (u < 0): y from 19.5 to 20.5 at x = 20, the border at y = 20.
    frame = _render(ridden, [[20.0, 20.0, 0.0]], [[2.0, 1.0, 2.0]], [ObjectClass.BICYCLE])
    lab = frame.labels
    (rider,) = np.flatnonzero(lab.rider)
    assert 0.2 < lab.truncation[rider] < 0.8 and lab.box_amodal[rider][0] < 0 <= lab.box_tight[rider][0]
    cols = {"track_id": np.array([1], np.int32), "cls": np.array(["bicycle"], object), "x_m": np.array([20.0]),
            "y_m": np.array([20.0]), "z_m": np.array([0.0]), "length_m": np.array([2.0]),
            "width_m": np.array([1.0]), "height_m": np.array([2.0]), "yaw_rad": np.array([0.0]),
            "model": np.array(["box"], object), "person": np.array([""], object)}
    out = camera_label_rows(3, "front", frame, cols, np.array([7]), np.array([2]))
    assert out["cls"].tolist() == ["bicycle", "rider"] and out["track_id"].tolist() == [1, 1 + 32768]
    assert out["category_id"].tolist() == [2, 1] and out["person"].tolist() == ["", "adult"]
    assert out["lidar_points"].tolist() == [7, 2]
    np.testing.assert_allclose([out["x_m"][1], out["y_m"][1], out["z_m"][1], out["height_m"][1]],
                               [20.0, 20.0, 0.5, 1.0], atol=1e-9)
    assert out["length_m"][0] == 2.0 and out["z_m"][0] == 0.0  # the cycle's own box is untouched
    assert np.isfinite(out["cycle_x1"][0]) and np.isnan(out["cycle_x1"][1])  # its boxes without the rider: its row
    assert out["cycle_amodal_x1"][0] < 0 <= out["cycle_x1"][0]


def test_cars_and_a_frame_without_riders_get_no_rider_rows(ridden):
    lab = _render(ridden, [[20.0, 0.0, 0.0]], [[4.0, 2.0, 1.5]], [ObjectClass.CAR]).labels
    assert len(lab) == 1 and not lab.rider.any()
    assert np.isnan(lab.box_cycle).all() and np.isnan(lab.box_cycle_amodal).all()  # a car is no ridden cycle


@pytest.mark.parametrize("family", [*BICYCLES, *MOTORCYCLES], ids=lambda f: f.__name__)
def test_every_cycle_model_marks_its_figure_as_the_rider(family):
    """The rider's triangles are the figure's (skin, hair, clothes) and none of the cycle's (tyres, lamps), its box
    the top of the model: above the wheels' hubs, reaching the model's top."""
    mesh = family(0) if hasattr(family, "poses") else family()
    rider = mesh.part == RIDER
    assert 0.2 < rider.mean() < 0.6
    mats = set(mesh.material[rider].tolist())
    assert not {material_index("rubber"), material_index("headlight"), material_index("taillight")} & mats
    skin = np.isin(mesh.material, [i for i, n in enumerate(MATERIAL_NAMES) if n.startswith("skin")])
    assert skin.any() and rider[skin].all()  # every bit of skin is the rider's (face, hands)
    top = mesh.rider_vertices()[:, 2].max()
    assert top == mesh.vertices[:, 2].max()
    assert mesh.rider_vertices()[:, 2].min() > mesh.vertices[:, 2].min() + 0.15  # feet above the tyres' bottom


def test_the_rider_box_of_a_real_bicycle_lies_inside_the_cycle_box():
    actors = make_actors([[5.0, 2.0, 0.9]], [[1.75, 0.6, 1.8]], yaws=[0.7], classes=[ObjectClass.BICYCLE])
    has, box = rider_boxes(actors, DEFAULT_MESHES)
    assert has.tolist() == [True]
    cycle = Boxes3D(actors.boxes.center, actors.boxes.size, actors.boxes.yaw_rad)
    local = np.linalg.inv(np.array([[np.cos(0.7), -np.sin(0.7)], [np.sin(0.7), np.cos(0.7)]])) @ (
        box.corners()[0][:, :2] - cycle.center[0, :2]).T
    assert (np.abs(local[0]) <= 1.75 / 2 + 1e-9).all() and (np.abs(local[1]) <= 0.3 + 1e-9).all()
    z = box.corners()[0][:, 2]
    assert z.max() == pytest.approx(0.9 + 0.9) and z.min() > 0.0 + 0.2
    assert box.size[0, 2] < 1.8 and box.yaw_rad[0] == pytest.approx(0.7)
