"""The LiDAR's returns from fog and rain droplets (pipeline/sensors/backscatter.py): the tabulated soft-target
return against a quadrature of its definition; the strongest-return rule and the detection threshold in a sweep;
the points' labels, ranges and intensities."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from pipeline.core.classes import SemanticClass
from pipeline.core.geometry import Transform
from pipeline.sensors.backscatter import BACKSCATTER_PER_EXTINCTION, LIGHT_M_PER_NS, soft_returns
from pipeline.sensors.conditions import get_condition
from pipeline.sensors.lidar import Lidar, render_lidar
from pipeline.sensors.spray import spray_clouds, sweep_soft_returns
from pipeline.sensors.weather import fog_extinction_per_m
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import condition, lidar_config, make_actors
from tests.sensors.test_night import ground
from tests.sensors.test_spray import _density

SMALL = dict(channels=8, upper_fov_deg=2.0, lower_fov_deg=-2.0, horizontal_resolution_deg=2.0)


def _soft_power(big_r, cut, alpha, beta, w, r1, r2):
    """The definition: beta x integral over [max(R - w, 0), min(R, cut)] of sin^2(pi (R - r) / w) xi(r)
    exp(-2 alpha r) / r^2 dr, xi rising linearly from 0 at r1 to 1 at r2."""
    def integrand(r):
        xi = min(max((r - r1) / (r2 - r1), 0.0), 1.0) if r2 > r1 else float(r >= r1)
        return math.sin(math.pi * (big_r - r) / w) ** 2 * xi * math.exp(-2.0 * alpha * r) / (r * r)

    lo, hi = max(big_r - w, r1), min(big_r, cut)
    if hi <= lo + 1e-9:  # an empty window (or one of rounding's width)
        return 0.0
    kinks = [r2] if lo < r2 < hi else None
    return beta * quad(integrand, lo, hi, points=kinks, epsabs=1e-12, epsrel=1e-7, limit=200)[0]


@pytest.mark.parametrize("overlap", [(1.67, 7.63), (0.9, 1.0)])
@pytest.mark.parametrize("cut", [2.5, 4.0, 7.0, math.inf])
def test_the_table_is_the_quadrature_of_the_definition(overlap, cut):
    alpha, tau = 0.05, 20.0
    beta = BACKSCATTER_PER_EXTINCTION * alpha
    w = LIGHT_M_PER_NS * tau
    table = soft_returns(alpha, beta, tau, *overlap)
    power, reported = (float(v[0]) for v in table.at(np.array([cut])))
    ends = np.arange(0.5, min(cut, 60.0) + w, 0.01)
    direct = np.array([_soft_power(e, cut, alpha, beta, w, *overlap) for e in ends])
    best = int(np.argmax(direct))
    assert power == pytest.approx(direct[best], rel=2e-3)
    assert reported == pytest.approx(ends[best] - 0.5 * w, abs=0.03)  # where a surface's peak would put it
    if cut < math.inf:  # a nearer surface cuts the droplets off: never a stronger return
        free = float(table.at(np.array([math.inf]))[0][0])
        assert power <= free * (1 + 1e-12)


def _sweep(scene, cond, seed=0, **cfg):
    lidar = Lidar(lidar_config(**{**SMALL, "dropout": 0.0, "range_noise_std_m": 0.0, **cfg}))
    return lidar, render_lidar(scene, lidar, Transform.identity(), np.random.default_rng(seed), condition=cond)


def _empty() -> FrameScene:
    return FrameScene(StaticScene([]), make_actors(np.zeros((0, 3)), np.zeros((0, 3))))


def _onset_visibility_m(cfg) -> float:
    """The fog visibility at which the droplets' free peak equals the detection threshold."""
    threshold = cfg.range_reflectivity / math.pi / cfg.range_m ** 2

    def excess(v):
        a = fog_extinction_per_m(v, cfg.wavelength_nm)
        return float(soft_returns(a, BACKSCATTER_PER_EXTINCTION * a, cfg.pulse_half_width_ns, *cfg.overlap_m)
                     .power[-1]) / threshold - 1.0

    return brentq(excess, 20.0, 400.0, xtol=1e-9)


