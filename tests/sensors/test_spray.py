"""Spray behind moving vehicles on a wet road (pipeline.sensors.spray): the clouds a frame's vehicles get, the
optical depth in closed form against a quadrature of the density, the camera's and the LiDAR's cloud lists against
every cloud, and the veil and the LiDAR's loss end to end; labels unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from pipeline.core.classes import ObjectClass
from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import get_condition
from pipeline.sensors.lidar import Lidar, render_lidar
from pipeline.sensors.render import render_camera
from pipeline.sensors.spray import (
    CAR,
    HEAVY,
    MIN_SPEED_MPS,
    NO_SPRAY,
    REFERENCE_SPEED_MPS,
    camera_optical_depths,
    optical_depths,
    spray_clouds,
    spray_factor,
    sweep_optical_depths,
)
from pipeline.sensors.weather import road_water_mm
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import camera_config, condition, lidar_config
from tests.sensors.test_night import ground

CAR_SIZE = [4.5, 1.8, 1.5]


def _velocity(speeds, yaws=None):
    yaws = np.zeros(len(speeds)) if yaws is None else np.asarray(yaws)
    return np.column_stack([np.cos(yaws) * speeds, np.sin(yaws) * speeds, np.zeros(len(speeds))])


def _density(clouds, k, point):
    """The cloud's extinction at a world point, written from the model's definition."""
    p = clouds.axes[k].T @ (point - clouds.origin[k])
    if np.any(p < clouds.lo[k]) or np.any(p > clouds.hi[k]):
        return 0.0
    return clouds.peak_per_m[k] * np.exp(-0.5 * np.sum((p / clouds.sigma[k]) ** 2))


def test_speed_factor_starts_above_the_threshold_and_is_one_at_the_reference():
    f = spray_factor(np.array([0.0, MIN_SPEED_MPS, MIN_SPEED_MPS + 1.0, REFERENCE_SPEED_MPS, 40.0, 50.0, 80.0]))
    assert f[0] == f[1] == 0.0 and 0.0 < f[2] < 0.1
    assert f[3] == pytest.approx(1.0)
    assert f[3] < f[4] < f[5] and f[5] == f[6]  # it stops growing at MAX_SPEED_MPS


def test_clouds_only_behind_moving_vehicles_on_a_wet_road(actors_factory):
    """A car at 25 m/s (yaw 90 degrees) gets a cloud from its rear bumper at road level, pointing backwards, with
    the car shape's peak x the road's water; a standing car, a reversing car, a pedestrian and a bicycle get none;
    a truck the heavy shape; a dry road or no velocities nothing."""
    classes = [ObjectClass.CAR, ObjectClass.CAR, ObjectClass.CAR, ObjectClass.PEDESTRIAN, ObjectClass.BICYCLE,
               ObjectClass.TRUCK]
    centres = [[10.0, 5.0, 0.75], [20.0, 0.0, 0.75], [30.0, 0.0, 0.75], [0.0, 3.0, 0.9], [0.0, 6.0, 0.9],
               [40.0, 0.0, 2.0]]
    sizes = [CAR_SIZE] * 3 + [[0.5, 0.6, 1.8], [1.8, 0.6, 1.8], [12.0, 2.5, 4.0]]
    yaws = [np.pi / 2, 0.0, 0.0, 0.0, 0.0, 0.0]
    actors = actors_factory(centres, sizes, yaws=yaws, classes=classes)
    velocity = _velocity([25.0, 0.0, -25.0, 25.0, 25.0, 25.0], yaws)
    clouds = spray_clouds(actors, velocity, water_mm=0.5)
    assert clouds.actor.tolist() == [0, 5]
    np.testing.assert_allclose(clouds.origin[0], [10.0, 5.0 - 2.25, 0.0], atol=1e-12)
    np.testing.assert_allclose(clouds.axes[0][:, 0], [0.0, -1.0, 0.0], atol=1e-12)  # backwards
    np.testing.assert_allclose(clouds.axes[0][:, 2], [0.0, 0.0, 1.0])
    assert clouds.peak_per_m[0] == pytest.approx(CAR.peak_per_m * 0.5)
    assert clouds.peak_per_m[1] == pytest.approx(HEAVY.peak_per_m * 0.5)
    np.testing.assert_allclose(clouds.sigma[1], [HEAVY.length_m, 1.25 + HEAVY.spread_m, HEAVY.height_m])
    assert clouds.lo[1, 0] == pytest.approx(-HEAVY.front * 12.0) and clouds.lo[1, 2] == 0.0
    assert len(spray_clouds(actors, velocity, water_mm=0.0)) == 0
    assert len(spray_clouds(actors, None, water_mm=0.5)) == 0
    assert len(spray_clouds(actors, velocity, water_mm=0.5, active=np.array([False] * 5 + [True]))) == 1
    with pytest.raises(ValueError, match="velocity_mps"):
        spray_clouds(actors, velocity[:2], water_mm=0.5)


def test_conditions_give_spray_only_in_rain():
    """The shipped rain sprays at its rate's water (road_water_mm); morning and fog do not, nor rain with spray 0."""
    from tests.sensors.conftest import make_actors

    actors = make_actors([[0.0, 0.0, 0.75]], [CAR_SIZE])
    velocity = _velocity([REFERENCE_SPEED_MPS])
    rain = get_condition("rain")
    clouds = rain.spray(actors, velocity)
    assert clouds.peak_per_m[0] == pytest.approx(CAR.peak_per_m * road_water_mm(rain.rain_rate_mm_h))
    assert get_condition("morning").spray(actors, velocity) is NO_SPRAY
    assert get_condition("fog").spray(actors, velocity) is NO_SPRAY
    off = condition(rain={"rate_mm_h": 10.0, "spray": 0.0})
    assert off.spray(actors, velocity) is NO_SPRAY
    double = condition(rain={"rate_mm_h": 10.0, "spray": 2.0})
    assert double.spray(actors, velocity).peak_per_m[0] == pytest.approx(2.0 * clouds.peak_per_m[0])


