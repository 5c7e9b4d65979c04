"""Conditions: shipped YAML configs, validation errors, Koschmieder fog with the exact distance, rain, LiDAR."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.core.classes import SemanticClass
from pipeline.core.config import ConditionConfig, ConfigError, config_dir, load_config
from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import KOSCHMIEDER, SHIPPED, Condition, get_condition
from pipeline.sensors.lidar import Lidar, render_lidar
from pipeline.sensors.render import render_camera
from pipeline.sensors.shading import shade
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene, make_rays
from tests.sensors.conftest import camera_config, condition, lidar_config

SMALL = dict(width_px=160, height_px=120)


def ground(material: str = "asphalt", half_m: float = 200.0) -> Mesh:
    """A flat square at z = 0 facing up."""
    h = half_m
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material_index(material), SemanticClass.ROAD)


def test_every_shipped_yaml_validates():
    files = sorted((config_dir() / "conditions").glob("*.yaml"))
    assert {f.stem for f in files} >= set(SHIPPED)
    for f in files:
        cfg, path = load_config(ConditionConfig, f.stem, "conditions")
        assert cfg.name == f.stem and path == f
        assert Condition(cfg).name == f.stem


def test_night_in_rain_is_the_nights_light_in_the_rains_weather():
    """night-rain takes every light, the sky and the lens from night.yaml and the rain and its mist from rain.yaml
    (so that a change to either reaches it, or this fails)."""
    night, rain, both = (get_condition(n).config for n in ("night", "rain", "night-rain"))
    for section in ("sun", "sky", "vehicle_lights", "headlights", "street_lamps", "lens"):
        assert getattr(both, section) == getattr(night, section), section
    for section in ("rain", "fog", "lidar"):
        assert getattr(both, section) == getattr(rain, section), section


@pytest.mark.parametrize(("body", "key"), [
    ("name: bad\nheadlights: {intensity: -1.0}\n", "headlights.intensity"),
    ("name: bad\nfog: {visibility: 50.0}\n", "fog.visibility"),
    ("name: bad\nlens: {vignetting: 1.5}\n", "lens.vignetting"),
    ("name: bad\nsky: {ambient_rgb: [0.1, -0.2, 0.1]}\n", "sky"),
    ("name: bad\nrain: {intensity: 0.5}\n", "rain.rate_mm_h"),
    ("name: bad\nrain: {rate_mm_h: -2.0}\n", "rain.rate_mm_h"),
    ("name: bad\nsky: {model: hosek}\n", "sky.model"),
    ("name: bad\nsky: {model: preetham, turbidity: 1.2}\n", "sky.turbidity"),
    ("name: bad\nsun: {elevation_deg: -5.0}\nsky: {model: preetham}\n", "sky.model"),
    ("name: bad\nsun: {angular_radius_deg: 9.0}\n", "sun.angular_radius_deg"),
])
def test_bad_yaml_names_file_and_key(tmp_path: Path, body: str, key: str):
    path = tmp_path / "mine.yaml"
    path.write_text(body)
    with pytest.raises(ConfigError) as err:
        get_condition(path)
    assert str(path) in str(err.value) and key in str(err.value)


def test_unknown_name_lists_the_shipped_ones():
    with pytest.raises(ConfigError, match="available: .*morning"):
        get_condition("snow")


def test_user_condition_from_any_path(tmp_path: Path):
    path = tmp_path / "storm.yaml"
    path.write_text("name: storm\nfog: {visibility_m: 40.0}\nrain: {rate_mm_h: 50.0}\n")
    cond = get_condition(path)
    assert cond.name == "storm" and cond.fog_visibility_m == 40.0 and cond.wetness == 1.0  # a drowned road
    assert cond.visibility_m < 40.0  # the rain dims the air beyond the fog


def test_fog_follows_koschmieder():
    cond = condition(fog={"visibility_m": 100.0, "color_rgb": (0.5, 0.5, 0.5)})
    radiance = np.array([[1.0, 0.0, 0.2]] * 3, np.float32)
    out = cond.fog(radiance, np.array([0.0, 100.0, np.inf], np.float32), np.array([True, True, False]))
    np.testing.assert_allclose(out[0], radiance[0])
    t = np.exp(-KOSCHMIEDER)  # 2 % contrast left at the visibility distance
    np.testing.assert_allclose(out[1], radiance[1] * t + 0.5 * (1 - t), rtol=1e-6)
    np.testing.assert_allclose(out[2], [0.5, 0.5, 0.5])  # the sky is all fog


def test_fog_contrast_decays_with_the_exact_ray_distance(actors_factory, wall):
    # Contrast against the airlight A of every pixel of a real scene: (L - A) / (L0 - A) = exp(-3.912 d / V)
    # with d the distance along that pixel's ray (not the z-depth, not a per-object distance).
    fog = get_condition("fog")
    scene = FrameScene(StaticScene([wall(60.0), ground()]), actors_factory([[12.0, 1.0, 0.75], [35.0, -4.0, 0.75]],
                                                                           [[4.5, 1.8, 1.5]] * 2))
    cam = Camera(camera_config(**SMALL))
    to_world = cam.camera_to_world(Transform.from_xyz_rpy((0.0, 0.0, 1.5)))
    rays = make_rays(to_world.translation, cam.pixel_directions, to_world.rotation)
    hits = scene.cast_rays(rays)
    clear = shade(scene, rays, hits, fog)
    foggy = fog.fog(clear, hits.t_m, hits.hit)
    airlight = np.asarray(fog.airlight_rgb, np.float32) * fog.exposure
    ok = hits.hit & (np.abs(clear[:, 0] - airlight[0]) > 0.05)
    assert ok.sum() > 1000 and np.ptp(hits.t_m[ok]) > 30.0
    ratio = (foggy[ok, 0] - airlight[0]) / (clear[ok, 0] - airlight[0])
    np.testing.assert_allclose(ratio, np.exp(-KOSCHMIEDER * hits.t_m[ok] / fog.fog_visibility_m), rtol=1e-4)


def test_fog_lowers_contrast_with_distance(box_meshes, actors_factory, wall):
    # The same dark box at 10 m and at 60 m in front of a bright wall: fog shrinks the far one's contrast.
    cam = Camera(camera_config(**SMALL))
    contrast = []
    for x in (10.0, 60.0):
        scene = FrameScene(StaticScene([wall(x + 2.0, material="lane_paint")]),
                           actors_factory([[x, 0.0, 0.0]], [[1.0, 0.3 * x / 10, 0.3 * x / 10]], colors=[[0.02] * 3]),
                           box_meshes)
        frame = render_camera(scene, cam, Transform.identity(), get_condition("fog"))
        grey = frame.rgb.astype(float).mean(axis=2)
        contrast.append(grey[frame.instance_id == 1].mean() - grey[frame.instance_id == 0].mean())
    assert abs(contrast[1]) < 0.5 * abs(contrast[0])


def test_rain_near_road_is_darker_than_dry():
    # The near road, seen steeply, is darker when wet; at grazing angles it mirrors the sky (not tested here).
    rain = get_condition("rain")
    dry = Condition(rain.config.model_copy(update={"rain": None}))
    scene = FrameScene(StaticScene([ground()]), _no_actors())
    cam = Camera(camera_config(**SMALL))
    pose = Transform.from_xyz_rpy((0.0, 0.0, 1.5))
    wet_img = render_camera(scene, cam, pose, rain).rgb.astype(float)
    dry_img = render_camera(scene, cam, pose, dry).rgb.astype(float)
    near, nearest = slice(SMALL["height_px"] * 3 // 4, None), slice(SMALL["height_px"] - 10, None)
    assert wet_img[near].mean() < dry_img[near].mean()
    assert wet_img[nearest].mean() < 0.9 * dry_img[nearest].mean()  # asphalt x 0.53 in linear units


def _no_actors():
    from pipeline.world.actors import Actors

    return Actors.empty()


def test_same_seed_same_noisy_image(actors_factory, wall):
    scene = FrameScene(StaticScene([wall(60.0), ground()]), actors_factory([[15.0, 1.0, 0.75]], [[4.5, 1.8, 1.5]]))
    cam = Camera(camera_config(**SMALL))
    pose = Transform.from_xyz_rpy((0.0, 0.0, 0.75))
    for name in ("night", "rain"):
        cond = get_condition(name)
        a = render_camera(scene, cam, pose, cond, np.random.default_rng(4)).rgb
        b = render_camera(scene, cam, pose, cond, np.random.default_rng(4)).rgb
        c = render_camera(scene, cam, pose, cond, np.random.default_rng(5)).rgb
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c)


def test_fog_attenuates_the_lidar_twice_over_its_path(wall):
    # Intensity I0 exp(-a d): fog adds its extinction at 905 nm on the way out and back, 2 beta; beyond some range the
    # return falls below the detection threshold.
    fog = get_condition("fog")
    lidar = Lidar(lidar_config(channels=8, upper_fov_deg=2.0, lower_fov_deg=-2.0, horizontal_resolution_deg=1.0,
                              dropout=0.0, range_noise_std_m=0.0))
    near = FrameScene(StaticScene([wall(20.0)]), _no_actors())  # within the fog's LiDAR range of 29 m
    clear = render_lidar(near, lidar, Transform.identity(), np.random.default_rng(0))
    foggy = render_lidar(near, lidar, Transform.identity(), np.random.default_rng(0), condition=fog)
    wall_points = foggy.semantic != SemanticClass.WEATHER  # the rest: the droplets' own returns near the sensor
    assert 0 < wall_points.sum() < len(clear)  # extra drop-out and the detection threshold lose points
    key_c = clear.column.astype(int) * 8 + clear.ring
    key_f = foggy.column[wall_points].astype(int) * 8 + foggy.ring[wall_points]
    both = np.isin(key_c, key_f)
    beta = KOSCHMIEDER / 80.0  # 80 m of fog: droplets large against 905 nm, the extinction of visible light
    d = np.linalg.norm(clear.points_m[both], axis=1)
    np.testing.assert_allclose(foggy.intensity[wall_points], clear.intensity[both] * np.exp(-2.0 * beta * d),
                               rtol=1e-4)
    far = FrameScene(StaticScene([wall(40.0)]), _no_actors())
    assert len(render_lidar(far, lidar, Transform.identity(), np.random.default_rng(0))) > 0
    far_fog = render_lidar(far, lidar, Transform.identity(), np.random.default_rng(0), condition=fog)
    assert (far_fog.semantic == SemanticClass.WEATHER).all() and (np.linalg.norm(far_fog.points_m, axis=1) < 20).all()
