"""Procedural textures: anchored to the world, band-limited by the pixel footprint, only on the static world."""

import numpy as np
import pytest

from pipeline.sensors.textures import TEXTURE_OF_MATERIAL, _lattice, noise2, noise3, textured_albedo
from pipeline.world.materials import material_arrays, material_index


def _ground_hits(points_xy: np.ndarray, height_m: float, material: str, instance: int = 0):
    """Rays straight down from ``height_m`` onto the ground points (N, 2): (rays, t, hit, instance, material,
    normal, colour) for :func:`textured_albedo`."""
    n = len(points_xy)
    rays = np.zeros((n, 6), np.float32)
    rays[:, :2], rays[:, 2], rays[:, 5] = points_xy, height_m, -1.0
    normal = np.zeros((n, 3), np.float32)
    normal[:, 2] = 1.0
    colour = np.tile(material_arrays()["albedo"][material_index(material)], (n, 1)).astype(np.float32)
    return (rays, np.full(n, height_m, np.float32), np.ones(n, bool), np.full(n, instance, np.int32),
            np.full(n, material_index(material), np.int32), normal, colour)


def _grid(n: int = 120, size_m: float = 30.0) -> np.ndarray:
    xs = np.linspace(3.0, 3.0 + size_m, n)
    x, y = np.meshgrid(xs, xs - 11.0)
    return np.column_stack([x.ravel(), y.ravel()])


def test_value_noise_interpolates_its_lattice_and_stays_in_range():
    for ix, iy in ((0, 0), (3, -7), (-12, 40)):
        assert noise2(float(ix), float(iy), 5) == _lattice(ix, iy, 0, 5)
        assert noise3(float(ix), float(iy), 2.0, 5) == _lattice(ix, iy, 2, 5)
    rng = np.random.default_rng(0)
    values = [noise2(x, y, 1) for x, y in rng.uniform(-100, 100, (2000, 2))]
    assert -1.0 <= min(values) < -0.5 and 0.5 < max(values) <= 1.0
    # continuous: a step of 1 mm changes the value by at most the lattice's slope bound (1.5 x 2 per cell) x 1 mm
    assert abs(noise2(10.3, 4.7, 1) - noise2(10.301, 4.7, 1)) <= 3.0 * 0.001


def test_texture_is_anchored_to_the_world_not_the_camera():
    """The same ground point seen from two heights with the same footprint gets the same albedo: the pattern lies
    on the road, not on the image."""
    pts = _grid(60)
    low = textured_albedo(*_ground_hits(pts, 5.0, "asphalt"), pixel_angle_rad=0.004)
    high = textured_albedo(*_ground_hits(pts, 20.0, "asphalt"), pixel_angle_rad=0.001)
    np.testing.assert_array_equal(low, high)
    assert low.std() > 0.005  # and there is a pattern


def test_finer_octaves_fade_with_the_footprint():
    """Seen from far (a large footprint) the asphalt keeps only its broad blotches: less variation pixel to pixel
    than seen from near; the far texture changes slowly (neighbouring samples 25 cm apart barely differ)."""
    pts = _grid(200, 50.0)
    near = textured_albedo(*_ground_hits(pts, 10.0, "asphalt"), pixel_angle_rad=0.0005)[:, 0].reshape(200, 200)
    far = textured_albedo(*_ground_hits(pts, 10.0, "asphalt"), pixel_angle_rad=0.2)[:, 0].reshape(200, 200)
    step_near = np.abs(np.diff(near, axis=1)).mean()
    step_far = np.abs(np.diff(far, axis=1)).mean()
    assert step_far < 0.25 * step_near


def test_actors_and_flat_materials_keep_their_colour():
    pts = _grid(30)
    for material in ("paint", "glass", "metal", "rubber"):
        assert material not in TEXTURE_OF_MATERIAL
        args = _ground_hits(pts, 10.0, material)
        np.testing.assert_array_equal(textured_albedo(*args, pixel_angle_rad=0.001), args[-1])
    args = _ground_hits(pts, 10.0, "asphalt", instance=7)  # an actor's asphalt-coloured part stays as it is
    np.testing.assert_array_equal(textured_albedo(*args, pixel_angle_rad=0.001), args[-1])
    args = _ground_hits(pts, 10.0, "asphalt")
    args[2][:] = False  # misses are left alone
    np.testing.assert_array_equal(textured_albedo(*args, pixel_angle_rad=0.001), args[-1])