def test_the_droplets_return_where_their_peak_reaches_the_threshold():
    lidar = Lidar(lidar_config(**SMALL))
    onset = _onset_visibility_m(lidar.config)
    assert 150.0 < onset < 300.0  # the default head: fog of 80 and 150 m returns, 300 m and rain's mist do not
    _, denser = _sweep(_empty(), condition(fog={"visibility_m": onset * 0.999}))
    _, thinner = _sweep(_empty(), condition(fog={"visibility_m": onset * 1.001}))
    beams = lidar.columns * lidar.config.channels  # all sky: the droplets' or nothing
    # At the threshold the ranging error is c tau_H / 2 = 3 m: some points scatter into the blind zone.
    assert 0.8 * beams < len(denser) <= beams and len(thinner) == 0
    assert (denser.semantic == SemanticClass.WEATHER).all() and (denser.instance_id == 0).all()
    for name, some in (("fog", True), ("fog-150", True), ("fog-300", False), ("rain", False), ("morning", False)):
        _, s = _sweep(_empty(), get_condition(name), range_noise_std_m=0.02, dropout=0.02)
        assert (len(s) > 0) == some, name


def test_weather_points_lie_at_the_table_range_scattered_by_the_ranging_error():
    cond = condition(fog={"visibility_m": 60.0})
    seed = 3
    lidar, s = _sweep(_empty(), cond, seed=seed, range_noise_std_m=0.05)
    cfg = cond.lidar(lidar)
    alpha = cond.extinction_per_m(cfg.wavelength_nm)
    table = soft_returns(alpha, BACKSCATTER_PER_EXTINCTION * alpha, cfg.pulse_half_width_ns, *cfg.overlap_m)
    power, reported = float(table.power[-1]), float(table.range_m[-1])
    threshold = cfg.range_reflectivity / math.pi / lidar.config.range_m ** 2
    normal = np.random.default_rng(seed).standard_normal(len(lidar.directions), dtype=np.float32)
    sigma = math.hypot(cfg.range_noise_std_m, 0.5 * LIGHT_M_PER_NS * cfg.pulse_half_width_ns * threshold / power)
    expected = reported + normal * sigma
    beams = s.column.astype(np.int64) * cfg.channels + s.ring
    seen = expected >= lidar.range_min_m  # scattered into the blind zone: no point
    np.testing.assert_array_equal(beams, np.flatnonzero(seen))
    np.testing.assert_allclose(np.linalg.norm(s.points_m, axis=1), expected[seen], rtol=1e-5, atol=1e-5)
    # Intensity: the reflectivity that returns the same power in clear air, then the rig's law at that range.
    equivalent = math.pi * power * reported ** 2 * math.exp(2.0 * alpha * reported)
    np.testing.assert_allclose(s.intensity, equivalent * math.exp(-cfg.attenuation_per_m * reported), rtol=1e-5)


def test_a_surface_returning_more_than_the_droplets_keeps_its_point(wall):
    cond = condition(fog={"visibility_m": 60.0})
    near = FrameScene(StaticScene([wall(3.0)]), make_actors(np.zeros((0, 3)), np.zeros((0, 3))))
    _, s = _sweep(near, cond)
    azimuth = 180.0 - 2.0 * s.column.astype(np.float64)
    front = np.abs(azimuth) <= 45.0  # the wall within 4.3 m
    assert front.sum() == 8 * 45  # azimuths -44 .. 44 degrees
    assert (s.semantic[front] == SemanticClass.BUILDING).all()  # a wall so near outshines the droplets
    np.testing.assert_allclose(s.points_m[front, 0], 3.0, atol=1e-4)
    behind = np.abs(azimuth) > 90.0
    assert behind.sum() > 8 * 80 and (s.semantic[behind] == SemanticClass.WEATHER).all()  # the sky: the droplets'
    # A dark wall 25 m away through 60 m of fog returns less than the droplets: their points replace its own.
    far = FrameScene(StaticScene([wall(25.0)]), make_actors(np.zeros((0, 3)), np.zeros((0, 3))))
    _, f = _sweep(far, cond)
    assert (f.semantic == SemanticClass.WEATHER).all() and (np.linalg.norm(f.points_m, axis=1) < 20.0).all()


def test_actor_points_replaced_by_droplets_are_not_counted(box_meshes):
    # A car 22 m away, turned 52 degrees, in 80 m fog: the beams meeting its sides at a slant return less than the
    # droplets near the sensor, those meeting it squarely more.
    actors = make_actors(np.array([[22.0, 0.0, 0.75]]), np.array([[4.5, 1.8, 1.5]]), yaws=[0.9])
    scene = FrameScene(StaticScene([]), actors, box_meshes)
    fan = dict(upper_fov_deg=1.0, lower_fov_deg=-3.0, horizontal_resolution_deg=0.5)
    _, clear = _sweep(scene, None, **fan)
    _, s = _sweep(scene, condition(fog={"visibility_m": 80.0}), **fan)
    on_actor = s.instance_id > 0
    assert 0 < on_actor.sum() < clear.points_per_actor[0]
    assert s.points_per_actor.tolist() == [int(on_actor.sum())]
    assert ((s.semantic == SemanticClass.WEATHER) == ~on_actor).all()
    lost = _beams(clear, clear.instance_id > 0) - _beams(s, on_actor)
    assert lost and lost <= _beams(s, s.semantic == SemanticClass.WEATHER)  # the droplets took those beams


