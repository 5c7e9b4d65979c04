"""Weather in physical units: extinction of fog and rain (closed forms and a numeric integral), the road's water
film, rain streaks over the exposure time, puddles, the wet road's mirror image, haloes in fog."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.core.classes import SemanticClass
from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import get_condition
from pipeline.sensors.rain import streak_coverage
from pipeline.sensors.render import render_camera
from pipeline.sensors.weather import (
    KOSCHMIEDER,
    drops_per_m3,
    fog_extinction_per_m,
    rain_extinction_per_m,
    road_wetness,
    terminal_velocity_mps,
    water_film_depth_mm,
)
from pipeline.sensors.wet import PUDDLE_SHARE, puddles
from pipeline.world.actors import Actors
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import camera_config, condition


def test_fog_extinction_by_visibility_and_wavelength():
    assert fog_extinction_per_m(80.0) == pytest.approx(KOSCHMIEDER / 80.0)
    # Dense fog: droplets large against any of these wavelengths, no wavelength dependence (Kim et al. 2001, q = 0).
    assert fog_extinction_per_m(300.0, 905.0) == pytest.approx(KOSCHMIEDER / 300.0)
    # Haze of 2 km: q = 0.16 * 2 + 0.34 = 0.66; near infrared passes better than green.
    assert fog_extinction_per_m(2000.0, 905.0) == pytest.approx(KOSCHMIEDER / 2000.0 * (905 / 550) ** -0.66)
    with pytest.raises(ValueError, match="visibility"):
        fog_extinction_per_m(0.0)


@pytest.mark.parametrize("rate", [1.0, 10.0, 50.0])
def test_rain_extinction_is_twice_the_drops_cross_section(rate):
    # beta = integral over Marshall-Palmer drops of Q_ext (pi D^2 / 4) N(D) dD with Q_ext = 2, numerically.
    lam = 4.1 * rate ** -0.21
    d_mm = np.linspace(0.0, 30.0, 300_001)
    integrand = 2.0 * np.pi * (d_mm * 1e-3) ** 2 / 4.0 * 8000.0 * np.exp(-lam * d_mm)  # per m^3 per mm
    assert rain_extinction_per_m(rate) == pytest.approx(np.trapezoid(integrand, d_mm), rel=1e-6)
    assert drops_per_m3(rate) == pytest.approx(8000.0 / lam)


def test_rain_visibility_and_fall_speeds_are_those_observed():
    # Heavy rain of 10 mm/h leaves a few km of visibility, a downpour of 50 mm/h under one.
    assert 2000.0 < KOSCHMIEDER / rain_extinction_per_m(10.0) < 3000.0
    assert KOSCHMIEDER / rain_extinction_per_m(50.0) < 1000.0
    assert rain_extinction_per_m(0.0) == 0.0
    np.testing.assert_allclose(terminal_velocity_mps([1.0, 2.0, 5.0]),
                               9.65 - 10.3 * np.exp(-0.6 * np.array([1.0, 2.0, 5.0])))
    assert 6.4 < float(terminal_velocity_mps(2.0)) < 6.7  # Gunn and Kinzer (1949) measured 6.49 m/s


def test_gallaway_water_film():
    # By hand: 0.01485 * 0.7^0.11 * 3.5^0.43 * 10^0.59 * 0.025^-0.42 - 0.7.
    expected = 0.01485 * 0.7 ** 0.11 * 3.5 ** 0.43 * 10 ** 0.59 * 0.025 ** -0.42 - 0.7
    assert water_film_depth_mm(10.0) == pytest.approx(expected)
    wet = [road_wetness(r) for r in (0.0, 0.5, 2.0, 10.0, 50.0)]
    assert wet[0] == 0.0 and wet[-1] == 1.0 and all(a < b for a, b in itertools.pairwise(wet))


def test_puddles_cover_their_share_of_the_road():
    x, y = np.meshgrid(np.arange(-400.0, 400.0, 0.7), np.arange(-300.0, 300.0, 0.7))
    for wetness in (0.5, 1.0):
        share = puddles(x.ravel(), y.ravel(), wetness).mean()
        assert share == pytest.approx(PUDDLE_SHARE * wetness ** 2, abs=0.02)
    assert not puddles(x.ravel(), y.ravel(), 0.0).any()


LEVEL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # optical frame -> world, looking along +x


def _streaks(rate=10.0, exposure_s=1 / 1000, depth=None, seed=0, velocity=(0.0, 0.0, 0.0), size=(320, 240)):
    cam = Camera(camera_config(width_px=size[0], height_px=size[1]))
    depth = np.zeros(size[::-1], np.float32) if depth is None else depth
    cover, lit = streak_coverage(rate, (0.0, 0.0), exposure_s, cam, Transform(LEVEL, np.zeros(3)),
                                 np.asarray(velocity), depth, np.random.default_rng(seed))
    assert lit is None  # no lights
    return cover


def test_streaks_are_seeded_and_grow_with_the_rate():
    a, b, c = _streaks(seed=3), _streaks(seed=3), _streaks(seed=4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.min() >= 0.0 and a.max() < 1.0
    assert _streaks(rate=50.0).mean() > 2.0 * _streaks(rate=10.0).mean() > 4.0 * _streaks(rate=2.0).mean()


def test_a_long_exposure_smears_drops_into_faint_vertical_streaks():
    short, long = (_streaks(50.0, exposure_s=t, size=(640, 480)) for t in (1 / 2000, 1 / 30))
    assert long.max() < 0.5 * short.max()  # a drop's light spread over a longer streak
    # Falling drops seen by a level camera streak down the image: the coverage varies far less along columns.
    assert np.count_nonzero(long > 1e-3) > 100
    along_col = np.abs(np.diff(long, axis=0)).mean()
    along_row = np.abs(np.diff(long, axis=1)).mean()
    assert along_col < 0.6 * along_row


def test_drops_behind_a_surface_are_hidden():
    open_air = _streaks()
    wall_2m = _streaks(depth=np.full((240, 320), 2.0, np.float32))
    wall_near = _streaks(depth=np.full((240, 320), 0.25, np.float32))  # nearer than any drop drawn
    assert 0.0 < wall_2m.sum() < 0.8 * open_air.sum()
    assert wall_near.sum() == 0.0


def _plane(z_m: float, half_m: float, material: str, semantic: SemanticClass, x0: float = 0.0) -> Mesh:
    v = np.array([[x0 - half_m, -half_m, z_m], [x0 + half_m, -half_m, z_m], [x0 + half_m, half_m, z_m],
                  [x0 - half_m, half_m, z_m]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material_index(material), semantic)


def test_the_wet_road_mirrors_a_lamp_where_geometry_puts_its_image():
    # A glowing panel 4 m up, 20 m ahead, above a flat road; the camera 1.5 m up looks along +x. The panel's mirror
    # image lies 4 m below the road: its pixel row is cy + f (1.5 + 4) / 20. There the wet road is brighter than the
    # dry one; above and beside it, not.
    panel = Mesh(np.array([[20.0, -1.0, 3.5], [20.0, 1.0, 3.5], [20.0, 1.0, 4.5], [20.0, -1.0, 4.5]]),
                 np.array([[0, 1, 2], [0, 2, 3]]), material_index("lamp"), SemanticClass.POLE)
    road = _plane(0.0, 200.0, "asphalt", SemanticClass.ROAD)
    scene = FrameScene(StaticScene([road, panel]), Actors.empty())
    cam = Camera(camera_config(width_px=160, height_px=120, quality="realistic"))
    pose = Transform.from_xyz_rpy((0.0, 0.0, 1.5))
    night = {"sun": {"elevation_deg": -10.0, "intensity": 0.0, "shadows": False},
             "sky": {"zenith_rgb": (1e-4,) * 3, "horizon_rgb": (1e-4,) * 3, "ambient_rgb": (1e-3,) * 3},
             "vehicle_lights": {"glow": True}}
    wet = condition(**night, rain={"rate_mm_h": 50.0})
    dry = condition(**night)
    img_wet = render_camera(scene, cam, pose, wet).rgb.astype(float).mean(axis=2)
    img_dry = render_camera(scene, cam, pose, dry).rgb.astype(float).mean(axis=2)
    row = round(cam.cy + cam.fy * (1.5 + 4.0) / 20.0 - 0.5)
    col = round(cam.cx - 0.5)
    assert img_wet[row, col] > img_dry[row, col] + 20
    beside = round(cam.cx + cam.fx * 3.0 / 20.0)  # 3 m to the side of the image, 2 m beyond the panel's edge
    assert img_wet[row, beside] < img_dry[row, beside] + 5
    assert img_wet[row + 25, col] < img_wet[row, col] - 20


def test_lamps_glow_through_fog():
    panel = Mesh(np.array([[30.0, -0.3, 1.2], [30.0, 0.3, 1.2], [30.0, 0.3, 1.8], [30.0, -0.3, 1.8]]),
                 np.array([[0, 1, 2], [0, 2, 3]]), material_index("lamp"), SemanticClass.POLE)
    scene = FrameScene(StaticScene([panel]), Actors.empty())
    cam = Camera(camera_config(width_px=160, height_px=120, quality="realistic"))
    pose = Transform.from_xyz_rpy((0.0, 0.0, 1.5))
    night = {"sun": {"elevation_deg": -10.0, "intensity": 0.0, "shadows": False},
             "sky": {"zenith_rgb": (1e-4,) * 3, "horizon_rgb": (1e-4,) * 3, "ambient_rgb": (1e-3,) * 3},
             "vehicle_lights": {"glow": True}, "lens": {"bloom_strength": 0.0}}
    clear = render_camera(scene, cam, pose, condition(**night)).rgb.astype(float).mean(axis=2)
    foggy = render_camera(scene, cam, pose, condition(**night, fog={"visibility_m": 100.0})).rgb.astype(float)
    foggy = foggy.mean(axis=2)
    ring = (slice(60 - 12, 60 - 8), slice(80 - 2, 80 + 2))  # a few pixels above the panel's top edge
    assert foggy[ring].mean() > clear[ring].mean() + 10


def test_fog_shortens_the_lidar_range_to_where_its_weakest_target_fades():
    # At the fogged range R the just-detectable target's power exp(-2 beta R) / R^2 equals 1 / R0^2 (closed form:
    # Lambert's W); 80 m of fog leaves a 120 m LiDAR some 30 m, as measured in fog chambers.
    from pipeline.sensors.conditions import lidar_range_m

    beta = KOSCHMIEDER / 80.0
    r = lidar_range_m(120.0, beta)
    assert np.exp(-2 * beta * r) / r ** 2 == pytest.approx(1 / 120.0 ** 2, rel=1e-9)
    assert 25.0 < r < 35.0
    assert lidar_range_m(120.0, 0.0) == 120.0


def test_the_clear_sky_sun_by_elevation():
    from pipeline.core.photometry import SUN_ANCHOR_LUX, air_mass, clear_sky_sun_lux

    assert air_mass(90.0) == pytest.approx(1.0, abs=1e-3)
    assert air_mass(60.0) == pytest.approx(1.0 / np.sin(np.radians(60.0)), rel=2e-3)  # a plane atmosphere up high
    assert 14.0 < air_mass(3.0) < 16.0
    assert clear_sky_sun_lux(65.0) == pytest.approx(SUN_ANCHOR_LUX, rel=0.02)  # the anchor: a high sun, 100 klx
    assert clear_sky_sun_lux(0.0) == 0.0 and clear_sky_sun_lux(3.0) < 0.06 * clear_sky_sun_lux(65.0)
    dusk = get_condition("dusk")
    from pipeline.core.photometry import lux_to_irradiance
    from pipeline.sensors.post import luminance

    assert float(luminance(np.asarray(dusk.sun_rgb))) == pytest.approx(lux_to_irradiance(clear_sky_sun_lux(3.0)))


def _facing_lamp(x_m: float = 20.0):
    """A wide uniform lamp at (x_m, 0, 0) shining back along -x, 1 unit of irradiance at 1 m (a 45 degree cone with
    a hard edge)."""
    from pipeline.sensors.lights import _spots

    return _spots([[x_m, 0.0, 0.0]], [[-1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], [1.0, 1.0, 1.0], 1.0, 1.0, 1.0, 0.01,
                  1e4, False)


def test_a_drop_scatters_a_lamp_by_its_phase_function():
    from pipeline.sensors.beams import PHASE_ASYMMETRY, henyey_greenstein
    from pipeline.sensors.rain import drop_radiance

    lamp = _facing_lamp()
    drops = np.array([[10.0, 0.0, 0.0], [-5.0, 0.0, 0.0], [30.0, 0.0, 0.0], [10.0, 3.0, 0.0]])
    out = drop_radiance(lamp, drops, np.zeros(3))
    # Between lamp and camera the light goes on forward to the camera (theta 0); behind the camera it must turn back
    # (theta 180 degrees); behind the lamp nothing; off the line, the angle between the two ways.
    off = np.array([-10.0, 3.0, 0.0]) / np.hypot(10.0, 3.0)  # the light's way to the last drop (unit)
    on = -np.array([10.0, 3.0, 0.0]) / np.hypot(10.0, 3.0)  # that drop's way on to the camera
    expected = np.array([henyey_greenstein(np.float32(1.0), PHASE_ASYMMETRY) / 100.0,
                         henyey_greenstein(np.float32(-1.0), PHASE_ASYMMETRY) / 625.0, 0.0,
                         henyey_greenstein(np.float32(off @ on), PHASE_ASYMMETRY) / 109.0])
    for c in range(3):
        np.testing.assert_allclose(out[:, c], expected, rtol=1e-4)
    assert out[0, 0] > 1000 * out[1, 0] * 625 / 100  # forward scattering dwarfs the back-scatter


def test_lamps_light_the_streaks_without_changing_them():
    cam = Camera(camera_config(width_px=320, height_px=240))
    args = (10.0, (0.0, 0.0), 1 / 1000, cam, Transform(LEVEL, np.zeros(3)), np.zeros(3),
            np.zeros((240, 320), np.float32))
    plain, none = streak_coverage(*args, np.random.default_rng(7))
    cover, lit = streak_coverage(*args, np.random.default_rng(7), _facing_lamp())
    assert none is None and lit.shape == (240, 320, 3) and lit.dtype == np.float32
    np.testing.assert_array_equal(plain, cover)  # the same drops, the same coverage
    assert lit.min() >= 0 and lit.max() > 0
    assert (lit[..., 0] > 0).sum() <= (cover > 0).sum()  # light only where a streak is
    # The lamp is straight ahead: streaks near the middle of the image, between it and the camera, glow most.
    middle = lit[80:160, 120:200, 0].sum() / max((cover[80:160, 120:200] > 0).sum(), 1)
    edge = lit[:, :40, 0].sum() / max((cover[:, :40] > 0).sum(), 1)
    assert middle > 3 * edge
