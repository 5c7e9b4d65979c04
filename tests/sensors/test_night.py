"""Night: darker than morning, headlight cones and street-lamp pools in closed form, shadows, bounded lights."""

from __future__ import annotations

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.core.geometry import Transform
from pipeline.core.photometry import lux_to_irradiance
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


def night_without_others():
    """Night with the ego's headlights only."""
    night = get_condition("night")
    headlights = night.headlights.model_copy(update={"others": False})
    return Condition(night.config.model_copy(update={"headlights": headlights}))


def down_ray(point: np.ndarray) -> np.ndarray:
    """A ray from 1 m above ``point`` straight down onto it."""
    return np.array([[point[0], point[1], point[2] + 1.0, 0.0, 0.0, -1.0]], np.float32)


def test_night_is_darker_than_morning(actors_factory, wall):
    """The night's lights are physical and the camera's exposure bounded (pipeline.sensors.exposure): lit by the
    ego's low beams alone, the frame is less than half as bright as the morning's, although the camera meters at
    its longest exposure and highest gain."""
    actors = actors_factory([[15.0, 1.0, 0.75], [30.0, -3.0, 0.75]], [[4.5, 1.8, 1.5]] * 2, brake=[True, False])
    scene = FrameScene(StaticScene([wall(60.0), ground()]), actors)
    cam = Camera(camera_config(width_px=160, height_px=120))
    morning = render_camera(scene, cam, EGO, get_condition("morning")).rgb.mean()
    night = render_camera(scene, cam, EGO, night_without_others()).rgb.mean()
    assert night < 0.5 * morning


def low_beam_pattern(cfg, below_cutoff_deg: float, side_deg: float) -> float:
    """The beam pattern of a headlight config in closed form (the config's definitions, not the code's)."""
    vertical = min(1.0, cfg.peak_band_deg / below_cutoff_deg) ** cfg.vertical_falloff
    if cfg.horizontal_falloff_deg is None:
        return vertical
    floor = cfg.horizontal_floor
    return vertical * (floor + (1 - floor) * np.exp(-((side_deg / cfg.horizontal_falloff_deg) ** 2)))


def test_headlight_on_axis_irradiance_is_closed_form():
    # The ego's low beam (one light of two lamps) hits the road where its axis, pitched down by p, meets it:
    # there the cone factor is 1 and E = 2 I rgb pattern sin(p) window(s) / s^2, s the distance along the axis,
    # with the pattern of a direction half_angle_up below the cut-off, straight ahead.
    night = night_without_others()
    cfg = night.headlights
    assert cfg.vertical_falloff > 0 and cfg.horizontal_falloff_deg is not None  # the shipped night has a pattern
    light = ego_headlights(EGO, cfg)
    # The beam, and the light above its cut-off, whose cone starts at the beam's axis (adds nothing there).
    assert len(light) == 2 and cfg.above_cutoff_share > 0
    p = np.radians(cfg.pitch_down_deg)
    s = light.position_m[0, 2] / np.sin(p)
    on_axis = light.position_m[0] + light.axis[0] * s
    assert abs(on_axis[2]) < 1e-9
    scene = FrameScene(StaticScene([ground()]), Actors.empty())
    rays = down_ray(on_axis)
    out = shade(scene, rays, scene.cast_rays(rays), night, light)
    window = (1.0 - (s / cfg.range_m) ** 4) ** 2
    pattern = low_beam_pattern(cfg, cfg.half_angle_up_deg, 0.0)
    irradiance = 2.0 * cfg.intensity * np.asarray(cfg.color_rgb) * pattern * np.sin(p) * window / s**2
    ambient = np.asarray(night.ambient_rgb)
    expected = ALBEDO * (ambient + irradiance) * night.exposure
    np.testing.assert_allclose(out[0], expected, rtol=1e-4)
    # Beyond the horizontal half-angle: no headlight at all, only the ambient light.
    angle = np.radians(cfg.half_angle_h_deg + 5.0)
    outside = np.array([s * np.cos(angle), s * np.sin(angle), 0.0])
    rays = down_ray(outside)
    out = shade(scene, rays, scene.cast_rays(rays), night, light)
    np.testing.assert_allclose(out[0], ALBEDO * ambient * night.exposure, rtol=1e-5)


