"""Night: darker than morning, headlight cones and street-lamp pools in closed form, shadows, bounded lights."""

from __future__ import annotations

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import Condition, get_condition
from pipeline.sensors.lights import ego_headlights, street_lamp_lights, vehicle_headlights
from pipeline.sensors.render import render_camera
from pipeline.sensors.shading import shade
from pipeline.world.actors import Actors
from pipeline.world.materials import material_arrays, material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import camera_config, wall_mesh

EGO = Transform.from_xyz_rpy((0.0, 0.0, 0.75))  # a car's box centre is 0.75 m above the road
MATTE = "concrete"  # no specular term: closed forms hold for the diffuse light alone
ALBEDO = material_arrays()["albedo"][material_index(MATTE)]


def ground(half_m: float = 300.0, material: str = MATTE) -> Mesh:
    h = half_m
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material_index(material), SemanticClass.ROAD)


def night_without_others(wdr: bool = True):
    """Night with the ego's headlights only; ``wdr=False`` also turns the camera's range compression off (the
    scene's light as it is)."""
    night = get_condition("night")
    headlights = night.headlights.model_copy(update={"others": False})
    update = {"headlights": headlights}
    if not wdr:
        update["lens"] = night.config.lens.model_copy(update={"wdr_gamma": 1.0})
    return Condition(night.config.model_copy(update=update))


def down_ray(point: np.ndarray) -> np.ndarray:
    """A ray from 1 m above ``point`` straight down onto it."""
    return np.array([[point[0], point[1], point[2] + 1.0, 0.0, 0.0, -1.0]], np.float32)


def test_night_is_darker_than_morning(actors_factory, wall):
    actors = actors_factory([[15.0, 1.0, 0.75], [30.0, -3.0, 0.75]], [[4.5, 1.8, 1.5]] * 2, brake=[True, False])
    scene = FrameScene(StaticScene([wall(60.0), ground()]), actors)
    cam = Camera(camera_config(width_px=160, height_px=120))
    morning = render_camera(scene, cam, EGO, get_condition("morning")).rgb.mean()
    night = get_condition("night")
    assert night.lens.wdr_gamma < 1.0
    lens = night.config.lens.model_copy(update={"wdr_gamma": 1.0})
    flat = Condition(night.config.model_copy(update={"lens": lens}))
    # The scene's light: with the camera's range compression off, night is less than half as bright as morning.
    unlifted = render_camera(scene, cam, EGO, flat).rgb.mean()
    assert unlifted < 0.5 * morning
    # The night camera's wide-dynamic-range processing lifts the dark parts; the frame stays darker than morning's.
    lifted = render_camera(scene, cam, EGO, night).rgb.mean()
    assert unlifted < lifted < morning


def test_headlight_on_axis_irradiance_is_closed_form():
    # The ego's low beam (one light of two lamps) hits the road where its axis, pitched down by p, meets it:
    # there the cone factor is 1 and E = 2 I rgb sin(p) window(s) / s^2, s the distance along the axis.
    night = night_without_others()
    cfg = night.headlights
    light = ego_headlights(EGO, cfg)
    assert len(light) == 1
    p = np.radians(cfg.pitch_down_deg)
    s = light.position_m[0, 2] / np.sin(p)
    on_axis = light.position_m[0] + light.axis[0] * s
    assert abs(on_axis[2]) < 1e-9
    scene = FrameScene(StaticScene([ground()]), Actors.empty())
    rays = down_ray(on_axis)
    out = shade(scene, rays, scene.cast_rays(rays), night, light)
    window = (1.0 - (s / cfg.range_m) ** 4) ** 2
    irradiance = 2.0 * cfg.intensity * np.asarray(cfg.color_rgb) * np.sin(p) * window / s**2
    ambient = np.asarray(night.ambient_rgb)
    expected = ALBEDO * (ambient + irradiance) * night.exposure
    np.testing.assert_allclose(out[0], expected, rtol=1e-4)
    # Beyond the horizontal half-angle: no headlight at all, only the ambient light.
    angle = np.radians(cfg.half_angle_h_deg + 5.0)
    outside = np.array([s * np.cos(angle), s * np.sin(angle), 0.0])
    rays = down_ray(outside)
    out = shade(scene, rays, scene.cast_rays(rays), night, light)
    np.testing.assert_allclose(out[0], ALBEDO * ambient * night.exposure, rtol=1e-5)


def test_road_in_the_ego_headlight_cone_is_brighter_than_outside():
    cam = Camera(camera_config(width_px=320, height_px=240, hfov_deg=120.0,
                              mount={"xyz_m": (0.6, 0.0, 0.65)}))
    scene = FrameScene(StaticScene([ground(material="asphalt")]), Actors.empty())
    world_to_cam = cam.camera_to_world(EGO).inverse()
    uv, _ = cam.project(world_to_cam.apply(np.array([[12.0, 0.0, 0.0], [8.0, 9.0, 0.0], [8.0, -9.0, 0.0]])))
    ratios = []
    for night in (night_without_others(wdr=False), night_without_others()):
        grey = render_camera(scene, cam, EGO, night).rgb.astype(float).mean(axis=2)
        inside, left, right = (grey[int(v), int(u)] for u, v in uv)
        ratios.append(inside / max(left, right))
    # The scene's light: the cone more than triples the road's brightness; the HDR camera compresses that contrast
    # but keeps the cone clearly brighter.
    assert ratios[0] > 3.0
    assert ratios[0] > ratios[1] > 1.5


