"""Which actors the rays of one frame can reach: the only ones the frame scene places and tests rays against.

Every actor costs its placed mesh (for its amodal box) and a test per ray that may meet it (see
:mod:`pipeline.world.actor_casts`), for the ~130 vehicles of a highway run or the ~220 of an urban one, where
most of them are behind buildings and far from the ego. :func:`actors_in_reach` is a conservative test of each
actor's bounding sphere (the sphere around its 3D box: a class's canonical mesh lies inside the unit box) against
every way a ray of the frame can meet it:

- a LiDAR beam: the sphere comes within the LiDAR's range under the condition (farther returns are dropped);
- a camera ray (primary or anti-aliasing sample): the sphere meets the camera's frustum, from its optical
  centre on (no near plane);
- a sun shadow ray from a point a camera sees: such a point lies below the actor away from the sun, no lower
  than the world's floor, so within the capsule that sweeps the sphere away from the sun down to the floor; that
  capsule (grown by the shadow rays' lift off their surface) meets the frustum;
- a shadow ray towards a spot light that casts shadows (street lamps at night): such a ray is shorter than the
  light's range, so the sphere comes within that range of the light;
- a sky-occlusion or mirror ray of a "realistic" camera (:mod:`pipeline.sensors.indirect`): such rays start at hits
  within INDIRECT_RANGE_M of the camera and meet nothing beyond MIRROR_RANGE_M (or AO_RADIUS_M), so the sphere comes
  within INDIRECT_REACH_M of the camera.

:class:`pipeline.world.scene.FrameScene` leaves the other actors out (``active``); they
keep their labels, which come from their boxes, and :func:`pipeline.sensors.groundtruth.project_actors` refuses
an actor a camera sees that was left out.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import Condition
from pipeline.sensors.indirect import INDIRECT_REACH_M
from pipeline.sensors.lidar import Lidar
from pipeline.world.actors import Actors

LIFT_MARGIN_M = 1.0  # shadow rays start this far off their surface at most (shading lifts them 1e-4 of t, + 1 mm)


def actors_in_reach(
    actors: Actors,
    ego_pose: Transform,
    cameras: list[Camera],
    lidars: list[Lidar],
    condition: Condition,
    *,
    floor_z_m: float,
    street_lights_m: np.ndarray | None = None,
    ego_size_m: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """(A,) bool: the actors that a ray of this frame (the rig's ``cameras`` and ``lidars`` on the ego at
    ``ego_pose``, under ``condition``) may meet; the others cannot be met (see the module docstring).

    ``floor_z_m``: no surface of the static world lies lower (e.g. :attr:`StaticScene.floor_z_m`);
    ``street_lights_m`` and ``ego_size_m`` as passed to :func:`pipeline.sensors.render.render_camera`.
    """
    n = len(actors)
    reach = np.zeros(n, bool)
    if not n:
        return reach
    centre = actors.boxes.center
    radius = 0.5 * np.linalg.norm(actors.boxes.size, axis=1) * 1.001 + 1e-3
    for lidar in lidars:
        origin = lidar.lidar_to_world(ego_pose).translation
        range_m = condition.lidar(lidar).range_m
        reach |= np.linalg.norm(centre - origin, axis=1) - radius <= range_m
    sun_shadows = condition.sun_shadows
    if sun_shadows:
        sun = condition.sun_direction.astype(np.float64)
        floor = min(floor_z_m, float(np.min(centre[:, 2] - 0.5 * actors.boxes.size[:, 2])))
        length = np.maximum(centre[:, 2] + radius - floor + LIFT_MARGIN_M, 0.0) / sun[2]
        shadow_end = centre - length[:, None] * sun
    for camera in cameras:
        cam_to_world = camera.camera_to_world(ego_pose)
        world_to_cam = cam_to_world.inverse()
        centre_cam = world_to_cam.apply(centre)
        reach |= camera.spheres_in_view(centre_cam, radius, near_m=0.0)
        if sun_shadows:
            reach |= camera.capsules_in_view(centre_cam, world_to_cam.apply(shadow_end), radius + LIFT_MARGIN_M,
                                             near_m=0.0)
        if camera.config.quality == "realistic":  # sky-occlusion and mirror rays (pipeline.sensors.indirect)
            reach |= np.linalg.norm(centre - cam_to_world.translation, axis=1) - radius <= INDIRECT_REACH_M
        lights = condition.frame_lights(actors, ego_pose, cam_to_world.translation, street_lights_m, ego_size_m)
        for k in np.flatnonzero(lights.shadows):
            reach |= np.linalg.norm(centre - lights.position_m[k], axis=1) - radius <= lights.range_m[k]
    return reach