def test_the_light_above_the_cut_off_is_closed_form_on_a_wall_ahead():
    # A matte wall 8 m ahead of the lamps, facing them (the back of a van). On the axis of the light above the
    # cut-off (half way from the beam's axis to above_cutoff_deg over the cut-off), well above the cut-off, the
    # beam itself gives nothing and that light E = share 2 I rgb cos(i) window(d) / d^2; without it (share 0) the
    # wall there has the ambient light only. At the foot of the wall the beam lights it as before.
    night = night_without_others()
    cfg = night.headlights
    no_stray = cfg.model_copy(update={"above_cutoff_share": 0.0})
    beam = ego_headlights(EGO, no_stray)
    lamp = beam.position_m[0]
    cutoff_deg = cfg.half_angle_up_deg - cfg.pitch_down_deg  # the cut-off above the horizontal
    tilt = np.radians(-cfg.pitch_down_deg + 0.5 * (cfg.half_angle_up_deg + cfg.above_cutoff_deg))
    ahead = 8.0
    point = lamp + [ahead, 0.0, ahead * np.tan(tilt)]
    assert np.degrees(tilt) > cutoff_deg + 2.0  # well above the cut-off
    scene = FrameScene(StaticScene([wall_mesh(point[0])]), Actors.empty())
    rays = np.array([[0.0, 0.0, point[2], 1.0, 0.0, 0.0]], np.float32)
    hits = scene.cast_rays(rays)
    ambient = ALBEDO * np.asarray(night.ambient_rgb) * night.exposure
    np.testing.assert_allclose(shade(scene, rays, hits, night, beam)[0], ambient, rtol=1e-5)
    d = ahead / np.cos(tilt)
    window = (1.0 - (d / cfg.range_m) ** 4) ** 2
    stray = cfg.above_cutoff_share * 2.0 * cfg.intensity * np.asarray(cfg.color_rgb) * np.cos(tilt) * window / d**2
    out = shade(scene, rays, hits, night, ego_headlights(EGO, cfg))[0]
    np.testing.assert_allclose(out, ambient + ALBEDO * stray * night.exposure, rtol=1e-4)
    assert (out > 3.0 * ambient).all()  # far more than the ambient light: the wall reads at night
    # On the ground in front of the wall, in the beam: the beam's light, the light above the cut-off adding < 1 %.
    low = np.array([[0.0, 0.0, lamp[2] - 0.2, 1.0, 0.0, 0.0]], np.float32)
    low_hits = scene.cast_rays(low)
    with_stray = shade(scene, low, low_hits, night, ego_headlights(EGO, cfg))[0]
    beam_only = shade(scene, low, low_hits, night, beam)[0]
    assert (beam_only > 100.0 * ambient).all() and (with_stray >= beam_only).all()
    np.testing.assert_allclose(with_stray, beam_only, rtol=cfg.above_cutoff_share)


def test_road_in_the_ego_headlight_cone_is_brighter_than_outside():
    cam = Camera(camera_config(width_px=320, height_px=240, hfov_deg=120.0,
                              mount={"xyz_m": (0.6, 0.0, 0.65)}))
    scene = FrameScene(StaticScene([ground(material="asphalt")]), Actors.empty())
    world_to_cam = cam.camera_to_world(EGO).inverse()
    uv, _ = cam.project(world_to_cam.apply(np.array([[12.0, 0.0, 0.0], [8.0, 9.0, 0.0], [8.0, -9.0, 0.0]])))
    grey = render_camera(scene, cam, EGO, night_without_others()).rgb.astype(float).mean(axis=2)
    inside, left, right = (grey[int(v), int(u)] for u, v in uv)
    # The cone more than triples the road's brightness in the image.
    assert inside > 3.0 * max(left, right)


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
    assert len(lights) == 2 and lights.axis[0, 0] < -0.99  # its beam and the light above its cut-off
    scene = FrameScene(StaticScene([ground()]), oncoming)
    rays = np.concatenate([down_ray(np.array([15.0, 0.0, 0.0])), down_ray(np.array([45.0, 0.0, 0.0]))])
    hits = scene.cast_rays(rays)
    out, unlit = shade(scene, rays, hits, night, lights), shade(scene, rays, hits, night)
    np.testing.assert_array_equal(out[1], unlit[1])  # behind the car: ambient only
    # In front: lit by more than 1 lx (a few lx: the beam well below its cut-off, 15 m away) and 2/3 of the ambient.
    assert out[0, 0] - unlit[0, 0] > max(lux_to_irradiance(1.0) * ALBEDO[0], 0.66 * unlit[0, 0])
    behind = vehicle_headlights(oncoming, night.headlights, np.array([40.0, 0.0, 1.4]), np.array([1.0, 0.0, 0.0]))
    assert len(behind) == 0  # lamps behind the camera are left out


