"""Which actors a frame's rays can reach (pipeline.sensors.reach): closed-form cases, and renders that the mask
leaves unchanged (real Embree scenes, with and without the actors it leaves out)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.geometry import Boxes3D, Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import Condition, get_condition
from pipeline.sensors.groundtruth import project_actors
from pipeline.sensors.lidar import Lidar, render_lidar
from pipeline.sensors.reach import actors_in_reach
from pipeline.sensors.render import render_camera
from pipeline.world.actors import Actors, place_actors
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene
from tests.sensors.conftest import camera_config, lidar_config, make_actors

EGO = Transform.from_xyz_rpy((0.0, 0.0, 0.75))
# Looks along +x: in view, |y| < x. Direct light only (the closed forms below); the realistic camera's sky-occlusion
# and mirror rays reach every actor within INDIRECT_REACH_M of it.
CAMERA = Camera(camera_config(width_px=160, height_px=120, hfov_deg=90.0, quality="fast"))
REALISTIC = Camera(camera_config(width_px=160, height_px=120, hfov_deg=90.0, quality="realistic"))
LIDAR = Lidar(lidar_config(channels=16, upper_fov_deg=2.0, lower_fov_deg=-20.0, horizontal_resolution_deg=1.0,
                          range_m=40.0, range_noise_std_m=0.0, dropout=0.0))
CAR = (4.5, 1.8, 1.5)


def ground(half_m: float = 400.0) -> Mesh:
    h = half_m
    v = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), material_index("concrete"), SemanticClass.ROAD)


STATIC = StaticScene([ground()])


def with_sun(name: str, azimuth_deg: float, elevation_deg: float):
    config = get_condition(name).config
    sun = config.sun.model_copy(update={"azimuth_deg": azimuth_deg, "elevation_deg": elevation_deg})
    return Condition(config.model_copy(update={"sun": sun}))


def reach(actors, condition, street_lights_m=None, camera=CAMERA):
    return actors_in_reach(actors, EGO, [camera], [LIDAR], condition, floor_z_m=STATIC.floor_z_m,
                           street_lights_m=street_lights_m)


def test_a_realistic_camera_reaches_actors_its_mirror_rays_can_meet(actors_factory):
    """Sky-occlusion and mirror rays start within INDIRECT_RANGE_M and end within MIRROR_RANGE_M: an actor behind the
    camera is reached up to INDIRECT_REACH_M (plus its sphere), not beyond."""
    from pipeline.sensors.indirect import INDIRECT_REACH_M

    camera_x = EGO.apply(CAMERA.mount.translation[None])[0, 0]
    r = 0.5 * np.linalg.norm(CAR)
    xs = [camera_x - INDIRECT_REACH_M - r + 0.5, camera_x - INDIRECT_REACH_M - r - 0.5]
    actors = actors_factory([[x, 0.0, 0.75] for x in xs], [CAR] * 2)
    night = get_condition("night")  # no sun: no shadows reach out of view
    assert reach(actors, night, camera=REALISTIC).tolist() == [True, False]
    assert reach(actors, night).tolist() == [False, False]


def test_actors_in_view_or_lidar_range_are_reached_and_far_ones_behind_are_not(actors_factory):
    actors = actors_factory([[30.0, 0.0, 0.75], [-20.0, 0.0, 0.75], [-100.0, 0.0, 0.75], [5.0, 60.0, 0.75]],
                            [CAR] * 4)
    # The sun ahead, high: shadows fall behind the actors, away from the camera's view.
    assert reach(actors, with_sun("noon", 0.0, 60.0)).tolist() == [True, True, False, False]


@pytest.mark.parametrize(("sun_azimuth_deg", "reached"), [(90.0, True), (-90.0, False)])
def test_an_actor_out_of_view_is_reached_where_its_shadow_falls_in_view(actors_factory, sun_azimuth_deg, reached):
    # 61 m away, to the left of the view (|y| > x). A low sun from the left (+y) throws its shadow ~8 m into the
    # view; from the right the shadow falls further left.
    actors = actors_factory([[40.0, 46.0, 0.75]], [CAR])
    condition = with_sun("morning", sun_azimuth_deg, 10.0)
    assert reach(actors, condition).tolist() == [reached]
    seen = render_camera(FrameScene(STATIC, actors), CAMERA, EGO, condition).rgb
    left_out = render_camera(FrameScene(STATIC, actors, active=np.array([False])), CAMERA, EGO, condition).rgb
    assert np.array_equal(seen, left_out) is not reached  # the shadow is in the image exactly when reached


def test_an_actor_out_of_view_is_reached_where_it_shadows_a_street_lamp_in_view():
    # A truck just left of the view (no LiDAR); a low, wide lamp further left lights the view, and the truck's
    # shadow from it falls there.
    night = get_condition("night")
    night = Condition(night.config.model_copy(update={"street_lamps": night.street_lamps.model_copy(
        update={"half_angle_deg": 80.0, "range_m": 40.0, "shadows": True})}))
    truck = make_actors([[12.0, 22.0, 2.0]], [(10.0, 2.5, 4.0)], classes=[ObjectClass.TRUCK])
    lamp = np.array([[12.0, 30.0, 5.0]])

    def reached(street_lights_m):
        return actors_in_reach(truck, EGO, [CAMERA], [], night, floor_z_m=0.0, street_lights_m=street_lights_m)

    assert reached(lamp).tolist() == [True]
    assert reached(None).tolist() == [False]  # without the lamp nothing reaches it
    images = [render_camera(FrameScene(STATIC, truck, active=active), CAMERA, EGO, night, street_lights_m=lamp).rgb
              for active in (None, np.array([False]))]
    assert np.count_nonzero(np.any(images[0] != images[1], axis=-1)) > 100  # its shadow is in the image


def random_actors(rng: np.random.Generator, n: int, scale: float = 1.0) -> Actors:
    """``n`` actors of random classes, sizes and headings: a third anywhere within 120 m, the others just outside
    the camera's view, beyond the LiDAR's range, where a shadow or a lamp decides whether they matter (distances x
    ``scale``)."""
    classes = [list(ObjectClass)[i] for i in rng.integers(0, len(ObjectClass), n)]
    size = np.column_stack([rng.uniform(0.5, 12.0, n), rng.uniform(0.5, 2.6, n), rng.uniform(1.0, 4.0, n)])
    anywhere = rng.uniform(-120.0, 120.0, (n, 2))
    side = rng.choice([-1.0, 1.0], n)  # along the left or right border of the view (|y| = x), then outwards
    along, out = rng.uniform(45.0, 120.0, n), rng.uniform(3.0, 15.0, n)
    near_border = np.column_stack([along - out, side * (along + out)]) / np.sqrt(2.0)
    xy = scale * np.where((np.arange(n) < n // 3)[:, None], anywhere, near_border)
    centre = np.column_stack([xy, 0.5 * size[:, 2]])
    return Actors(np.arange(1, n + 1), tuple(classes), Boxes3D(centre, size, rng.uniform(-np.pi, np.pi, n)),
                  rng.uniform(0.0, 1.0, (n, 3)), rng.random(n) < 0.5)


@pytest.mark.parametrize(("seed", "condition", "camera"), [(0, "morning", CAMERA), (1, "noon", CAMERA),
                                                        (2, "night", CAMERA), (3, "dusk", CAMERA),
                                                        (4, "morning", REALISTIC), (5, "noon", REALISTIC)])
def test_leaving_out_the_actors_out_of_reach_changes_no_output(seed, condition, camera):
    rng = np.random.default_rng(seed)
    # A realistic camera reaches all within INDIRECT_REACH_M (~120 m): spread them twice as far, so many are not.
    actors = random_actors(rng, 150, 1.0 if camera is CAMERA else 2.0)
    lamps = np.column_stack([rng.uniform(10.0, 90.0, 16), rng.uniform(-90.0, 90.0, 16), np.full(16, 8.0)])
    cond = get_condition(condition)
    if cond.sun_elevation_deg > 0:  # a low sun from anywhere: long shadows
        cond = with_sun(condition, float(rng.uniform(-180.0, 180.0)), float(rng.uniform(8.0, 20.0)))
    active = reach(actors, cond, street_lights_m=lamps, camera=camera)
    assert 0.2 * len(actors) < np.count_nonzero(~active)  # a test of something: many are left out
    full, culled = FrameScene(STATIC, actors), FrameScene(STATIC, actors, active=active)
    cams = [render_camera(s, camera, EGO, cond, street_lights_m=lamps) for s in (full, culled)]
    for field in ("rgb", "instance_id", "semantic", "depth_m"):
        assert np.array_equal(getattr(cams[0], field), getattr(cams[1], field)), field
    assert cams[0].labels.track_id.tolist() == cams[1].labels.track_id.tolist()
    sweeps = [render_lidar(s, LIDAR, EGO, np.random.default_rng(0), condition=cond) for s in (full, culled)]
    for field in ("points_m", "intensity", "instance_id", "points_per_actor"):
        assert np.array_equal(getattr(sweeps[0], field), getattr(sweeps[1], field)), field


def test_a_camera_refuses_an_actor_in_view_that_was_left_out(actors_factory):
    actors = actors_factory([[30.0, 0.0, 0.75], [-30.0, 0.0, 0.75]], [CAR] * 2)
    scene = FrameScene(STATIC, actors, active=np.array([False, True]))
    with pytest.raises(ValueError, match=r"sees actors \[1\].*left out"):
        project_actors(scene, CAMERA, CAMERA.camera_to_world(EGO))


def test_placing_some_actors_keeps_their_indices(actors_factory):
    actors = actors_factory([[0.0, 0.0, 0.75], [10.0, 0.0, 0.75], [20.0, 0.0, 0.75]], [CAR] * 3)
    some = place_actors(actors, where=np.array([True, False, True]))
    assert sorted(set(some.triangle_actor.tolist())) == [0, 2]
    assert len(some.triangles) == 2 * len(place_actors(actors).triangles) // 3
    with pytest.raises(ValueError, match=r"where must be \(3,\) bool"):
        place_actors(actors, where=np.array([True, False]))
    with pytest.raises(ValueError, match=r"active must be \(3,\) bool"):
        FrameScene(STATIC, actors, active=np.array([True, False]))
