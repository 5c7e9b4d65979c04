"""The realistic camera in physical units: light to electrons, auto-exposure within the sensor's limits, noise from
the signal, and the night's street lamps giving the road the luminance of their EN 13201 class."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import ValidationError

from pipeline.core.classes import SemanticClass
from pipeline.core.config.sensors import ImageSensorConfig, LensConfig, StreetLampConfig
from pipeline.core.photometry import CD_M2_PER_UNIT, LUX_PER_UNIT, candela_to_intensity, radiance_to_luminance
from pipeline.sensors.conditions import Condition, get_condition
from pipeline.sensors.exposure import auto_exposure, electrons_per_unit_second, exposure_for
from pipeline.sensors.lights import street_lamp_lights
from pipeline.sensors.post import apply_post
from pipeline.sensors.shading import shade
from pipeline.world.actors import Actors
from pipeline.world.materials import material_arrays, material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene

SENSOR = ImageSensorConfig()


def test_the_sun_anchors_the_units():
    """Sun intensity 2.6 is 100 klx; white paper under 1 unit of irradiance has 1 unit of radiance = E / pi."""
    assert pytest.approx(100_000.0) == 2.6 * LUX_PER_UNIT
    assert pytest.approx(LUX_PER_UNIT / math.pi) == CD_M2_PER_UNIT
    assert radiance_to_luminance(1.0) == pytest.approx(12_242.7, rel=1e-4)


def test_electrons_follow_the_camera_equation():
    """A surface of L cd/m^2 gives the focal plane pi T L / (4 N^2) lx; a 3.75 um pixel collects E t p^2 lm s,
    1.35e16 photons each, a third of them through its filter, QE 0.6 of those as electrons."""
    lux = math.pi * 0.9 * CD_M2_PER_UNIT / (4 * 2.0 ** 2)
    expected = lux * (3.75e-6) ** 2 * 1.35e16 * 0.6 / 3
    assert electrons_per_unit_second(SENSOR) == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(8.214e7, rel=1e-3)
    # One stop of aperture (f/2 -> f/2.8) halves the light; the pixel's area goes as its pitch squared.
    assert electrons_per_unit_second(SENSOR.model_copy(update={"f_number": 2.0 * math.sqrt(2)})) == pytest.approx(
        expected / 2)
    assert electrons_per_unit_second(SENSOR.model_copy(update={"pixel_pitch_um": 7.5})) == pytest.approx(4 * expected)


def grey(level: float) -> np.ndarray:
    return np.full((64, 80, 3), level, np.float32)


def test_auto_exposure_hits_the_key_with_the_exposure_time_first():
    """A daylight grey frame: the exposure time alone brings its log-average luminance to the key, gain 1."""
    level = 0.05  # ~600 cd/m^2: a road by day
    exposure = auto_exposure(grey(level), SENSOR)
    assert exposure.gain == 1.0
    assert SENSOR.exposure_time_s[0] < exposure.time_s < SENSOR.exposure_time_s[1]
    # Within half of the auto-exposure's step (1/16 stop): 2^(1/32) - 1 = 2.2 %.
    assert exposure.scale * level == pytest.approx(SENSOR.metering_key, rel=0.022)
    assert math.log2(exposure.time_s) * 16 == pytest.approx(round(math.log2(exposure.time_s) * 16), abs=1e-9)
    # The exposure compensation (a condition's lens.exposure) brightens the image by its factor.
    assert auto_exposure(grey(level), SENSOR, 2.0).scale == pytest.approx(2 * exposure.scale, rel=1e-9)
    # Radiance already multiplied by an exposure is divided by it again: the sensor sees the scene's light.
    assert auto_exposure(grey(3 * level), SENSOR, shaded_with=3.0).scale == pytest.approx(exposure.scale, rel=1e-6)


def test_a_dark_scene_gets_the_longest_time_the_highest_gain_and_stays_dark():
    """A dimly lit road all over (0.3 cd/m^2, EN 13201's lowest class M6): 1/30 s and gain 16 are not enough for
    the key; the image stays darker. (A frame of 1 cd/m^2 everywhere would just reach it, at gain 13.)"""
    level = 0.3 / CD_M2_PER_UNIT
    exposure = auto_exposure(grey(level), SENSOR)
    assert (exposure.time_s, exposure.gain) == (SENSOR.exposure_time_s[1], SENSOR.max_gain)
    electrons = electrons_per_unit_second(SENSOR) * level / 30
    assert exposure.scale * level == pytest.approx(electrons * 16 / SENSOR.full_well_e, rel=1e-9)
    assert exposure.scale * level < SENSOR.metering_key
    # Between the two: the longest time, then just the gain that reaches the key.
    dusk = auto_exposure(grey(30 * level), SENSOR)
    assert dusk.time_s == SENSOR.exposure_time_s[1] and 1.0 < dusk.gain < SENSOR.max_gain
    assert dusk.scale * 30 * level == pytest.approx(SENSOR.metering_key, rel=0.022)  # within half a step


def test_a_very_bright_scene_gets_the_shortest_time_and_stays_bright():
    level = 50.0  # the sun's disc all over
    exposure = auto_exposure(grey(level), SENSOR)
    assert (exposure.time_s, exposure.gain) == (SENSOR.exposure_time_s[0], 1.0)
    assert exposure.scale * level > SENSOR.metering_key


def measured_variance(level: float, exposure, seed: int = 3) -> float:
    """The noise variance apply_post adds to a flat patch at ``level`` (image units) under ``exposure``, with no
    other effect (no vignetting, bloom, range compression)."""
    lens = LensConfig(vignetting=0.0)
    image = np.full((400, 500, 3), level, np.float32)
    out = apply_post(image, lens, np.random.default_rng(seed), sensor=exposure)
    return float(np.var(out.astype(np.float64) - level))


@pytest.mark.parametrize("gain", [1.0, 4.0, 16.0])
def test_noise_is_shot_and_read_noise_amplified_by_the_gain(gain):
    """A flat grey patch: variance = v g / full_well + (g read / full_well)^2 (v the image value): the shot noise's
    standard deviation grows as the square root of the signal, and every term with the gain."""
    exposure = exposure_for(SENSOR, 1 / 100, gain)
    for level in (0.01, 0.04, 0.16):
        expected = level * gain / SENSOR.full_well_e + (gain * SENSOR.read_noise_e / SENSOR.full_well_e) ** 2
        # 600,000 draws: the variance's sampling error is sqrt(2 / 6e5) ~ 0.2 %.
        assert measured_variance(level, exposure) == pytest.approx(expected, rel=0.02)
    # Quadrupling the signal doubles the shot noise's standard deviation (read noise taken out).
    shot = [measured_variance(v, exposure) - exposure.read_variance for v in (0.04, 0.16)]
    assert math.sqrt(shot[1] / shot[0]) == pytest.approx(2.0, rel=0.03)


def test_a_light_in_candela_sets_its_intensity_and_round_trips():
    lamp = StreetLampConfig(intensity_cd=1430.0, color_rgb=(1.0, 0.75, 0.45))
    # Candela are luminous intensity: the colour's luminance (Rec. 709 Y) is divided out.
    y = 0.2126 * 1.0 + 0.7152 * 0.75 + 0.0722 * 0.45
    assert lamp.intensity * y == pytest.approx(1430.0 / LUX_PER_UNIT)
    assert StreetLampConfig.model_validate(lamp.model_dump()) == lamp  # a dumped config holds both, in agreement
    with pytest.raises(ValidationError, match="intensity_cd"):
        StreetLampConfig(intensity=30.0, intensity_cd=1430.0)


def road_luminance_under_lamps(condition: Condition, xy: np.ndarray) -> np.ndarray:
    """Luminance (cd/m^2) the condition's street lamps alone give dry asphalt (albedo 0.17, diffuse) at the points
    ``xy`` of a street lit like the town's: poles 6.7 m high every 30 m on both sides of a 7 m road, staggered
    (pipeline/world/props.py), shaded by the renderer on a matte ground and scaled to asphalt's albedo."""
    cfg = condition.street_lamps
    along = np.arange(-120.0, 150.0, 30.0)
    lamps = np.concatenate([np.column_stack([along, np.zeros_like(along), np.full_like(along, 6.7)]),
                            np.column_stack([along + 11.0, np.full_like(along, 7.0), np.full_like(along, 6.7)])])
    matte = "concrete"
    ground = Mesh(np.array([[-300.0, -300, 0], [300, -300, 0], [300, 300, 0], [-300, 300, 0]]),
                  np.array([[0, 1, 2], [0, 2, 3]]), material_index(matte), SemanticClass.ROAD)
    scene = FrameScene(StaticScene([ground]), Actors.empty())
    lights = street_lamp_lights(lamps, cfg.model_copy(update={"max_lamps": len(lamps), "shadows": False}),
                                np.array([15.0, 3.5, 0.0]))
    dark = Condition(condition.config.model_copy(update={"sky": condition.config.sky.model_copy(
        update={"ambient_rgb": (0.0, 0.0, 0.0)}), "headlights": None}))
    rays = np.zeros((len(xy), 6), np.float32)
    rays[:, :2], rays[:, 2], rays[:, 5] = xy, 1.0, -1.0
    radiance = shade(scene, rays, scene.cast_rays(rays), dark, lights)
    luminance = radiance @ np.array([0.2126, 0.7152, 0.0722], np.float32) / condition.exposure
    albedo = material_arrays()["albedo"][material_index(matte)].mean()
    return luminance / albedo * 0.17 * CD_M2_PER_UNIT


def test_the_nights_street_lamps_light_the_road_as_en13201_class_m3_asks():
    """EN 13201-2, class M3: average road luminance 1.0 cd/m^2 (maintained), overall uniformity U0 >= 0.4."""
    x, y = np.meshgrid(np.arange(0.25, 30.0, 0.5), np.arange(0.25, 7.0, 0.5))
    luminance = road_luminance_under_lamps(get_condition("night"), np.column_stack([x.ravel(), y.ravel()]))
    assert luminance.mean() == pytest.approx(1.0, abs=0.1)
    assert luminance.min() / luminance.mean() >= 0.4
    # The lamps are given in candela: 1,430 cd over a 70 deg cone is a ~5,900 lm luminaire.
    cfg = get_condition("night").street_lamps
    y = float(np.dot(cfg.color_rgb, [0.2126, 0.7152, 0.0722]))
    assert cfg.intensity * y == pytest.approx(candela_to_intensity(1430.0))
    lumens = 1430.0 * 2 * math.pi * (1 - math.cos(math.radians(cfg.half_angle_deg)))
    assert 5000 < lumens < 7000


def test_a_night_frame_is_exposed_at_the_sensors_limits():
    """The night's scene is too dark for the key: the camera takes its longest exposure and highest gain."""
    from pipeline.core.geometry import Transform
    from pipeline.sensors.camera import Camera
    from pipeline.sensors.render import render_camera
    from tests.sensors.conftest import camera_config, wall_mesh

    cam = Camera(camera_config(width_px=80, height_px=60))
    scene = FrameScene(StaticScene([wall_mesh(30.0)]), Actors.empty())
    night = get_condition("night")
    radiance = np.full((60, 80, 3), 1e-5, np.float32)
    exposure = auto_exposure(radiance, cam.config.sensor, night.exposure)
    assert (exposure.time_s, exposure.gain) == (1 / 30, 16.0)
    frame = render_camera(scene, cam, Transform.from_xyz_rpy((0.0, 0.0, 0.75)), night, np.random.default_rng(0))
    assert frame.rgb.mean() < render_camera(scene, cam, Transform.from_xyz_rpy((0.0, 0.0, 0.75)),
                                            get_condition("morning"), np.random.default_rng(0)).rgb.mean()


def test_motion_blur_follows_the_exposure_time_and_each_road_users_own_motion(actors_factory, wall):
    """At night (1/30 s) the ego's 15 m/s blurs a parked car beside the road; a car driving alongside at the ego's
    velocity does not move in the image during the exposure and stays as sharp as when nothing moves."""
    from pipeline.core.geometry import Transform
    from pipeline.sensors.camera import Camera
    from pipeline.sensors.render import render_camera
    from tests.sensors.conftest import camera_config

    ego = Transform.from_xyz_rpy((0.0, 0.0, 0.75))
    car = actors_factory([[7.0, 2.6, 0.75]], [[4.5, 1.8, 1.5]])
    scene = FrameScene(StaticScene([wall(40.0)]), car)
    cam = Camera(camera_config(width_px=320, height_px=240))
    night = get_condition("night")

    def frame(ego_speed: float, car_velocity) -> np.ndarray:
        out = render_camera(scene, cam, ego, night, np.random.default_rng(1), ego_speed_mps=ego_speed,
                            actor_velocity_mps=car_velocity)
        return out.rgb.astype(np.int16), out.instance_id

    still, ids = frame(0.0, None)
    parked, _ = frame(15.0, np.zeros((1, 3)))
    alongside, _ = frame(15.0, np.array([[15.0, 0.0, 0.0]]))
    import cv2

    inside = cv2.erode((ids > 0).astype(np.uint8), np.ones((7, 7), np.uint8)).astype(bool)
    assert inside.sum() > 200
    # Sharp: the car's own pixels do not move (what differs, a little, is the glow that bloom spreads onto it from
    # the blurred background).
    sharp, blurred = (np.abs(x[inside] - still[inside]).mean() for x in (alongside, parked))
    assert sharp < 0.5 and blurred > 4 * sharp + 1.0
