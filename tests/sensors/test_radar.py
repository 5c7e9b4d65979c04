"""Radar: closed-form ranges and Doppler, detections inside their objects' boxes, RCS by class, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.core.classes import ObjectClass
from pipeline.core.config import ConditionConfig, RadarConfig, RigConfig
from pipeline.core.geometry import Transform
from pipeline.sensors.radar import (
    NOISE_CLIP_SIGMA,
    actor_ray_mask,
    mount,
    ray_pattern,
    render_radar,
    weather_attenuation_db_per_km,
)
from pipeline.world.actors import DEFAULT_MESHES, Actors
from pipeline.world.scene import FrameScene, StaticScene

EGO = Transform.identity()
MOUNT = {"xyz_m": (2.0, 0.0, 0.5)}
EXACT = dict(range_accuracy_m=0.0, azimuth_accuracy_deg=0.0, elevation_accuracy_deg=0.0, velocity_accuracy_mps=0.0,
             snr_0dbsm_100m_db=90.0, max_detections=100000)  # no noise, every cell detected


def radar(**fields) -> RadarConfig:
    return RadarConfig(**{"name": "front", "mount": MOUNT, **fields})


def scan(scene, config, seed=0, **kwargs):
    return render_radar(scene, config, EGO, np.random.default_rng(seed), **kwargs)


def test_ray_pattern_is_symmetric_and_covers_the_field_of_view():
    config = radar(azimuth_fov_deg=120.0, elevation_fov_deg=8.0, ray_step_deg=0.5)
    dirs, solid = ray_pattern(config)
    assert len(dirs) == 241 * 17 == config.ray_count
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6)
    az = np.degrees(np.arctan2(dirs[:, 1], dirs[:, 0])).reshape(17, 241)
    el = np.degrees(np.arcsin(dirs[:, 2])).reshape(17, 241)
    np.testing.assert_allclose(az[0, [0, 120, 240]], [60.0, 0.0, -60.0], atol=1e-4)  # left to right
    np.testing.assert_allclose(el[[0, 8, 16], 0], [4.0, 0.0, -4.0], atol=1e-4)  # top to bottom
    # The rays' solid angles add up to the field of view's: (fov_az + step) * 2 sin((fov_el + step) / 2).
    step = np.radians(0.5)
    expected = (np.radians(120.0) + step) * 2 * np.sin(0.5 * (np.radians(8.0) + step))
    assert solid.sum() == pytest.approx(expected, rel=1e-3)


def test_actor_ray_mask_is_a_superset(actors_factory, box_meshes):
    rng = np.random.default_rng(1)
    n = 15
    centers = np.column_stack([rng.uniform(-60, 60, n), rng.uniform(-60, 60, n), rng.uniform(-1, 3, n)])
    centers[:3] = [[9.0, 0.3, 0.5], [-20.0, 0.0, 0.5], [2.0, 30.0, 0.5]]  # ahead, behind, beside
    sizes = np.column_stack([rng.uniform(0.5, 12, n), rng.uniform(0.5, 3, n), rng.uniform(1, 4, n)])
    actors = actors_factory(centers, sizes, yaws=rng.uniform(-np.pi, np.pi, n))
    scene = FrameScene(StaticScene([]), actors, box_meshes)
    config = radar(ray_step_deg=0.5, azimuth_fov_deg=170.0, elevation_fov_deg=20.0)
    to_world = EGO @ mount(config)
    dirs, _ = ray_pattern(config)
    mask = actor_ray_mask(scene, config, to_world)
    hits = scene.cast(np.broadcast_to(to_world.translation, dirs.shape), to_world.apply_vectors(dirs))
    reach = hits.hit & (hits.t_m <= config.range_max_m)
    assert reach.sum() > 100 and mask[reach].all()
    assert mask.mean() < 0.9  # and it does leave rays out
    around = FrameScene(StaticScene([]), actors_factory([[2.0, 0.0, 0.5]], [[4.5, 1.8, 1.5]]), box_meshes)
    assert actor_ray_mask(around, config, to_world).all()  # an actor around the radar: every ray


def test_config_errors_name_the_field():
    with pytest.raises(ValidationError, match="range_min_m"):
        radar(range_min_m=50.0, range_max_m=40.0)
    with pytest.raises(ValidationError, match="ray_step_deg"):
        radar(ray_step_deg=1.0, azimuth_resolution_deg=0.5)
    with pytest.raises(ValidationError, match="false_alarm_probability"):
        radar(false_alarm_probability=1.0)
    with pytest.raises(ValidationError, match="repeated: front"):
        RigConfig(name="r", cameras=[{"name": "front", "mount": MOUNT}], radars=[radar()])


def test_a_rig_without_radars_dumps_as_before():
    rig = RigConfig(name="r", lidars=[{"name": "top", "mount": MOUNT}])
    assert "radars" not in rig.model_dump(mode="json")
    assert RigConfig(name="r", radars=[radar()]).model_dump(mode="json")["radars"][0]["name"] == "front"


def test_wall_at_a_known_range(wall):
    config = radar(**EXACT)
    s = scan(FrameScene(StaticScene([wall(42.0, material="barrier")]), _no_actors()), config)
    assert len(s) > 50 and (s.instance_id == 0).all()
    # Noise-free: a cell's power-weighted centroid lies on the plane, 40 m ahead of the radar (2 m forward).
    np.testing.assert_allclose(s.points_m[:, 0], 40.0, atol=1e-3)
    np.testing.assert_allclose(s.range_m, np.linalg.norm(s.points_m, axis=1), rtol=1e-6)
    np.testing.assert_allclose(s.azimuth_rad, np.arctan2(s.points_m[:, 1], s.points_m[:, 0]), atol=1e-6)
    np.testing.assert_allclose(s.elevation_rad, np.arcsin(s.points_m[:, 2] / s.range_m), atol=1e-5)
    # Within the field of view and the range.
    assert np.abs(np.degrees(s.azimuth_rad)).max() <= 60.0 + 1e-3
    assert s.range_m.max() <= 200.0


def test_static_wall_seen_from_a_moving_ego_approaches_at_the_ego_speed_along_the_ray(wall):
    config = radar(**EXACT)
    scene = FrameScene(StaticScene([wall(42.0, material="barrier")]), _no_actors())
    s = scan(scene, config, ego_velocity_mps=np.array([15.0, 0.0, 0.0]))
    cos = s.points_m[:, 0] / s.range_m
    # A cell's velocity is a power-weighted mean over its rays, each within the cell's angular diagonal (its
    # azimuth resolution by the whole elevation field: elevation is not resolved) of the cell's centroid.
    spread = np.radians(np.hypot(config.azimuth_resolution_deg, config.elevation_fov_deg))
    np.testing.assert_allclose(s.radial_velocity_mps, -15.0 * cos, atol=15.0 * (1 - np.cos(spread)) + 1e-4)
    assert (s.radial_velocity_mps < 0).all()  # approaching
    np.testing.assert_array_equal(s.radial_velocity_comp_mps, 0.0)


def test_head_on_target_at_a_known_closing_speed(actors_factory, box_meshes, wall):
    actors = actors_factory([[52.0, 0.0, 0.5]], [[4.5, 1.8, 1.5]], yaws=[np.pi])
    scene = FrameScene(StaticScene([wall(150.0)]), actors, box_meshes)
    config = radar()  # default noise and detection model
    s = scan(scene, config, ego_velocity_mps=np.array([8.0, 0.0, 0.0]),
             actor_velocity_mps=np.array([[-12.0, 0.0, 0.0]]))
    mine = s.instance_id == 1
    assert mine.sum() == s.detections_per_actor[0] >= 1
    # Closing at 20 m/s straight ahead: cos(angle) > 0.9995 over the car's face at 48 m.
    bound = NOISE_CLIP_SIGMA * config.velocity_accuracy_mps + 20.0 * 5e-4
    np.testing.assert_allclose(s.radial_velocity_mps[mine], -20.0, atol=bound)
    np.testing.assert_allclose(s.radial_velocity_comp_mps[mine], -12.0, atol=bound)
    wall_hits = s.instance_id == 0
    np.testing.assert_allclose(s.radial_velocity_comp_mps[wall_hits], 0.0,
                               atol=NOISE_CLIP_SIGMA * config.velocity_accuracy_mps + 1e-6)


def test_detections_lie_in_their_box_grown_by_the_accuracy(actors_factory, box_meshes, wall):
    actors = actors_factory([[15.0, 3.0, 0.75], [30.0, -6.0, 1.5], [60.0, -1.0, 1.0]],
                            [[4.5, 1.8, 1.5], [8.0, 2.5, 3.0], [0.6, 0.6, 1.8]], yaws=[0.3, -0.5, 0.0],
                            classes=[ObjectClass.CAR, ObjectClass.TRUCK, ObjectClass.PEDESTRIAN])
    scene = FrameScene(StaticScene([wall(190.0)]), actors, box_meshes)
    config = radar(snr_0dbsm_100m_db=40.0)
    s = scan(scene, config, actor_velocity_mps=np.array([[5.0, 0.0, 0.0], [-3.0, 1.0, 0.0], [0.0, 1.2, 0.0]]))
    world = (EGO @ mount(config)).apply(s.points_m.astype(np.float64))
    for k, tid in enumerate(actors.track_id):
        mine = s.instance_id == tid
        assert mine.sum() == s.detections_per_actor[k] >= 1
        angle = np.radians(config.azimuth_accuracy_deg + config.elevation_accuracy_deg)
        margin = NOISE_CLIP_SIGMA * (config.range_accuracy_m + float(s.range_m[mine].max()) * angle) + 1e-3
        assert actors.boxes.contains(world[mine], margin_m=margin)[k].all()


def test_rcs_by_class_truck_above_car_above_pedestrian(actors_factory):
    """The built-in bodies alone at 30 m, seen from four sides: an object's RCS is the sum over its detections."""
    sizes = {ObjectClass.TRUCK: (8.0, 2.5, 3.5), ObjectClass.CAR: (4.5, 1.8, 1.5),
             ObjectClass.PEDESTRIAN: (0.6, 0.6, 1.75)}
    config = radar(**EXACT)
    rcs = {}
    for cls, size in sizes.items():
        values = []
        for yaw in (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi):
            actors = actors_factory([[32.0, 0.0, 0.5 * size[2]]], [size], yaws=[yaw], classes=[cls])
            s = scan(FrameScene(StaticScene([]), actors, DEFAULT_MESHES), config)
            values.append(10 * np.log10(np.sum(10 ** (s.rcs_dbsm[s.instance_id == 1] / 10))))
        rcs[cls] = float(np.mean(values))
    assert rcs[ObjectClass.TRUCK] > rcs[ObjectClass.CAR] > rcs[ObjectClass.PEDESTRIAN]
    # The calibration the module states: a car about 10 dBsm, a pedestrian near -8 dBsm (5 dB either way).
    assert 5.0 <= rcs[ObjectClass.CAR] <= 15.0
    assert -13.0 <= rcs[ObjectClass.PEDESTRIAN] <= -3.0