def test_parked_vehicles_lamps_and_beams_are_off(actors_factory):
    # Two cars facing the camera side by side, one with its lights on, one parked (lights off), and two seen from
    # behind likewise: at night only the first of each pair glows (head lamps; tail lamps and the lit plate) and
    # casts low beams.
    night = get_condition("night")
    actors = actors_factory([[20.0, -2.0, 0.75], [20.0, 2.0, 0.75], [20.0, -6.0, 0.75], [20.0, 6.0, 0.75]],
                            [[4.5, 1.8, 1.5]] * 4, yaws=np.array([np.pi, np.pi, 0.0, 0.0]),
                            lights_on=[True, False, True, False])
    lights = vehicle_headlights(actors, night.headlights, np.array([0.0, 0.0, 1.4]), np.array([1.0, 0.0, 0.0]))
    # The two with their lights on (each a beam and the light above its cut-off).
    np.testing.assert_allclose(np.sort(lights.position_m[:, 1]), [-6.0, -6.0, -2.0, -2.0])
    scene = FrameScene(StaticScene([]), actors)
    geo = scene.geometry
    for name in ("headlight", "taillight", "plate_rear"):
        rays = []
        for k in range(4):
            tri = np.flatnonzero((geo.triangle_actor == k) & (geo.triangle_material == material_index(name)))
            if not len(tri):
                rays.append(None)
                continue
            centroid = geo.vertices[geo.triangles[tri]].mean(axis=1)
            target = centroid[np.argmax(np.abs(centroid[:, 0] - 20.0))]  # on the face at the box's end
            origin = target + [(-3.0 if target[0] < 20.0 else 3.0), 0.0, 0.0]
            rays.append(np.concatenate([origin, (target - origin) / np.linalg.norm(target - origin)]))
        pairs = [(0, 1), (2, 3)] if name == "headlight" else [(2, 3), (0, 1)]
        k_on, k_off = pairs[0]
        r = np.asarray([rays[k_on], rays[k_off]], np.float32)
        hits = scene.cast_rays(r)
        assert (hits.material == material_index(name)).all() and hits.actor_index.tolist() == [k_on, k_off]
        lit, dark = shade(scene, r, hits, night)
        assert lit.sum() > 10 * dark.sum(), name  # the lamp's glow (or the plate lamp's light) is on one car only


def test_lights_per_frame_are_bounded(actors_factory):
    night = get_condition("night")
    n = 60
    actors = actors_factory(np.column_stack([np.arange(n) * 6.0 + 10.0, np.zeros(n), np.full(n, 0.75)]),
                            [[4.5, 1.8, 1.5]] * n, yaws=np.full(n, np.pi))
    lamps = np.column_stack([np.arange(200) * 5.0, np.full(200, 6.0), np.full(200, 7.0)])
    lights = night.frame_lights(actors, EGO, np.array([0.6, 0.0, 1.4]), lamps)
    # Each vehicle's beam and the light above its cut-off (two lights), the lamps.
    assert len(lights) == 2 * (1 + night.headlights.max_other_vehicles) + night.street_lamps.max_lamps