def _beams(sweep, mask) -> set[int]:
    return set((sweep.column[mask].astype(np.int64) * 8 + sweep.ring[mask]).tolist())


def _spray_waveform_peak(clouds, origin, direction, alpha, ratio, w, overlap, far, dt=0.002):
    """The soft-target waveform through spray and air written from the definition: beta(t) from the clouds' density
    (test_spray's), tau by the trapezoid rule, the pulse by direct convolution; its peak and reported range."""
    r1, r2 = overlap
    t = np.arange(dt / 2, far, dt)
    beta = np.array([sum(_density(clouds, k, origin + s * direction) for k in range(len(clouds))) for s in t])
    tau = np.concatenate([[0.0], np.cumsum(0.5 * (beta[1:] + beta[:-1]) * dt)])
    xi = np.clip((t - r1) / (r2 - r1), 0.0, 1.0)
    f = ratio * (beta + alpha) * xi * np.exp(-2.0 * (alpha * t + tau)) / t ** 2 * dt
    pulse = np.sin(np.pi * np.arange(0.0, w, dt) / w) ** 2
    waveform = np.convolve(f, pulse)  # index n: window end R = (n + 1) dt
    n = int(np.argmax(waveform))
    return waveform[n], (n + 1) * dt - 0.5 * w


def test_spray_returns_are_the_quadrature_of_the_definition(actors_factory):
    actors = actors_factory([[10.0, 0.0, 0.75]], [[4.5, 1.8, 1.5]])
    clouds = spray_clouds(actors, np.array([[25.0, 0.0, 0.0]]), water_mm=1.0, scale=8.0)  # 0.4 /m at the bumper
    origin = np.array([0.0, 0.0, 1.0])
    angles = [(0.0, -4.0), (3.0, -8.0), (0.0, -12.0), (180.0, -6.0), (90.0, -2.0)]
    direction = np.array([[np.cos(np.radians(e)) * np.cos(np.radians(a)), np.cos(np.radians(e)) * np.sin(np.radians(a)),
                           np.sin(np.radians(e))] for a, e in angles])
    rays = np.column_stack([np.broadcast_to(origin, direction.shape), direction]).astype(np.float32)
    alpha, w, overlap, far = 0.004, LIGHT_M_PER_NS * 20.0, (1.67, 7.63), 30.0
    ratio = BACKSCATTER_PER_EXTINCTION
    air = float(soft_returns(alpha, ratio * alpha, 20.0, *overlap).power[-1])
    met, power, reported = sweep_soft_returns(clouds, rays, np.full(len(rays), np.inf), alpha, ratio, w, overlap,
                                              far, air, 1e-12)
    assert len(met) >= 4
    for j, i in enumerate(met):
        peak, at = _spray_waveform_peak(clouds, origin, rays[i, 3:].astype(np.float64), alpha, ratio, w, overlap,
                                        far)
        assert power[j] == pytest.approx(peak, rel=0.03)
        assert reported[j] == pytest.approx(at, abs=0.15)
        assert power[j] > air  # the spray adds to the air's return


def test_dense_spray_near_the_sensor_returns_points_inside_its_cloud(actors_factory, box_meshes):
    scene = FrameScene(StaticScene([ground()]), actors_factory([[9.0, 0.0, 0.75]], [[4.5, 1.8, 1.5]]), box_meshes)
    velocity = np.array([[30.0, 0.0, 0.0]])
    lidar = Lidar(lidar_config(channels=16, upper_fov_deg=2.0, lower_fov_deg=-15.0, horizontal_resolution_deg=1.0,
                               mount={"xyz_m": (0.0, 0.0, 1.8)}))
    ego = Transform.identity()
    for spray, expect in ((1.0, False), (10.0, True)):  # the model's spray; ten times as dense
        rain = condition(rain={"rate_mm_h": 10.0, "spray": spray})
        clouds = rain.spray(scene.actors, velocity)
        s = render_lidar(scene, lidar, ego, np.random.default_rng(0), condition=rain, spray=clouds)
        weather = s.semantic == SemanticClass.WEATHER
        assert weather.any() == expect, spray
        if expect:
            world = lidar.lidar_to_world(ego).apply(s.points_m[weather].astype(np.float64))
            inside = clouds.boxes.contains(world, margin_m=1.0)[0]  # the ranging error scatters them
            assert inside.mean() > 0.9 and (s.instance_id[weather] == 0).all()
