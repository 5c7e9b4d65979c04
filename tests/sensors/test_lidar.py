"""LiDAR: ranges to known walls, the intensity law, object ids inside their boxes, agreement with the camera."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.lidar import Lidar, render_lidar
from pipeline.sensors.render import render_camera
from pipeline.world.materials import material_arrays, material_index
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import camera_config, lidar_config

EGO = Transform.identity()
EXACT = dict(range_noise_std_m=0.0, dropout=0.0)


def sweep(scene, seed=0, **cfg):
    return render_lidar(scene, Lidar(lidar_config(**{**EXACT, **cfg})), EGO, np.random.default_rng(seed))


def test_ray_pattern():
    lidar = Lidar(lidar_config(channels=4, upper_fov_deg=10.0, lower_fov_deg=-20.0, horizontal_resolution_deg=10.0))
    d = lidar.directions.reshape(36, 4, 3)  # (column, ring)
    np.testing.assert_allclose(np.degrees(np.arcsin(d[0, :, 2])), [10.0, 0.0, -10.0, -20.0], atol=1e-5)
    az = np.degrees(np.arctan2(d[::9, 0, 1], d[::9, 0, 0]))
    np.testing.assert_allclose(az, [180.0, 90.0, 0.0, -90.0], atol=1e-5)  # clockwise from behind
    with pytest.raises(ValueError):
        lidar_config(horizontal_resolution_deg=0.7)
    with pytest.raises(ValueError):
        lidar_config(dropout=1.0)


def test_range_to_a_wall_at_a_known_distance(wall):
    scene = FrameScene(StaticScene([wall(25.0)]), _no_actors())
    s = sweep(scene, range_m=200.0)
    assert len(s) > 1000
    np.testing.assert_allclose(s.points_m[:, 0], 25.0, atol=1e-3)  # every point lies on the wall
    assert (s.points_m[:, 0] > 0).all() and (s.instance_id == 0).all()


def test_intensity_follows_exp_minus_a_d(wall):
    a = 0.01
    scene = FrameScene(StaticScene([wall(30.0, material="barrier")]), _no_actors())
    s = sweep(scene, attenuation_per_m=a)
    d = np.linalg.norm(s.points_m, axis=1)
    cos_inc = s.points_m[:, 0] / d  # the wall's normal is -x
    i0 = material_arrays()["reflectivity"][material_index("barrier")] * cos_inc
    np.testing.assert_allclose(s.intensity, i0 * np.exp(-a * d), rtol=1e-4)
    # Two walls, same incidence: the ratio of intensities is exp(-a * (d2 - d1)).
    far = sweep(FrameScene(StaticScene([wall(60.0, material="barrier")]), _no_actors()), attenuation_per_m=a)
    assert far.intensity[far.ring == 40].max() / s.intensity[s.ring == 40].max() == pytest.approx(
        np.exp(-a * 30.0 / np.cos(np.radians(s_elev(40)))), rel=1e-3)


def s_elev(ring: int) -> float:
    cfg = lidar_config()
    return np.linspace(cfg.upper_fov_deg, cfg.lower_fov_deg, cfg.channels)[ring]


def test_object_points_lie_in_their_box_and_project_into_their_tight_box(box_meshes, actors_factory, wall):
    actors = actors_factory([[12.0, 2.0, -0.8], [25.0, -3.0, -0.6], [40.0, 4.0, 0.0]],
                            [[4.5, 1.8, 1.5], [8.0, 2.5, 3.0], [12.0, 2.5, 3.2]], yaws=[0.2, -0.4, 3.0])
    scene = FrameScene(StaticScene([wall(80.0)]), actors, box_meshes)
    lidar = Lidar(lidar_config(mount={"xyz_m": (0.3, 0.0, 0.4)}, **EXACT))
    s = render_lidar(scene, lidar, EGO, np.random.default_rng(0))
    world = lidar.lidar_to_world(EGO).apply(s.points_m)
    inside = actors.boxes.contains(world, margin_m=1e-3)  # (K, M)
    for k, tid in enumerate(actors.track_id):
        mine = s.instance_id == tid
        assert mine.sum() == s.points_per_actor[k] > 20
        assert inside[k, mine].all()
        assert not inside[k, s.instance_id == 0].any()
    frame = render_camera(scene, Camera(camera_config()), EGO)
    cam_to_world = frame.cam_to_world
    for row, tid in enumerate(frame.labels.track_id):
        uv, in_front = Camera(camera_config()).project(cam_to_world.inverse().apply(world[s.instance_id == tid]))
        x1, y1, x2, y2 = frame.labels.box_tight[row]
        on_image = in_front & (uv[:, 0] >= 0) & (uv[:, 0] < 800) & (uv[:, 1] >= 0) & (uv[:, 1] < 600)
        assert on_image.any()
        u, v = uv[on_image].T
        assert ((u >= x1 - 1) & (u <= x2 + 1) & (v >= y1 - 1) & (v <= y2 + 1)).all()


def test_same_seed_same_sweep_noise_and_dropout(wall):
    scene = FrameScene(StaticScene([wall(20.0)]), _no_actors())
    cfg = dict(range_noise_std_m=0.05, dropout=0.1)
    a, b, c = sweep(scene, 1, **cfg), sweep(scene, 1, **cfg), sweep(scene, 2, **cfg)
    np.testing.assert_array_equal(a.points_m, b.points_m)
    np.testing.assert_array_equal(a.intensity, b.intensity)
    assert len(a) != len(c) or not np.array_equal(a.points_m, c.points_m)
    exact = sweep(scene)
    assert len(a) / len(exact) == pytest.approx(0.9, abs=0.02)
    assert np.std(a.points_m[:, 0] - 20.0) == pytest.approx(0.05 * np.mean(a.points_m[:, 0] / np.linalg.norm(
        a.points_m, axis=1)), rel=0.1)


def test_actor_ray_mask_is_a_superset(actors_factory):
    rng = np.random.default_rng(3)
    n = 30
    r, phi = rng.uniform(12, 40, n), rng.uniform(-np.pi, np.pi, n)
    actors = actors_factory(np.column_stack([r * np.cos(phi), r * np.sin(phi), rng.uniform(-2, 2, n)]),
                            rng.uniform(0.5, 12, (n, 3)), yaws=rng.uniform(-3, 3, n))
    scene = FrameScene(StaticScene([]), actors)
    lidar = Lidar(lidar_config(horizontal_resolution_deg=0.5,
                               mount={"xyz_m": (0, 0, 1.0), "rpy_rad": (0.05, -0.1, 0.3)}))
    to_world = lidar.lidar_to_world(EGO)
    mask = lidar.actor_ray_mask(scene, to_world)
    d = lidar.directions @ to_world.rotation.T.astype(np.float32)
    full = scene.cast(np.broadcast_to(to_world.translation.astype(np.float32), d.shape), d)
    assert not (full.instance_id[~mask] > 0).any()
    assert mask.mean() < 0.9


def _no_actors():
    from pipeline.world.actors import Actors

    return Actors.empty()


def test_returns_and_points_of_hand_made_beams():
    from pipeline.sensors.lidar import _points, _returns

    # 6 beams, 2 rings x 3 columns (column-major): a hit head-on at 10 m; a miss; a hit too near; a dropped hit;
    # a hit at 60 deg incidence on an actor; a hit beyond the range.
    d = np.float32([[1, 0, 0]] * 6)
    rays = np.concatenate([np.zeros((6, 3), np.float32), d], axis=1)
    hit = np.array([True, False, True, True, True, True])
    t = np.float32([10.0, np.inf, 0.1, 20.0, 30.0, 500.0])
    c60 = np.cos(np.radians(60.0))
    normal = np.float32([[-1, 0, 0], [0, 0, 0], [-1, 0, 0], [-1, 0, 0], [-c60, np.sin(np.radians(60.0)), 0],
                         [-1, 0, 0]])
    material = np.int32([0, 0, 0, 0, 1, 0])
    keep, t_kept, reflected = _returns(hit, t, normal, rays, material, np.float32([0.5, 0.8]),
                                       np.array([False, False, False, True, False, False]), np.float32(0.5),
                                       np.float32(120.0))
    assert keep.tolist() == [0, 4]
    np.testing.assert_allclose(t_kept, [10.0, 30.0])
    np.testing.assert_allclose(reflected, [0.5, 0.8 * c60], rtol=1e-6)
    noise = np.float32([0.25, 0, 0, 0, -31.0, 0])  # the second return's noisy range clamps at 0
    points, ring, column, time_s, instance, semantic, per_actor = _points(
        keep, t_kept, noise, d, np.int32([0, 0, 0, 0, 7, 0]), np.uint8([1, 0, 0, 0, 13, 0]),
        np.int32([0, 0, 0, 0, 2, 0]), 2, 30.0, 3)
    np.testing.assert_allclose(points, [[10.25, 0, 0], [0, 0, 0]])
    assert ring.tolist() == [0, 0] and column.tolist() == [0, 2]
    np.testing.assert_allclose(time_s, [0.0, 2 / 30.0])
    assert instance.tolist() == [0, 7] and semantic.tolist() == [1, 13] and per_actor.tolist() == [0, 0, 1]