def test_low_beam_pattern_is_closed_form_across_and_down_the_beam():
    # Road points at several distances and bearings: the headlight's share of the light (the night minus the same
    # night without headlights) over the uniform cone's (the pattern switched off) is the pattern of the direction
    # from the lamp, from the config's definitions: peak band, vertical fall-off, horizontal Gaussian with a floor.
    night = night_without_others()
    cfg = night.headlights
    uniform = cfg.model_copy(update={"vertical_falloff": 0.0, "horizontal_falloff_deg": None})
    dark = Condition(night.config.model_copy(update={"headlights": None}))
    scene = FrameScene(StaticScene([ground()]), Actors.empty())
    lamp = ego_headlights(EGO, cfg).position_m[0]
    cutoff_above_horizon_deg = cfg.half_angle_up_deg - cfg.pitch_down_deg
    for ahead_m, side_deg in ((12.0, 0.0), (25.0, 6.0), (40.0, 12.0), (70.0, 3.0), (8.0, 20.0)):
        bearing = np.radians(side_deg)
        point = lamp + ahead_m * np.array([np.cos(bearing), np.sin(bearing), 0.0])
        point[2] = 0.0
        rays = down_ray(point)
        hits = scene.cast_rays(rays)
        base = shade(scene, rays, hits, dark)[0]
        lit = shade(scene, rays, hits, night, ego_headlights(EGO, cfg))[0] - base
        flat = shade(scene, rays, hits, night, ego_headlights(EGO, uniform))[0] - base
        # Angles of the direction lamp -> point in the beam's frame (pitched down, so "side" is about its up axis).
        light = ego_headlights(EGO, cfg)
        d = point - lamp
        axial = d @ light.axis[0]
        left = np.cross(light.up[0], light.axis[0])
        side = np.degrees(np.arctan(abs(d @ left) / axial))
        below_cutoff = cfg.half_angle_up_deg - np.degrees(np.arctan((d @ light.up[0]) / axial))
        expected = low_beam_pattern(cfg, below_cutoff, side)
        np.testing.assert_allclose(lit / flat, expected, rtol=2e-3)
        assert below_cutoff > cutoff_above_horizon_deg  # every point is on the road, below the horizontal


def test_retroreflection_is_closed_form_and_returns_towards_the_lamp():
    # A marking lit by the ego's lamp, seen from a camera beside the lamp and from one far from it: the retroreflected
    # term is pi R f(alpha) E_perp albedo / max(albedo), f = (1.05 deg / max(alpha, 0.5 deg)) exp(-(alpha / 6 deg)^2),
    # alpha the angle at the marking between the lamp and the camera, E_perp the irradiance across the lamp's ray.
    night = night_without_others()
    cfg = night.headlights
    light = ego_headlights(EGO, cfg)
    paint = material_arrays()
    k = material_index("lane_paint")
    albedo, r_l = paint["albedo"][k], paint["retroreflection"][k]
    assert r_l > 0 and paint["retroreflection"][material_index("concrete")] == 0
    lamp = light.position_m[0]
    marking = np.array([lamp[0] + 30.0, 0.0, 0.0])
    dark = Condition(night.config.model_copy(update={"headlights": None}))
    out = {}
    for name, eye in (("beside", lamp + [-1.7, 0.0, 0.8]), ("far", marking + [-10.0, 12.0, 6.0])):
        scene = FrameScene(StaticScene([ground(material="lane_paint")]), Actors.empty())
        direction = (marking - eye) / np.linalg.norm(marking - eye)
        rays = np.array([[*eye, *direction]], np.float32)
        hits = scene.cast_rays(rays)
        added = shade(scene, rays, hits, night, light)[0] - shade(scene, rays, hits, dark)[0]
        to_lamp, to_eye = lamp - marking, eye - marking
        dist = np.linalg.norm(to_lamp)
        cos_alpha = to_lamp @ to_eye / (dist * np.linalg.norm(to_eye))
        alpha = np.degrees(np.arccos(cos_alpha))
        beam = -to_lamp  # lamp -> marking
        below_cutoff = cfg.half_angle_up_deg - np.degrees(np.arctan((beam @ light.up[0]) / (beam @ light.axis[0])))
        e_perp = 2.0 * cfg.intensity * np.asarray(cfg.color_rgb) * low_beam_pattern(cfg, below_cutoff, 0.0) * (
            1.0 - (dist / cfg.range_m) ** 4) ** 2 / dist**2
        diffuse = albedo * e_perp * to_lamp[2] / dist
        retro = np.pi * r_l * (1.05 / max(alpha, 0.5)) * np.exp(-((alpha / 6.0) ** 2)) * e_perp * albedo / albedo.max()
        np.testing.assert_allclose(added, (diffuse + retro) * night.exposure, rtol=2e-3)
        out[name] = added.mean()
    # Seen from beside the lamp the marking returns many times its diffuse light; seen from far off, almost none.
    assert out["beside"] > 5.0 * out["far"]