def _random_clouds(rng, n=6):
    from tests.sensors.conftest import make_actors

    centres = np.column_stack([rng.uniform(-30, 30, n), rng.uniform(-30, 30, n), np.full(n, 0.75)])
    yaws = rng.uniform(-np.pi, np.pi, n)
    classes = [ObjectClass.CAR if i % 2 else ObjectClass.TRUCK for i in range(n)]
    actors = make_actors(centres, [CAR_SIZE] * n, yaws=yaws, classes=classes)
    return spray_clouds(actors, _velocity(rng.uniform(15.0, 40.0, n), yaws), water_mm=1.0)


def test_optical_depth_is_the_integral_of_the_density():
    """Rays from inside and outside the clouds, along and across them, some axis-parallel (a direction component
    0), some ending inside a cloud: the closed form equals a quadrature of the density written from the model's
    definition, cloud by cloud."""
    rng = np.random.default_rng(5)
    clouds = _random_clouds(rng)
    origins = np.column_stack([rng.uniform(-40, 40, 60), rng.uniform(-40, 40, 60), rng.uniform(0.2, 3.0, 60)])
    origins[:6] = clouds.origin + 0.5 * clouds.axes[:, :, 0]  # inside each cloud, just behind the bumper
    targets = np.column_stack([rng.uniform(-40, 40, 60), rng.uniform(-40, 40, 60), rng.uniform(0.0, 2.0, 60)])
    d = targets - origins
    d[6:9, 1:] = 0.0  # along +-x
    d[9:12, :2] = 0.0  # straight down or up
    d[9:12, 2] = [-1.0, 1.0, -1.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rays = np.column_stack([origins, d]).astype(np.float32)
    ends = np.where(rng.random(60) < 0.5, rng.uniform(2.0, 60.0, 60), np.inf)
    got = optical_depths(clouds, rays, ends)
    o, dd = rays[:, :3].astype(np.float64), rays[:, 3:].astype(np.float64)
    checked = 0
    for i in range(len(rays)):
        end = min(ends[i], 200.0)
        want = 0.0
        for k in range(len(clouds)):
            # Integrate between where the ray enters and leaves the cloud's bounds (the density is smooth there, and
            # jumps to 0 at the bounds, which a quadrature across them would misjudge).
            p, e = clouds.axes[k].T @ (o[i] - clouds.origin[k]), clouds.axes[k].T @ dd[i]
            with np.errstate(divide="ignore", invalid="ignore"):
                t_lo, t_hi = (clouds.lo[k] - p) / e, (clouds.hi[k] - p) / e
            inside = (p >= clouds.lo[k]) & (p <= clouds.hi[k])
            a = max(0.0, *np.where(e != 0, np.minimum(t_lo, t_hi), np.where(inside, -np.inf, np.inf)))
            b = min(end, *np.where(e != 0, np.maximum(t_lo, t_hi), np.where(inside, np.inf, -np.inf)))
            if b > a:
                want += quad(lambda t, k=k, i=i: _density(clouds, k, o[i] + t * dd[i] * (1 - 1e-12)), a, b, limit=400,
                             epsabs=1e-12, epsrel=1e-9)[0]
        assert got[i] == pytest.approx(want, rel=2e-4, abs=1e-7), i
        checked += want > 1e-3
    assert checked >= 10  # the rays meet clouds, not only empty air


def test_camera_and_sweep_lists_miss_no_cloud():
    """The camera's per-tile lists and the sweep's per-azimuth lists give every ray the optical depth that testing
    every cloud gives (to float32 rounding: the sum's order may differ), with clouds round the sensor, beside it
    and behind it."""
    rng = np.random.default_rng(8)
    clouds = _random_clouds(rng, 12)
    camera = Camera(camera_config(width_px=200, height_px=150, hfov_deg=100.0))
    for pose in (Transform.from_xyz_rpy((0.0, 0.0, 1.4), (0.0, 0.0, 0.3)), Transform.from_xyz_rpy(
            clouds.origin[0] + [0.0, 0.0, 1.0], (0.0, 0.0, 2.0))):
        cam_to_world = camera.camera_to_world(pose)
        from pipeline.world.scene import make_rays

        rays = make_rays(cam_to_world.translation, camera.pixel_directions, cam_to_world.rotation)
        ends = np.where(rng.random(len(rays)) < 0.3, rng.uniform(1.0, 50.0, len(rays)), np.inf)
        every = optical_depths(clouds, rays, ends)
        rows, tau = camera_optical_depths(clouds, camera, cam_to_world, rays, ends)
        full = np.zeros(len(rays), np.float32)
        full[rows] = tau
        assert (every > 1e-3).sum() > 500
        np.testing.assert_allclose(full, every, rtol=1e-5, atol=1e-9)
        swept = sweep_optical_depths(clouds, rays, ends, np.arange(len(rays)))
        np.testing.assert_allclose(swept, every, rtol=1e-5, atol=1e-9)


def _road_scene(actors_factory, box_meshes, ahead_m=25.0):
    """A car ``ahead_m`` ahead on a flat road, driving away."""
    actors = actors_factory([[ahead_m, 0.0, 0.75]], [CAR_SIZE])
    return FrameScene(StaticScene([ground()]), actors, box_meshes)


def test_spray_veils_the_road_behind_a_car_and_leaves_the_labels(actors_factory, box_meshes):
    """Rendered in rain with the car at 25 m/s: the road just behind the car moves towards the airlight, the sky
    above the car does not change, and every label image and box is the same as without spray."""
    scene = _road_scene(actors_factory, box_meshes)
    camera = Camera(camera_config(width_px=160, height_px=120, mount={"xyz_m": (0.0, 0.0, 1.4)}))
    rain = get_condition("rain")
    clouds = rain.spray(scene.actors, _velocity([REFERENCE_SPEED_MPS]))
    ego = Transform.identity()
    plain = render_camera(scene, camera, ego, rain)
    sprayed = render_camera(scene, camera, ego, rain, spray=clouds)
    for name in ("instance_id", "semantic", "depth_m", "depth_valid"):
        np.testing.assert_array_equal(getattr(plain, name), getattr(sprayed, name))
    for name in ("box_tight", "box_amodal", "visible_px", "occlusion", "truncation"):
        np.testing.assert_array_equal(getattr(plain.labels, name), getattr(sprayed.labels, name))
    # The road between the camera and the car, just behind it (20-22 m ahead, on the car's line).
    cam_to_world = camera.camera_to_world(ego)
    uv, _ = camera.project(cam_to_world.inverse().apply(np.array([[21.0, 0.0, 0.0], [25.0, 0.0, 6.0]])))
    (u0, v0), (u1, v1) = np.round(uv).astype(int)
    air = np.asarray(rain.airlight_rgb) * rain.exposure
    assert plain.rgb[v0, u0].mean() < sprayed.rgb[v0, u0].mean()  # the dark road lightens towards the grey air
    assert np.abs(plain.rgb[v1, u1].astype(int) - sprayed.rgb[v1, u1].astype(int)).max() <= 1  # the sky above
    assert air.mean() > 0


def test_lidar_pulses_lose_twice_the_optical_depth(actors_factory, box_meshes):
    """A LiDAR behind the car: a beam through the cloud keeps exp(-2 tau) of its intensity (tau from the closed
    form), beams that miss the cloud keep theirs; a dense enough cloud loses the return behind it."""
    scene = _road_scene(actors_factory, box_meshes, ahead_m=40.0)  # the cloud's bounds end ~14 m ahead
    lidar = Lidar(lidar_config(channels=16, upper_fov_deg=2.0, lower_fov_deg=-10.0, horizontal_resolution_deg=1.0,
                               mount={"xyz_m": (0.0, 0.0, 1.0)}, range_noise_std_m=0.0, dropout=0.0))
    ego = Transform.identity()
    clouds = spray_clouds(scene.actors, _velocity([REFERENCE_SPEED_MPS]), water_mm=1.0)
    plain = render_lidar(scene, lidar, ego, np.random.default_rng(0))
    sprayed = render_lidar(scene, lidar, ego, np.random.default_rng(0), spray=clouds)
    assert len(plain) == len(sprayed)
    np.testing.assert_array_equal(plain.points_m, sprayed.points_m)
    to_world = lidar.lidar_to_world(ego)
    world = to_world.apply(plain.points_m.astype(np.float64))
    origin = to_world.translation
    d = (world - origin) / np.linalg.norm(world - origin, axis=1, keepdims=True)
    rays = np.column_stack([np.broadcast_to(origin, d.shape), d]).astype(np.float32)
    tau = optical_depths(clouds, rays, np.linalg.norm(world - origin, axis=1))
    assert (tau > 0.01).sum() >= 5 and (tau == 0).sum() >= 5
    np.testing.assert_allclose(sprayed.intensity, plain.intensity * np.exp(-2.0 * tau), rtol=1e-5)
    dense = spray_clouds(scene.actors, _velocity([REFERENCE_SPEED_MPS]), water_mm=1000.0)
    lost = render_lidar(scene, lidar, ego, np.random.default_rng(0), spray=dense)
    assert len(lost) < len(plain)


def test_lamps_glow_in_spray_as_in_fog():
    """A lamp pixel seen through fog of transmittance T_f and spray of T_s (composited with the same airlight, as
    the render does) sends HALO_FORWARD_SHARE of the light both took, L0 (1 - T_f T_s), into its halo; with the
    spray's transmittance 1 the halo is the fog's alone, byte for byte."""
    from pipeline.sensors.conditions import HALO_FORWARD_SHARE

    fog = condition(sun={"elevation_deg": -10.0, "intensity": 0.0, "shadows": False}, fog={"visibility_m": 300.0})
    h, w = 240, 320
    distance = np.full(h * w, 60.0)
    lamp = (h // 2) * w + w // 2
    sources = np.zeros(h * w, bool)
    sources[lamp] = True
    air = np.asarray(fog.airlight_rgb, np.float32) * np.float32(fog.exposure)
    l0 = np.float32(50.0)
    t_fog = float(np.exp(-fog.extinction_per_m() * 60.0))
    totals = {}
    for t_spray in (1.0, 0.4):
        radiance = np.tile(air, (h * w, 1)).astype(np.float32)
        t = t_fog * t_spray
        radiance[lamp] = l0 * t + air * (1.0 - t)
        before = radiance.copy()
        spray_t = np.ones(h * w, np.float32)
        spray_t[lamp] = t_spray
        fog.halos(radiance, distance, sources, (h, w), 300.0, spray_t)
        totals[t_spray] = float((radiance - before).sum(axis=0).mean())
        assert totals[t_spray] == pytest.approx(HALO_FORWARD_SHARE * l0 * (1.0 - t), rel=0.02)
        if t_spray == 1.0:
            alone = before.copy()
            fog.halos(alone, distance, sources, (h, w), 300.0)
            np.testing.assert_array_equal(alone, radiance)
    assert totals[0.4] > totals[1.0]
