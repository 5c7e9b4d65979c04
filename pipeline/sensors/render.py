"""Render one camera frame: primary rays, shading, label images and ground-truth labels.

Label images (instance, semantic, depth) come from the pixel-centre rays; the colour image averages
``samples_per_pixel`` stratified rays (reusing the centre rays when there is one sample), each shaded
and fogged under the :class:`Condition`, then noised and tone-mapped. Depth is the
**z-depth** in the optical frame (metres along the camera's z axis, not along the ray), valid where
``depth_valid``; it is 0 elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.geometry import Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import CONDITIONS, Condition
from pipeline.sensors.groundtruth import CameraLabels, camera_labels, project_actors
from pipeline.sensors.shading import shade, to_srgb8
from pipeline.world.scene import FrameScene, make_rays


@dataclass(frozen=True)
class CameraFrame:
    """One rendered camera frame (H x W).

    Attributes:
        rgb: (H, W, 3) uint8 sRGB.
        instance_id: (H, W) int32 actor track id, 0 = background.
        semantic: (H, W) uint8 :class:`SemanticClass` value, 0 = nothing (sky).
        depth_m: (H, W) float32 z-depth in the optical frame, metres; 0 where not ``depth_valid``.
        depth_valid: (H, W) bool, the pixel-centre ray hit something.
        labels: the frame's :class:`CameraLabels`.
        cam_to_world: optical frame -> world at this frame.
    """

    rgb: np.ndarray
    instance_id: np.ndarray
    semantic: np.ndarray
    depth_m: np.ndarray
    depth_valid: np.ndarray
    labels: CameraLabels
    cam_to_world: Transform


def render_camera(
    scene: FrameScene,
    camera: Camera,
    ego_pose: Transform,
    condition: Condition | None = None,
    rng: np.random.Generator | None = None,
) -> CameraFrame:
    """Render ``camera`` on the ego at ``ego_pose`` (ego frame -> world) in ``scene``.

    The ego must not be one of the scene's actors (the camera would sit inside its mesh). ``condition``
    defaults to noon; ``rng`` draws the image noise (none without it, so labels never depend on it).
    """
    condition = CONDITIONS["noon"] if condition is None else condition
    lighting = condition.lighting
    h, w = camera.height, camera.width
    cam_to_world = camera.camera_to_world(ego_pose)
    amodal = project_actors(scene, camera, cam_to_world)
    actor_rays = amodal.pixel_mask(w, h)
    dirs_cam = camera.pixel_directions
    rays = make_rays(cam_to_world.translation, dirs_cam, cam_to_world.rotation)
    hits = scene.cast_rays(rays, actor_rays=actor_rays)

    actor_image = np.where(hits.instance_id > 0, hits.actor_index + 1, 0).astype(np.int32).reshape(h, w)
    labels = camera_labels(scene, camera, cam_to_world, amodal, actor_image)
    depth = np.where(hits.hit, hits.t_m * dirs_cam[:, 2], 0.0).astype(np.float32)

    samples = camera.sample_directions
    if len(samples) == 1:
        radiance = condition.fog(shade(scene, rays, hits, lighting), hits.t_m, hits.hit)
    else:
        radiance = np.zeros((h * w, 3), np.float32)
        for sample in samples:  # loop over samples; all pixels vectorised
            sample_rays = make_rays(cam_to_world.translation, sample, cam_to_world.rotation)
            sample_hits = scene.cast_rays(sample_rays, actor_rays)
            radiance += condition.fog(shade(scene, sample_rays, sample_hits, lighting), sample_hits.t_m,
                                      sample_hits.hit)
        radiance /= len(samples)
    if rng is not None:
        radiance = condition.noisy(radiance, rng)
    return CameraFrame(
        rgb=to_srgb8(radiance.reshape(h, w, 3)),
        instance_id=hits.instance_id.reshape(h, w),
        semantic=hits.semantic.reshape(h, w),
        depth_m=depth.reshape(h, w),
        depth_valid=hits.hit.reshape(h, w),
        labels=labels,
        cam_to_world=cam_to_world,
    )