def test_lit_windows_glow_with_the_lamps_only_when_lights_are_on():
    """A lit pane adds its room's light (the NIGHT_LIT irradiance times the pane's albedo, times the condition's
    lamp_glow and the exposure) when the lights are on, and nothing by day: by day it is glass like the others."""
    from pipeline.sensors.shading import NIGHT_LIT

    rgb, scale, actors_only = NIGHT_LIT["window_lit"]
    assert scale == "lamp_glow" and not actors_only
    albedo = material_arrays()["albedo"][material_index("window_lit")]
    rays = np.array([[0.0, 0.0, 1.0, 1.0, 0.0, 0.0]], np.float32)  # square onto a wall 10 m ahead
    for name, glows in (("night", True), ("dusk", True), ("morning", False)):
        cond = get_condition(name)
        dark = Condition(cond.config.model_copy(update={"vehicle_lights": cond.config.vehicle_lights.model_copy(
            update={"lamp_glow": 0.0})}))
        lit_scene = FrameScene(StaticScene([wall_mesh(10.0, material="window_lit")]), Actors.empty())
        out, off = (shade(lit_scene, rays, lit_scene.cast_rays(rays), c) for c in (cond, dark))
        added = albedo * np.asarray(rgb) * cond.lamp_glow * cond.exposure if glows else np.zeros(3)
        np.testing.assert_allclose(out[0] - off[0], added, rtol=1e-5, atol=1e-7)


def test_the_compiled_light_pass_is_the_numpy_definition_term_by_term():
    """_lit_pairs against spot_strength (cone, window, inverse square, beam pattern) times n.l / d, for the ego's
    low beams and a street lamp, on random hits: the same float32 values where both keep a pair."""
    from pipeline.sensors.lights import _lit_pairs, light_params, spot_strength

    condition = get_condition("night")
    lights = ego_headlights(Transform.from_xyz_rpy([0.0, 0.0, 0.75], [0.0, 0.0, 0.2]), condition.headlights)
    lights = lights.concatenate([lights, street_lamp_lights(np.array([[12.0, 4.0, 6.7]]), condition.street_lamps,
                                                            np.zeros(3))])
    rng = np.random.default_rng(3)
    m = 20000
    pos = rng.uniform([-2, -15, 0], [60, 15, 3], (m, 3)).astype(np.float32).T.copy()
    nrm = rng.normal(size=(m, 3)).astype(np.float32)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = nrm.T.copy()
    view = -pos / np.linalg.norm(pos, axis=0, keepdims=True)
    retro = np.zeros(m, np.float32)
    specular, shininess = np.zeros(m, np.float32), np.ones(m, np.float32)
    everyone = np.arange(m, dtype=np.int64)
    for k in range(len(lights)):
        kept, w, s, start, seg = _lit_pairs(everyone, pos, nrm, view.astype(np.float32), retro, everyone, specular,
                                            shininess, light_params(lights, k))
        assert len(kept) > 100 and not s.any()
        v = [np.float32(lights.position_m[k, c]) - pos[c, kept] for c in range(3)]
        d2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
        axial = -(v[0] * np.float32(lights.axis[k, 0]) + v[1] * np.float32(lights.axis[k, 1])
                  + v[2] * np.float32(lights.axis[k, 2]))
        n_dot_v = nrm[0, kept] * v[0] + nrm[1, kept] * v[1] + nrm[2, kept] * v[2]
        want = spot_strength(lights, k, v, d2, axial) * n_dot_v * (1.0 / np.sqrt(d2))
        assert np.allclose(w, want, rtol=2e-6, atol=0)
        assert np.allclose(seg, np.stack(v, axis=1) * (1.0 - 0.05 / np.sqrt(d2))[:, None], rtol=1e-6)
        assert np.array_equal(start, (pos[:, kept] + nrm[:, kept] * np.float32(2e-3)).T)
