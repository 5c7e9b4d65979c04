"""Anti-aliasing: samples go to edge pixels only (pipeline.sensors.render.edge_pixels), found in closed-form scenes."""

from __future__ import annotations

import cv2
import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.render import edge_pixels, render_camera, window_contrast
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene, make_rays
from tests.sensors.conftest import camera_config

EGO = Transform.identity()  # the camera looks along +x from the origin


def ground(z_m: float = -1.5, half_m: float = 2000.0) -> Mesh:
    v = np.array([[-half_m, -half_m, z_m], [half_m, -half_m, z_m], [half_m, half_m, z_m], [-half_m, half_m, z_m]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material_index("asphalt"), SemanticClass.ROAD)


def centre_hits(scene: FrameScene, camera: Camera):
    to_world = camera.camera_to_world(EGO)
    hits = scene.cast_rays(make_rays(to_world.translation, camera.pixel_directions, to_world.rotation))
    depth = np.where(hits.hit, hits.t_m * camera.pixel_directions[:, 2], 0.0).reshape(camera.height, camera.width)
    return hits, depth.astype(np.float32)


def test_a_plane_at_any_slant_has_edges_only_at_its_horizon(actors_factory):
    """Depth along a road seen at a grazing angle changes fast, but 1/z is affine on a plane: no edge there."""
    camera = Camera(camera_config(width_px=200, height_px=150))
    scene = FrameScene(StaticScene([ground()]), actors_factory(np.zeros((0, 3)), np.zeros((0, 3))))
    hits, depth = centre_hits(scene, camera)
    hit = hits.hit.reshape(camera.height, camera.width)
    horizon = np.flatnonzero(hit.any(axis=1))[0]  # first image row that sees the ground
    edge = edge_pixels(hits, depth)
    rows = np.flatnonzero(edge.any(axis=1))
    assert rows.min() >= horizon - 2 and rows.max() <= horizon + 2  # the sky/ground boundary, grown by 1 px
    assert edge[horizon].all()


def test_edges_cover_a_box_silhouette_and_little_else(box_meshes, actors_factory, wall):
    camera = Camera(camera_config(width_px=200, height_px=150))
    actors = actors_factory([[15.0, 1.0, 0.0]], [[4.0, 2.0, 1.5]], yaws=[0.35])
    scene = FrameScene(StaticScene([wall(40.0)]), actors, box_meshes)
    hits, depth = centre_hits(scene, camera)
    edge = edge_pixels(hits, depth)
    ids = hits.instance_id.reshape(camera.height, camera.width)
    silhouette = np.zeros_like(edge)
    silhouette[:-1] |= ids[:-1] != ids[1:]
    silhouette[1:] |= ids[:-1] != ids[1:]
    silhouette[:, :-1] |= ids[:, :-1] != ids[:, 1:]
    silhouette[:, 1:] |= ids[:, :-1] != ids[:, 1:]
    assert silhouette.any() and edge[silhouette].all()
    # besides the silhouette only the crease between the two visible faces (grown by a pixel): a thin set
    assert edge.sum() < 0.25 * (ids == 1).sum() + 3 * silhouette.sum()
    near_box = cv2.dilate((ids == 1).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert not edge[~near_box].any()  # the plain wall: no edge farther than 2 px from the box


def test_extra_samples_change_only_edge_pixels(box_meshes, actors_factory, wall):
    """With N samples the colour of a non-edge pixel is its centre sample's, byte for byte; labels never change."""
    actors = actors_factory([[15.0, 1.0, 0.0]], [[4.0, 2.0, 1.5]], yaws=[0.35])
    scene = FrameScene(StaticScene([wall(40.0)]), actors, box_meshes)
    one = render_camera(scene, Camera(camera_config(width_px=200, height_px=150)), EGO)
    four_camera = Camera(camera_config(width_px=200, height_px=150, samples_per_pixel=4))
    four = render_camera(scene, four_camera, EGO)
    edge = edge_pixels(*centre_hits(scene, four_camera))
    changed = (one.rgb != four.rgb).any(axis=2)
    assert changed.any() and not changed[~edge].any()
    np.testing.assert_array_equal(one.instance_id, four.instance_id)
    np.testing.assert_array_equal(one.labels.box_tight, four.labels.box_tight)
    everywhere = render_camera(scene, Camera(camera_config(width_px=200, height_px=150, samples_per_pixel=4,
                                                          samples_everywhere=True)), EGO)
    # The same samples where both take them: every pixel they change (edges that show, AA_MIN_CONTRAST).
    np.testing.assert_array_equal(everywhere.rgb[changed], four.rgb[changed])


def test_window_contrast_is_the_widest_3x3_spread_of_any_channel():
    image = np.zeros((5, 6, 3), np.uint8)
    image[2, 3] = (10, 200, 7)
    image[0, 0, 2] = 3
    spread = window_contrast(image)
    expected = np.zeros((5, 6), np.uint8)
    expected[1:4, 2:5] = 200  # the bright pixel's 3x3 neighbourhood, green
    expected[0:2, 0:2] = 3  # the corner's window is clipped to the image
    np.testing.assert_array_equal(spread, expected)


def test_the_rig_file_sets_the_sampling():
    from pipeline.core.config import RigConfig, load_config
    from pipeline.stages.rig import build_sensors

    rig, _ = load_config(RigConfig, "default", "rigs")
    camera = build_sensors(rig)[0][0].config
    assert (camera.samples_per_pixel, camera.samples_everywhere, camera.quality) == (4, False, "realistic")
    assert camera.psf_sigma_px == 0.65
    spec = rig.cameras[0].model_copy(update={"samples_per_pixel": 2, "samples_everywhere": True, "quality": "fast"})
    camera = build_sensors(rig.model_copy(update={"cameras": [spec]}))[0][0].config
    assert (camera.samples_per_pixel, camera.samples_everywhere, camera.quality) == (2, True, "fast")