def test_street_lamp_pool_and_its_shadow(actors_factory):
    night = get_condition("night")
    cfg = night.street_lamps
    lamp = np.array([[10.0, 0.0, 7.0]])
    lights = street_lamp_lights(lamp, cfg, np.zeros(3))
    below = np.array([10.0, 0.0, 0.0])
    rays = down_ray(below)
    ambient = np.asarray(night.ambient_rgb)
    window = (1.0 - (7.0 / cfg.range_m) ** 4) ** 2
    lit = ALBEDO * (ambient + cfg.intensity * np.asarray(cfg.color_rgb) * window / 49.0) * night.exposure
    empty = FrameScene(StaticScene([ground()]), Actors.empty())
    np.testing.assert_allclose(shade(empty, rays, empty.cast_rays(rays), night, lights)[0], lit, rtol=1e-4)
    # A box between the lamp and the road (but not over the ray's start) shades the pool.
    blocker = FrameScene(StaticScene([ground()]), actors_factory([[10.0, 0.0, 4.0]], [[1.0, 1.0, 0.2]]))
    rays_below = np.array([[10.3, 0.3, 0.5, 0.0, 0.0, -1.0]], np.float32)  # starts under the box
    hits = blocker.cast_rays(rays_below)
    assert hits.instance_id[0] == 0
    np.testing.assert_allclose(shade(blocker, rays_below, hits, night, lights)[0],
                               ALBEDO * ambient * night.exposure, rtol=1e-4)


def test_oncoming_headlights_light_the_road_in_front_of_them(actors_factory):
    night = get_condition("night")
    oncoming = actors_factory([[30.0, 0.0, 0.75]], [[4.5, 1.8, 1.5]], yaws=np.array([np.pi]))
    lights = vehicle_headlights(oncoming, night.headlights, np.array([0.0, 0.0, 1.4]), np.array([1.0, 0.0, 0.0]))
    assert len(lights) == 1 and lights.axis[0, 0] < -0.99
    scene = FrameScene(StaticScene([ground()]), oncoming)
    rays = np.concatenate([down_ray(np.array([15.0, 0.0, 0.0])), down_ray(np.array([45.0, 0.0, 0.0]))])
    hits = scene.cast_rays(rays)
    out, unlit = shade(scene, rays, hits, night, lights), shade(scene, rays, hits, night)
    np.testing.assert_array_equal(out[1], unlit[1])  # behind the car: ambient only
    # In front: lit, by far more than the sensor's noise (0.0015 read noise x exposure 2.5) and 2/3 of the ambient.
    assert out[0, 0] - unlit[0, 0] > max(0.015, 0.66 * unlit[0, 0])
    behind = vehicle_headlights(oncoming, night.headlights, np.array([40.0, 0.0, 1.4]), np.array([1.0, 0.0, 0.0]))
    assert len(behind) == 0  # lamps behind the camera are left out


def test_lights_per_frame_are_bounded(actors_factory):
    night = get_condition("night")
    n = 60
    actors = actors_factory(np.column_stack([np.arange(n) * 6.0 + 10.0, np.zeros(n), np.full(n, 0.75)]),
                            [[4.5, 1.8, 1.5]] * n, yaws=np.full(n, np.pi))
    lamps = np.column_stack([np.arange(200) * 5.0, np.full(200, 6.0), np.full(200, 7.0)])
    lights = night.frame_lights(actors, EGO, np.array([0.6, 0.0, 1.4]), lamps)
    assert len(lights) == 1 + night.headlights.max_other_vehicles + night.street_lamps.max_lamps


def test_lit_windows_glow_with_the_lamps_only_when_lights_are_on():
    """A lit pane adds the NIGHT_GLOWS radiance times the condition's lamp_glow (times the exposure) when the lights are
    on, and nothing by day: by day it is glass like the others."""
    from pipeline.sensors.shading import NIGHT_GLOWS

    rgb, scale, actors_only = NIGHT_GLOWS["window_lit"]
    assert scale == "lamp_glow" and not actors_only
    rays = np.array([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]], np.float32)  # square onto a wall 10 m ahead
    for name, glows in (("night", True), ("dusk", True), ("morning", False)):
        cond = get_condition(name)
        dark = Condition(cond.config.model_copy(update={"vehicle_lights": cond.config.vehicle_lights.model_copy(
            update={"lamp_glow": 0.0})}))
        lit_scene = FrameScene(StaticScene([wall_mesh(10.0, material="window_lit")]), Actors.empty())
        out, off = (shade(lit_scene, rays, lit_scene.cast_rays(rays), c) for c in (cond, dark))
        added = np.asarray(rgb) * cond.lamp_glow * cond.exposure if glows else np.zeros(3)
        np.testing.assert_allclose(out[0] - off[0], added, rtol=1e-5, atol=1e-7)
