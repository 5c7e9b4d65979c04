"""Camera ground truth on hand-made scenes with closed-form answers (box-shaped actors, no mocks)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.geometry import Boxes3D, Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.render import render_camera
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import camera_config

FX = CX = 400.0  # 800 x 600, hfov 90 deg: fx = fy = 400, (cx, cy) = (400, 300)
CY = 300.0
EGO = Transform.identity()  # camera body frame = ego frame = world: looks along +x from the origin


def analytic_bbox(corners_world: np.ndarray) -> np.ndarray:
    """Pinhole projection of world points seen from the origin along +x: u = cx - fx y/x, v = cy - fy z/x."""
    u = CX - FX * corners_world[:, 1] / corners_world[:, 0]
    v = CY - FX * corners_world[:, 2] / corners_world[:, 0]
    return np.array([u.min(), v.min(), u.max(), v.max()])


def render(actors, box_meshes, static=(), **camera_kwargs):
    scene = FrameScene(StaticScene(list(static)), actors, box_meshes)
    return render_camera(scene, Camera(camera_config(**camera_kwargs)), EGO)


def row_of(labels, track_id):
    (i,) = np.flatnonzero(labels.track_id == track_id)
    return i


@pytest.mark.parametrize("yaw", [0.0, 0.35, -1.2])
def test_single_box_tight_box_is_the_analytic_projection(box_meshes, actors_factory, yaw):
    actors = actors_factory([[20.0, 1.0, -0.5]], [[4.0, 2.0, 1.5]], yaws=[yaw])
    frame = render(actors, box_meshes)
    lab = frame.labels
    assert len(lab) == 1 and lab.visible[0]
    expected = analytic_bbox(actors.boxes.corners()[0])
    np.testing.assert_allclose(lab.box_tight[0], expected, atol=1.0)
    np.testing.assert_allclose(lab.box_amodal[0], expected, atol=1e-6)
    assert lab.visible_px[0] == lab.unoccluded_px[0] == np.count_nonzero(frame.instance_id == 1)
    assert lab.occlusion[0] == 0.0 and lab.truncation[0] == 0.0
    # 3D box in the optical frame: x_cam = -y, y_cam = -z, z_cam = x; heading (cos, sin, 0) -> (-sin, 0, cos).
    np.testing.assert_allclose(lab.center_cam[0], [-1.0, 0.5, 20.0], atol=1e-9)
    np.testing.assert_allclose(lab.rotation_cam[0][:, 0], [-np.sin(yaw), 0.0, np.cos(yaw)], atol=1e-12)
    np.testing.assert_allclose(lab.size[0], [4.0, 2.0, 1.5])
    assert lab.distance_m[0] == pytest.approx(np.sqrt(1 + 0.25 + 400), rel=1e-6)
    # KITTI: heading = (cos ry, 0, -sin ry) in the camera; a level camera gives ry = -yaw - pi/2.
    ry = np.arctan2(-lab.rotation_cam[0][2, 0], lab.rotation_cam[0][0, 0])
    assert np.cos(ry - (-yaw - np.pi / 2)) == pytest.approx(1.0)


def test_half_hidden_box_has_the_analytic_occlusion(box_meshes, actors_factory):
    # Rear box centred on the axis: its silhouette is its near face (x = 29, |y| <= 2, |z| <= 1).
    # The occluder (x in [14, 16], y in [-0.3, 5.7]) hides every ray with u < cx + fx * 0.3 / 14.
    actors = actors_factory([[31.0, 0.0, 0.0], [15.0, 2.7, 0.0]], [[4.0, 4.0, 2.0], [2.0, 6.0, 6.0]])
    lab = render(actors, box_meshes).labels
    rear, front = row_of(lab, 1), row_of(lab, 2)
    u_min, u_max, u_edge = CX - FX * 2 / 29, CX + FX * 2 / 29, CX + FX * 0.3 / 14
    expected = (u_edge - u_min) / (u_max - u_min)
    assert lab.occlusion[rear] == pytest.approx(expected, abs=0.03)
    assert lab.occlusion[front] == 0.0
    assert lab.truncation[rear] == 0.0
    np.testing.assert_allclose(lab.box_tight[rear], [u_edge, CY - FX / 29, u_max, CY + FX / 29], atol=1.0)
    np.testing.assert_allclose(lab.box_amodal[rear], [u_min, CY - FX / 29, u_max, CY + FX / 29], atol=1e-6)


def test_fully_hidden_box_is_labelled_but_never_visible(box_meshes, actors_factory):
    actors = actors_factory([[30.0, 0.0, 0.0], [10.0, 0.0, 0.0], [-10.0, 0.0, 0.0]],
                            [[2.0, 2.0, 2.0], [1.0, 8.0, 8.0], [2.0, 2.0, 2.0]])
    lab = render(actors, box_meshes).labels
    assert sorted(lab.track_id.tolist()) == [1, 2]  # the box behind the camera has no row
    hidden = row_of(lab, 1)
    assert not lab.visible[hidden] and lab.visible_px[hidden] == 0 and lab.unoccluded_px[hidden] > 0
    assert lab.occlusion[hidden] == 1.0
    assert np.isnan(lab.box_tight[hidden]).all()


def test_truncation_at_the_image_edge(box_meshes, actors_factory):
    # A thin plate facing the camera at x = 20 with y in [18, 22]: u in [-40, 40], half off the image.
    actors = actors_factory([[20.0, 20.0, 0.0]], [[0.02, 4.0, 2.0]])
    lab = render(actors, box_meshes).labels
    assert lab.truncation[0] == pytest.approx(0.5, abs=0.02)
    assert lab.occlusion[0] == 0.0
    expected = analytic_bbox(actors.boxes.corners()[0])
    np.testing.assert_allclose(lab.box_amodal[0], expected, atol=1e-6)
    np.testing.assert_allclose(lab.box_amodal_clipped[0], np.clip(expected, 0, [800, 600, 800, 600]), atol=1e-6)


def test_truncation_of_a_huge_object_uses_a_strided_virtual_plane(box_meshes, actors_factory):
    # Plate at x = 2, |y| <= 20, |z| <= 1: u in [-3600, 4400] (8000 px wide); 800 px of it are in the image.
    actors = actors_factory([[2.0, 0.0, 0.0]], [[0.002, 40.0, 2.0]])
    lab = render(actors, box_meshes).labels
    assert lab.truncation[0] == pytest.approx(0.9, abs=0.01)
    assert lab.visible_px[0] == lab.unoccluded_px[0] == 800 * 400


def test_depth_is_z_depth_and_images_agree(box_meshes, actors_factory, wall):
    actors = actors_factory([[8.0, 0.0, 0.0]], [[2.0, 2.0, 2.0]])  # on the axis: only its near face shows
    frame = render(actors, box_meshes, static=[wall(12.0)])
    assert frame.depth_valid.all()
    wall_px = frame.instance_id == 0
    np.testing.assert_allclose(frame.depth_m[wall_px], 12.0, rtol=1e-5)  # z-depth of a fronto-parallel wall
    np.testing.assert_allclose(frame.depth_m[~wall_px], 7.0, rtol=1e-5)  # the box's near face at x = 7
    assert set(np.unique(frame.semantic[~wall_px])) == {actors.object_class[0].semantic}
    assert frame.rgb.shape == (600, 800, 3) and frame.rgb.dtype == np.uint8


def test_distorted_camera_boxes_agree(box_meshes, actors_factory):
    actors = actors_factory([[12.0, 3.0, -0.5], [25.0, -4.0, 0.0]], [[4.0, 2.0, 1.5], [4.0, 2.0, 1.5]], yaws=[0.3, 1.0])
    lab = render(actors, box_meshes, distortion=(-0.12, 0.02, 0.001, -0.0015, -0.002)).labels
    assert lab.visible.all() and (lab.occlusion == 0).all() and (lab.truncation == 0).all()
    np.testing.assert_allclose(lab.box_tight, lab.box_amodal, atol=1.0)


def test_procedural_meshes_tight_within_amodal(actors_factory):
    from pipeline.core.classes import ObjectClass

    classes = list(ObjectClass)
    centers = [[10.0 + 6 * i, (-1) ** i * 2.0, -0.6] for i in range(len(classes))]
    actors = actors_factory(centers, [[4.5, 1.8, 1.5]] * len(classes), yaws=np.linspace(-3, 3, len(classes)),
                            classes=classes)
    scene = FrameScene(StaticScene([]), actors)
    lab = render_camera(scene, Camera(camera_config()), EGO).labels
    assert (lab.visible_px <= lab.unoccluded_px).all()
    vis = lab.visible & (lab.occlusion == 0)
    assert vis.any()
    np.testing.assert_allclose(lab.box_tight[vis], lab.box_amodal[vis], atol=1.0)


@pytest.mark.parametrize("spp", [1, 3])
def test_same_seed_same_output(box_meshes, actors_factory, wall, spp):
    actors = actors_factory([[15.0, 1.0, 0.0], [25.0, -2.0, 0.0]], [[4.0, 2.0, 1.5]] * 2)
    a = render(actors, box_meshes, static=[wall(40.0)], samples_per_pixel=spp, width_px=200, height_px=150)
    b = render(actors, box_meshes, static=[wall(40.0)], samples_per_pixel=spp, width_px=200, height_px=150)
    np.testing.assert_array_equal(a.rgb, b.rgb)
    np.testing.assert_array_equal(a.instance_id, b.instance_id)
    for field in ("box_tight", "visible_px", "unoccluded_px", "full_px", "occlusion", "truncation"):
        np.testing.assert_array_equal(getattr(a.labels, field), getattr(b.labels, field))


def test_actor_ray_mask_is_a_superset(actors_factory):
    rng = np.random.default_rng(5)
    n = 25
    from pipeline.core.classes import ObjectClass

    classes = [list(ObjectClass)[i % 7] for i in range(n)]
    actors = actors_factory(np.column_stack([rng.uniform(-5, 60, n), rng.uniform(-15, 15, n), rng.uniform(-2, 1, n)]),
                            rng.uniform(0.5, 10, (n, 3)), yaws=rng.uniform(-3, 3, n), classes=classes)
    scene = FrameScene(StaticScene([]), actors)
    cam = Camera(camera_config(width_px=160, height_px=120, hfov_deg=100))
    from pipeline.sensors.groundtruth import project_actors

    to_world = cam.camera_to_world(EGO)
    mask = project_actors(scene, cam, to_world).pixel_mask(160, 120)
    d = cam.pixel_directions @ to_world.rotation.T.astype(np.float32)
    full = scene.cast(np.zeros_like(d), d)
    assert not (full.instance_id[~mask] > 0).any()
    assert mask.mean() < 1.0


def test_boxes3d_world_round_trip(box_meshes, actors_factory):
    actors = actors_factory([[20.0, 1.0, -0.5]], [[4.0, 2.0, 1.5]], yaws=[0.35])
    lab = render(actors, box_meshes).labels
    cam_to_world = Camera(camera_config()).camera_to_world(EGO)
    back = Boxes3D(cam_to_world.apply(lab.center_cam), lab.size, [0.35])
    np.testing.assert_allclose(back.corners(), actors.boxes.corners(), atol=1e-9)


def test_empty_world_is_all_sky_and_has_no_labels():
    from pipeline.world.actors import Actors

    frame = render_camera(FrameScene(StaticScene([]), Actors.empty()), Camera(camera_config(width_px=40, height_px=30)),
                          EGO)
    assert len(frame.labels) == 0 and not frame.depth_valid.any() and not frame.instance_id.any()
    assert (frame.rgb[0, :, 2] > frame.rgb[0, :, 0]).all()  # blue sky


def test_pixel_counts_and_tight_boxes_of_an_id_image():
    from pipeline.sensors.groundtruth import _pixel_boxes

    image = np.zeros((6, 8), np.int32)
    image[1:3, 2:5] = 1  # a 2 x 3 block: box (2, 1, 5, 3)
    image[5, 7] = 3  # one corner pixel
    image[0, 0] = image[4, 6] = 3  # id 3 spans the image: box (0, 0, 8, 6)
    count, box = _pixel_boxes(image, 4)
    assert count.tolist() == [6, 0, 3, 0]
    np.testing.assert_array_equal(box[0], [2, 1, 5, 3])
    np.testing.assert_array_equal(box[2], [0, 0, 8, 6])
    assert np.isnan(box[[1, 3]]).all()
    with pytest.raises(ValueError, match="above k"):
        _pixel_boxes(image, 2)


def test_group_bounds_are_numpys_minimum_and_maximum_at():
    from pipeline.sensors.groundtruth import _group_bounds

    rng = np.random.default_rng(3)
    group = rng.integers(0, 6, 500)
    group[group == 4] = 5  # group 4 empty
    points = rng.normal(size=(500, 2)) * 100
    points[7] = [np.nan, 1.0]
    lo, hi = np.full((6, 2), np.inf), np.full((6, 2), -np.inf)
    np.minimum.at(lo, group, points)
    np.maximum.at(hi, group, points)
    got_lo, got_hi = _group_bounds(group.astype(np.int64), points, 6)
    np.testing.assert_array_equal(got_lo, lo)
    np.testing.assert_array_equal(got_hi, hi)
    assert np.isnan(got_lo[group[7], 0]) and np.isinf(got_lo[4]).all()


@pytest.mark.parametrize("distortion", [None, (-0.2, 0.05, 0.0, 0.0, 0.0)])
def test_amodal_boxes_from_hull_vertices_equal_those_from_all_vertices(distortion):
    """project_actors projects only each model's convex-hull vertices for actors wholly in front of the near plane:
    the same boxes, to the bit, as projecting every vertex (real body models, many poses, some crossing the near
    plane, some beside or behind the camera)."""
    from pipeline.core.classes import ObjectClass
    from pipeline.sensors.groundtruth import project_actors
    from pipeline.world.actors import Actors, actor_variants

    rng = np.random.default_rng(4)
    n = 120
    classes = [list(ObjectClass)[i] for i in rng.integers(0, 4, n)]  # car, van, truck, bus
    size = np.column_stack([rng.uniform(3.5, 16.0, n), rng.uniform(1.6, 2.6, n), rng.uniform(1.3, 4.0, n)])
    centre = np.column_stack([rng.uniform(-5.0, 60.0, n), rng.uniform(-30.0, 30.0, n), 0.5 * size[:, 2] - 1.2])
    actors = Actors(np.arange(1, n + 1), classes, Boxes3D(centre, size, rng.uniform(-np.pi, np.pi, n)),
                    rng.uniform(0, 1, (n, 3)), variant=actor_variants(np.arange(1, n + 1), 3))
    scene = FrameScene(StaticScene([]), actors)
    kwargs = {} if distortion is None else {"distortion": distortion, "hfov_deg": 70.0}
    camera = Camera(camera_config(**kwargs))
    cam_to_world = camera.camera_to_world(EGO)
    fast = project_actors(scene, camera, cam_to_world)
    assert scene.geometry.vertex_on_hull.mean() < 0.5  # the hulls leave most vertices out
    hull = scene.geometry.vertex_on_hull  # FrameScene's hull vertices are the placed mesh's on the hull, in order
    np.testing.assert_array_equal(scene.hull_vertices, scene.geometry.vertices[hull])
    np.testing.assert_array_equal(scene.hull_actor, scene.geometry.vertex_actor[hull])
    scene.hull_vertices, scene.hull_actor = scene.geometry.vertices, scene.geometry.vertex_actor  # every vertex
    every = project_actors(scene, camera, cam_to_world)
    assert fast.valid.sum() > 20 and (~fast.valid).sum() > 5  # boxes for some, none for others behind
    np.testing.assert_array_equal(fast.valid, every.valid)
    np.testing.assert_array_equal(fast.box, every.box)