def test_same_seed_same_scan_and_the_cap_keeps_the_strongest(actors_factory, box_meshes, wall):
    actors = actors_factory([[20.0, 1.0, 0.75]], [[4.5, 1.8, 1.5]])
    scene = FrameScene(StaticScene([wall(60.0, material="barrier")]), actors, box_meshes)
    config = radar()
    a, b, c = scan(scene, config, seed=3), scan(scene, config, seed=3), scan(scene, config, seed=4)
    for name in ("points_m", "range_m", "radial_velocity_mps", "rcs_dbsm", "snr_db", "instance_id"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
    assert a.points_m.tobytes() != c.points_m.tobytes()
    full = scan(scene, radar(**EXACT))
    capped = scan(scene, radar(**{**EXACT, "max_detections": 5}))
    assert len(capped) == 5 < len(full)
    np.testing.assert_allclose(np.sort(capped.snr_db), np.sort(full.snr_db)[-5:])


def test_weather_attenuates_the_snr_two_ways(wall):
    downpour = ConditionConfig(name="rain", rain={"rate_mm_h": 50.0})
    fog = ConditionConfig(name="fog", fog={"visibility_m": 50.0})
    alpha_rain, alpha_fog = weather_attenuation_db_per_km(downpour), weather_attenuation_db_per_km(fog)
    assert alpha_rain == pytest.approx(1.1 * 50.0 ** 0.71)  # ITU-R P.838 at 77 GHz, 50 mm/h
    assert 0.0 < alpha_fog < 1.0  # fog that blinds a camera at 50 m costs a radar < 1 dB/km
    assert weather_attenuation_db_per_km(ConditionConfig(name="clear")) == 0.0
    scene = FrameScene(StaticScene([wall(102.0, material="barrier")]), _no_actors())
    clear, wet = scan(scene, radar(**EXACT)), scan(scene, radar(**EXACT), attenuation_db_per_km=alpha_rain)
    np.testing.assert_array_equal(clear.range_m, wet.range_m)
    np.testing.assert_allclose(clear.snr_db - wet.snr_db, 2 * clear.range_m * alpha_rain / 1000.0, atol=1e-3)


def _no_actors() -> Actors:
    return Actors.empty()


def test_a_bad_rig_file_names_the_file_and_the_field(tmp_path):
    from pipeline.core.config import ConfigError, load_config

    path = tmp_path / "rig.yaml"
    path.write_text("name: r\nradars:\n  - name: front\n    range_max_m: -5\n    mount: {xyz_m: [2, 0, 0.5]}\n")
    with pytest.raises(ConfigError) as err:
        load_config(RigConfig, path, "rigs")
    assert str(path) in str(err.value) and "radars[0].range_max_m" in str(err.value)
