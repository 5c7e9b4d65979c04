"""Camera model: intrinsics, frames, distortion round trip and agreement with OpenCV's projection."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from tests.sensors.conftest import camera_config

DISTORTION = (-0.12, 0.02, 0.001, -0.0015, -0.002)


def test_intrinsics_from_hfov():
    cam = Camera(camera_config(width_px=800, height_px=600, hfov_deg=90.0))
    assert cam.fx == pytest.approx(400.0) and cam.fy == pytest.approx(400.0)
    assert (cam.cx, cam.cy) == (400.0, 300.0)
    explicit = Camera(camera_config(hfov_deg=None, K=((500.0, 0.0, 401.0), (0.0, 510.0, 299.0), (0.0, 0.0, 1.0))))
    np.testing.assert_allclose(explicit.K, [[500, 0, 401], [0, 510, 299], [0, 0, 1]])


@pytest.mark.parametrize(
    "kwargs",
    [dict(width_px=0), dict(hfov_deg=180.0), dict(distortion=(0.1, 0.2)), dict(samples_per_pixel=0),
     dict(hfov_deg=None, K=((0.0, 0.0, 2.0), (0.0, 1.0, 3.0), (0.0, 0.0, 1.0)))],
)
def test_bad_config_raises(kwargs):
    with pytest.raises(ValueError):
        camera_config(**kwargs)


def test_pixel_centre_rays():
    cam = Camera(camera_config(width_px=16, height_px=16, hfov_deg=90.0))
    d = cam.pixel_directions.reshape(16, 16, 3)
    # pixel (col 8, row 8) has its centre at (8.5, 8.5): x = 0.5 / fx, y = 0.5 / fy in the optical frame.
    expected = np.array([0.5 / cam.fx, 0.5 / cam.fy, 1.0])
    np.testing.assert_allclose(d[8, 8], expected / np.linalg.norm(expected), atol=1e-7)


@pytest.mark.parametrize("config", [camera_config(), camera_config(width_px=37, height_px=23, hfov_deg=70.0),
                                    camera_config(width_px=64, height_px=48, hfov_deg=None,
                                                  K=((50.5, 0.0, 30.25), (0.0, 61.0, 25.0), (0.0, 0.0, 1.0)))])
def test_pixel_directions_without_distortion_are_unprojects_bytes(config):
    """Without distortion pixel_directions takes a compiled path of its own: the same bytes as unproject."""
    cam = Camera(config)
    rows, cols = np.divmod(np.arange(cam.width * cam.height), cam.width)
    dirs, ok = cam.unproject(cam.pixel_uv(cols, rows))
    assert ok.all()
    np.testing.assert_array_equal(cam.pixel_directions, dirs.astype(np.float32))


def test_camera_to_world_looks_along_ego_x():
    cam = Camera(camera_config(mount={"xyz_m": (1.0, 0.0, 1.5)}))
    pose = cam.camera_to_world(Transform.from_xyz_rpy((10.0, 5.0, 0.0), (0.0, 0.0, np.pi / 2)))
    np.testing.assert_allclose(pose.translation, [10.0, 6.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(pose.apply_vectors([0.0, 0.0, 1.0]), [0.0, 1.0, 0.0], atol=1e-12)  # optical z = heading
    np.testing.assert_allclose(pose.apply_vectors([1.0, 0.0, 0.0]), [1.0, 0.0, 0.0], atol=1e-12)  # x right = -left
    np.testing.assert_allclose(pose.apply_vectors([0.0, 1.0, 0.0]), [0.0, 0.0, -1.0], atol=1e-12)  # y down


def test_distortion_round_trip():
    cam = Camera(camera_config(distortion=DISTORTION))
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], [800, 600], size=(5000, 2))
    dirs, invertible = cam.unproject(uv)
    back, in_front = cam.project(dirs)
    assert invertible.all() and in_front.all()
    np.testing.assert_allclose(back, uv, atol=1e-6)


def test_projection_matches_opencv():
    cam = Camera(camera_config(distortion=DISTORTION))
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(-4, 4, 500), rng.uniform(-3, 3, 500), rng.uniform(5, 30, 500)])
    ours, _ = cam.project(pts)
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, np.array(DISTORTION))
    np.testing.assert_allclose(ours, ref.reshape(-1, 2), atol=1e-6)


def test_points_behind_are_masked():
    cam = Camera(camera_config())
    _, in_front = cam.project(np.array([[0.0, 0.0, 5.0], [0.0, 0.0, -5.0], [1.0, 0.0, 0.0]]))
    assert in_front.tolist() == [True, False, False]


def test_samples_are_stratified_inside_their_pixel_and_seeded():
    cfg = camera_config(width_px=16, height_px=16, samples_per_pixel=4, distortion=DISTORTION, name="cam3")
    cam = Camera(cfg)
    s = cam.sample_directions
    assert s.shape == (4, 16 * 16, 3)
    rows, cols = np.divmod(np.arange(16 * 16), 16)
    for k in range(4):
        uv, _ = cam.project(s[k].astype(np.float64))
        assert np.all((uv[:, 0] >= cols - 1e-4) & (uv[:, 0] < cols + 1 + 1e-4))
        assert np.all((uv[:, 1] >= rows - 1e-4) & (uv[:, 1] < rows + 1 + 1e-4))
    u_strata = np.stack([np.floor((cam.project(s[k].astype(np.float64))[0][:, 0] - cols) * 4) for k in range(4)])
    assert np.all(np.sort(u_strata, axis=0) == np.arange(4)[:, None])  # one sample per column stratum
    np.testing.assert_array_equal(s, Camera(cfg).sample_directions)


@pytest.mark.parametrize("samples", [2, 4, 5])
def test_pinhole_samples_equal_the_lens_models_arithmetic(samples):
    """A lens without distortion takes its anti-aliasing samples from one compiled pass: the same bytes as the
    general path (the random draws in their order, argsort per pixel, unproject) gives with zero distortion, which
    its Newton iterations leave unchanged."""
    cfg = camera_config(width_px=40, height_px=30, samples_per_pixel=samples, name="cam4")
    compiled = Camera(cfg)
    general = Camera(cfg)
    general.has_distortion = True  # zero coefficients: the general path's arithmetic, unchanged by its iterations
    assert not compiled.has_distortion
    assert compiled.sample_directions.tobytes() == general.sample_directions.tobytes()


def test_distortion_beyond_its_fold_is_refused():
    cam = Camera(camera_config(hfov_deg=100.0, distortion=(-0.28, 0.09, 0.0, 0.0, -0.012)))
    _, invertible = cam.unproject(np.array([[400.0, 300.0], [0.0, 0.0]]))
    assert invertible.tolist() == [True, False]
    with pytest.raises(ValueError, match="cannot be inverted"):
        _ = cam.pixel_directions


def _box_hits(cam: Camera, cam_to_world: Transform, lo, hi) -> np.ndarray:
    """(H*W,) bool: pixel-centre rays that hit the box [lo, hi] (world), cast with Embree."""
    from pipeline.core.classes import SemanticClass
    from pipeline.world.actor_shapes import cuboid
    from pipeline.world.mesh import Mesh
    from pipeline.world.scene import StaticScene, make_rays

    scene = StaticScene([Mesh(*cuboid(tuple(lo), tuple(hi), "concrete"), semantic=SemanticClass.BUILDING)])
    rays = make_rays(cam_to_world.translation, cam.pixel_directions, cam_to_world.rotation)
    return np.isfinite(scene.cast(rays)[0])


def test_boxes_pixel_mask_of_a_box_in_front_is_its_projected_rectangle():
    cam = Camera(camera_config(width_px=800, height_px=600, hfov_deg=90.0))  # fx = fy = 400, centre (400, 300)
    optical = Transform.identity()  # the optical frame is the world: x right, y down, z forward
    mask = cam.boxes_pixel_mask(optical, [[-1.0, -0.5, 4.0]], [[1.0, 0.5, 6.0]]).reshape(600, 800)
    # The nearest face spans x/z in [-1/4, 1/4], y/z in [-1/8, 1/8]: columns [300, 500], rows [250, 350],
    # grown by the one-pixel margin.
    expected = np.zeros((600, 800), bool)
    expected[249:351, 299:501] = True
    np.testing.assert_array_equal(mask, expected)
    assert _box_hits(cam, optical, [-1.0, -0.5, 4.0], [1.0, 0.5, 6.0]).reshape(600, 800)[expected].mean() > 0.95


@pytest.mark.parametrize("distortion", [(0.0,) * 5, DISTORTION])
@pytest.mark.parametrize("box", [
    ((-30.0, -40.0, -0.05), (30.0, 40.0, 0.0)),  # ground under and behind the camera, across the image plane
    ((8.0, 1.5, 0.0), (9.0, 2.5, 12.0)),  # a tall pole ahead and to the left
    ((0.02, -0.3, 0.5), (0.03, 0.3, 1.0)),  # a sheet 2 cm in front of the lens: nearer than the near plane
    ((-5.0, -5.0, -1.0), (5.0, 5.0, 5.0)),  # around the camera: every ray
])
def test_boxes_pixel_mask_covers_every_ray_through_a_box(distortion, box):
    cam = Camera(camera_config(width_px=160, height_px=120, distortion=distortion))
    cam_to_world = cam.camera_to_world(Transform.from_xyz_rpy((0.0, 0.0, 0.75), (0.0, 0.05, 0.1)))
    lo, hi = np.array([box[0]]), np.array([box[1]])
    hits = _box_hits(cam, cam_to_world, lo[0], hi[0])
    mask = cam.boxes_pixel_mask(cam_to_world, lo, hi)
    assert hits.any()
    assert not (hits & ~mask).any(), f"{np.count_nonzero(hits & ~mask)} rays hit the box outside the mask"


def test_boxes_pixel_mask_is_empty_behind_the_camera_and_full_around_it():
    cam = Camera(camera_config(width_px=80, height_px=60))
    optical = Transform.identity()
    assert not cam.boxes_pixel_mask(optical, [[-1.0, -1.0, -6.0]], [[1.0, 1.0, -4.0]]).any()
    assert not cam.boxes_pixel_mask(optical, np.zeros((0, 3)), np.zeros((0, 3))).any()
    assert cam.boxes_pixel_mask(optical, [[-1.0, -1.0, -1.0]], [[1.0, 1.0, 1.0]]).all()