def test_worn_markings_blend_towards_the_asphalt():
    """A worn marking is paint partly worn through to asphalt, both times a dirt factor in [0.8, 1]: every channel
    lies between 0.8 x asphalt and the paint; some of it is worn, most of it still reads as paint."""
    args = _ground_hits(_grid(100, 20.0), 10.0, "lane_paint")
    out = textured_albedo(*args, pixel_angle_rad=0.0005)
    paint = material_arrays()["albedo"][material_index("lane_paint")]
    asphalt = material_arrays()["albedo"][material_index("asphalt")]
    assert np.all(out >= 0.8 * asphalt - 1e-6) and np.all(out <= paint + 1e-6)
    share_worn = np.mean(out[:, 0] < 0.5 * paint[0])
    assert 0.01 < share_worn < 0.4


def test_bad_pixel_angle_is_refused():
    with pytest.raises(ValueError, match="pixel_angle_rad"):
        textured_albedo(*_ground_hits(_grid(4), 10.0, "asphalt"), pixel_angle_rad=0.0)


def _wall_hits(points_yz: np.ndarray, distance_m: float, material: str):
    """Rays along +x onto a wall x = 0 facing -x at (y, z) points (N, 2): the arguments of :func:`textured_albedo`."""
    n = len(points_yz)
    rays = np.zeros((n, 6), np.float32)
    rays[:, 0], rays[:, 1:3], rays[:, 3] = -distance_m, points_yz, 1.0
    normal = np.tile(np.float32([-1.0, 0.0, 0.0]), (n, 1))
    colour = np.tile(material_arrays()["albedo"][material_index(material)], (n, 1)).astype(np.float32)
    return (rays, np.full(n, distance_m, np.float32), np.ones(n, bool), np.zeros(n, np.int32),
            np.full(n, material_index(material), np.int32), normal, colour)


def test_brick_courses_and_their_mean_from_afar():
    """Near, a brick wall is bricks (each its own shade) and mortar joints in their share of the wall; from afar, where
    a pixel spans many courses, it is the two blended in that share, uniformly."""
    from pipeline.sensors.textures import BRICK_COURSE_M, BRICK_LENGTH_M, JOINT_M, MORTAR_RGB

    rng = np.random.default_rng(0)
    pts = rng.uniform([0.0, 1.0], [4.0, 5.0], (4000, 2))
    brick = material_arrays()["albedo"][material_index("brick")]
    share = JOINT_M / BRICK_COURSE_M + JOINT_M / BRICK_LENGTH_M - JOINT_M**2 / (BRICK_COURSE_M * BRICK_LENGTH_M)
    far = textured_albedo(*_wall_hits(pts, 10.0, "brick"), pixel_angle_rad=1.0)  # a 10 m footprint
    np.testing.assert_allclose(far, np.tile((1 - share) * brick + share * MORTAR_RGB, (len(pts), 1)), rtol=1e-5)
    near = textured_albedo(*_wall_hits(pts, 2.0, "brick"), pixel_angle_rad=0.0005)  # 1 mm
    mortar = np.abs(near[:, 1] / near[:, 0] - MORTAR_RGB[1] / MORTAR_RGB[0]) < 0.05
    assert abs(mortar.mean() - share) < 0.03
    shades = near[~mortar, 0] / brick[0]  # each brick's shade (1 +- 0.14) times the stains (1 +- 0.13)
    assert shades.std() > 0.04 and shades.min() > 0.86 * 0.87 and shades.max() < 1.14 * 1.13


def test_window_glass_shows_rooms_behind_it():
    """Glass varies (furniture and shade behind it) about its albedo, within [0.35, 2.2] times it."""
    pts = np.random.default_rng(1).uniform([0.0, 1.0], [20.0, 20.0], (3000, 2))
    for name in ("building_glass", "window_lit", "glass_tinted"):
        out = textured_albedo(*_wall_hits(pts, 10.0, name), pixel_angle_rad=0.001)[:, 0]
        base = material_arrays()["albedo"][material_index(name)][0]
        assert out.std() > 0.15 * base and 0.35 * base - 1e-6 <= out.min() and out.max() <= 2.2 * base + 1e-6
