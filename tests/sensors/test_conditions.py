"""Conditions: night darker than morning, Koschmieder fog with the exact distance, seeded noise, registry."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera, CameraConfig
from pipeline.sensors.conditions import CONDITIONS, KOSCHMIEDER, Condition, get_condition
from pipeline.sensors.lidar import LidarConfig
from pipeline.sensors.render import render_camera
from pipeline.sensors.shading import Lighting
from pipeline.world.scene import FrameScene, StaticScene

SMALL = dict(width_px=160, height_px=120)


def _scene(actors_factory, wall):
    actors = actors_factory([[15.0, 1.0, -0.5], [30.0, -3.0, -0.5]], [[4.5, 1.8, 1.5]] * 2, brake=[True, False])
    return FrameScene(StaticScene([wall(60.0)]), actors)


def test_night_is_darker_than_morning(actors_factory, wall):
    scene = _scene(actors_factory, wall)
    cam = Camera(CameraConfig(**SMALL))
    morning = render_camera(scene, cam, Transform.identity(), get_condition("morning")).rgb.mean()
    night = render_camera(scene, cam, Transform.identity(), get_condition("night")).rgb.mean()
    assert night < 0.5 * morning


def test_fog_follows_koschmieder():
    cond = Condition("test", Lighting(), fog_visibility_m=100.0, fog_rgb=(0.5, 0.5, 0.5))
    radiance = np.array([[1.0, 0.0, 0.2]] * 3, np.float32)
    out = cond.fog(radiance, np.array([0.0, 100.0, np.inf], np.float32), np.array([True, True, False]))
    np.testing.assert_allclose(out[0], radiance[0])
    t = np.exp(-KOSCHMIEDER)  # 2 % contrast left at the visibility distance
    np.testing.assert_allclose(out[1], radiance[1] * t + 0.5 * (1 - t), rtol=1e-6)
    np.testing.assert_allclose(out[2], [0.5, 0.5, 0.5])  # the sky is all fog


def test_fog_lowers_contrast_with_distance(box_meshes, actors_factory, wall):
    # The same dark box at 10 m and at 60 m in front of a bright wall: fog shrinks the far one's contrast.
    cam = Camera(CameraConfig(**SMALL))
    contrast = []
    for x in (10.0, 60.0):
        scene = FrameScene(StaticScene([wall(x + 2.0, material="lane_paint")]),
                           actors_factory([[x, 0.0, 0.0]], [[1.0, 0.3 * x / 10, 0.3 * x / 10]], colors=[[0.02] * 3]),
                           box_meshes)
        frame = render_camera(scene, cam, Transform.identity(), get_condition("fog"))
        grey = frame.rgb.astype(float).mean(axis=2)
        contrast.append(grey[frame.instance_id == 0].mean() - grey[frame.instance_id == 1].mean())
    assert contrast[1] < 0.5 * contrast[0]


def test_same_seed_same_noisy_image(actors_factory, wall):
    scene = _scene(actors_factory, wall)
    cam = Camera(CameraConfig(**SMALL))
    night = get_condition("night")
    a = render_camera(scene, cam, Transform.identity(), night, np.random.default_rng(4)).rgb
    b = render_camera(scene, cam, Transform.identity(), night, np.random.default_rng(4)).rgb
    c = render_camera(scene, cam, Transform.identity(), night, np.random.default_rng(5)).rgb
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_registry_and_lidar_degradation():
    assert set(CONDITIONS) == {"morning", "noon", "dusk", "night", "fog", "rain"}
    with pytest.raises(KeyError, match="known: morning"):
        get_condition("snow")
    fog = get_condition("fog").lidar(LidarConfig())
    assert fog.range_max_m < LidarConfig().range_max_m and fog.attenuation_per_m > LidarConfig().attenuation_per_m
    with pytest.raises(ValueError):
        Condition("bad", Lighting(), fog_visibility_m=0.0)
