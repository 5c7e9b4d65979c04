"""Render one camera frame: primary rays, shading, label images and ground-truth labels.

Label images (instance, semantic, depth) come from the pixel-centre rays. The colour image shades the
centre ray of every pixel; with ``samples_per_pixel`` N > 1, pixels on an edge (:func:`edge_pixels`: object,
class or material boundaries, silhouettes, creases: a small share of a frame) average N stratified rays
instead (all pixels with ``samples_everywhere``: for shadow edges too, at several times the cost; see
bench/bench_antialias.py); with the lights off, only the edges that show in the centres' image (more than
AA_MIN_CONTRAST 8-bit levels across a 3x3 window). Each ray is shaded
and fogged under the :class:`Condition` (sun, sky, and at night the frame's spot lights: headlights and street
lamps), then given the condition's post effects (:mod:`pipeline.sensors.post`: rain, motion blur, bloom,
flare, vignetting, noise) and tone-mapped. Depth is the
**z-depth** in the optical frame (metres along the camera's z axis, not along the ray), valid where
``depth_valid``; it is 0 elsewhere.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pipeline.core.geometry import Transform
from pipeline.core.jit import as_input, kernel
from pipeline.sensors.beams import beams
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import Condition, get_condition
from pipeline.sensors.exposure import auto_exposure
from pipeline.sensors.groundtruth import CameraLabels, camera_labels, project_actors
from pipeline.sensors.indirect import AO_FILTER_DEPTH, AO_FILTER_NORMAL_COS
from pipeline.sensors.post import apply_post, channel_max, motion_flow
from pipeline.sensors.rain import streak_coverage
from pipeline.sensors.shading import shade, shading_materials, sky, to_srgb8
from pipeline.sensors.shadows import (
    SHADOW_FILTER_DEPTH,
    SHADOW_FILTER_NORMAL_COS,
    borrowed_shares,
    pixel_shares,
    sun_shares,
)
from pipeline.sensors.spray import SprayClouds, camera_optical_depths
from pipeline.sensors.wet import road_reflections
from pipeline.world.scene import FrameScene, Hits, make_rays


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
    *,
    street_lights_m: np.ndarray | None = None,
    ego_speed_mps: float = 0.0,
    ego_size_m: tuple[float, float, float] | None = None,
    actor_velocity_mps: np.ndarray | None = None,
    spray: SprayClouds | None = None,
) -> CameraFrame:
    """Render ``camera`` on the ego at ``ego_pose`` (ego frame -> world, origin at the ego's box centre).

    The ego must not be one of the scene's actors (the camera would sit inside its mesh). ``condition``
    defaults to noon; ``rng`` draws the image noise, rain streaks and drops (none without it; labels never
    depend on it). ``street_lights_m`` (S, 3): the static world's lamp positions
    (:attr:`pipeline.world.static.StaticWorld.street_lights`), lit where the condition has street lamps;
    ``ego_speed_mps`` (forward) and ``actor_velocity_mps`` ((A, 3) world velocities of the scene's actors; None:
    they stand) move the image during the exposure (motion blur); ``ego_size_m``
    (length, width, height) places the ego's headlights (a 4.5 x 1.8 x 1.5 m car by default). ``spray``: the
    frame's spray clouds (:meth:`pipeline.sensors.conditions.Condition.spray`), which veil what lies behind them.
    """
    condition = get_condition("noon") if condition is None else condition
    h, w = camera.height, camera.width
    cam_to_world = camera.camera_to_world(ego_pose)
    amodal = project_actors(scene, camera, cam_to_world)
    actor_rays = amodal.pixel_mask(w, h)
    dirs_cam = camera.pixel_directions
    rays = make_rays(cam_to_world.translation, dirs_cam, cam_to_world.rotation)
    # Rays outside every static chunk's projection (most of the sky) cannot hit the static world: not cast.
    static_rays = camera.boxes_pixel_mask(cam_to_world, *scene.static.chunk_boxes)
    hits = scene.cast_rays(rays, actor_rays=actor_rays, static_rays=static_rays)

    actor_image, depth = _actor_image_and_depth(as_input(hits.instance_id, np.int32), as_input(hits.actor_index,
                                                np.int32), as_input(hits.hit, bool), as_input(hits.t_m, np.float32),
                                                as_input(dirs_cam, np.float32))
    labels = camera_labels(scene, camera, cam_to_world, amodal, actor_image.reshape(h, w), hits.semantic.reshape(h, w))

    lights = condition.frame_lights(scene.actors, ego_pose, cam_to_world.translation, street_lights_m, ego_size_m)
    samples = camera.sample_directions
    indirect = camera.config.quality == "realistic"
    texture_rad = 1.0 / camera.fx if indirect else 0.0  # the realistic camera textures the static world
    # The camera meters its frame and exposes it within its sensor's limits (pipeline.sensors.exposure), on the pixel
    # centres' radiance where it has it (so that anti-aliasing moves no exposure); the exposure time blurs motion, the
    # sensor's shot and read noise follow from the signal and the gain.
    sensor, compensation = camera.config.sensor, condition.exposure
    exposure = None
    # The wet road mirrors the scene (the realistic camera; the fast one adds the sky's sheen in shade).
    reflection = (road_reflections(scene, rays, hits, condition, lights, (h, w), camera.fy)
                  if indirect and condition.wetness > 0 else None)
    if len(samples) == 1:
        radiance = condition.fog(shade(scene, rays, hits, condition, lights, indirect, texture_rad, (h, w)),
                                 hits.t_m, hits.hit)
    else:
        # The pixel centres' share of the sun's disc, smoothed over penumbrae, lent to the samples on their surfaces.
        sunlit = _centre_sun_shares(scene, rays, hits, condition, (h, w), texture_rad) if indirect else None
        skylit = None
        # Every pixel gets its centre sample; pixels on an edge (edge_pixels) get the stratified samples instead.
        if camera.config.samples_everywhere:
            radiance, where = np.zeros((h * w, 3), np.float32), np.arange(h * w)
        else:
            # The centres' sky visibility (smoothed over each surface) is kept and lent on to the samples, as the sun.
            skylit = np.full(h * w, np.nan, np.float32) if indirect else None
            radiance = condition.fog(shade(scene, rays, hits, condition, lights, indirect, texture_rad, (h, w),
                                           sunlit, skylit), hits.t_m, hits.hit)
            where = np.flatnonzero(edge_pixels(hits, depth.reshape(h, w)))
            if reflection is not None:
                reflection.apply(radiance)
            exposure = auto_exposure(radiance.reshape(h, w, 3), sensor, compensation, shaded_with=compensation)
            if not condition.lights_on:
                # Only where the edge shows: an edge whose 3x3 window spans at most AA_MIN_CONTRAST 8-bit levels in
                # the centres' image (this exposure and tone curve) would average to within them. Not with the lights
                # on: a lamp smaller than a pixel, far off, shows in no centre, only in a sample (and then blooms).
                display = to_srgb8(radiance.reshape(h, w, 3) * np.float32(exposure.scale / compensation),
                                   "filmic" if indirect else "soft")
                where = where[window_contrast(display).reshape(-1)[where] > AA_MIN_CONTRAST]
        # The samples stacked into as few passes as hold no more rays than the centres' (fewer, larger casts; no
        # more memory), each sample shaded as if alone (``period``), summed in the samples' order.
        m, count = len(where), len(samples)
        per_pass = max(1, (h * w) // max(m, 1))
        edge = np.zeros((m, 3), np.float32)
        for first in range(0, count, per_pass):
            group = samples[first:first + per_pass]
            mask = np.tile(actor_rays.reshape(-1)[where], len(group))
            stacked = np.tile(where, len(group))
            sample_rays = make_rays(cam_to_world.translation, np.concatenate([sample[where] for sample in group]),
                                    cam_to_world.rotation)
            sample_hits = scene.cast_rays(sample_rays, mask)
            lent = None if sunlit is None else _lent(sunlit, hits, sample_hits, stacked, (h, w),
                                                     SHADOW_FILTER_NORMAL_COS, SHADOW_FILTER_DEPTH)
            lent_sky = None if skylit is None else _lent(skylit, hits, sample_hits, stacked, (h, w),
                                                         AO_FILTER_NORMAL_COS, AO_FILTER_DEPTH)
            shaded = condition.fog(shade(scene, sample_rays, sample_hits, condition, lights, indirect, texture_rad,
                                         sunlit=lent, sky_visible=lent_sky, period=m), sample_hits.t_m,
                                   sample_hits.hit)
            for k in range(len(group)):
                edge += shaded[k * m:(k + 1) * m]
        radiance[where] = edge / count
        if reflection is not None:  # the edge pixels' new radiance, on wet road, mirrors too
            reflection.apply(radiance, where if not camera.config.samples_everywhere else None)
    if reflection is not None and len(samples) == 1:
        reflection.apply(radiance)
    spray_t = None
    if spray is not None and len(spray):
        spray_t = _spray_veil(radiance, spray, rays, hits, camera, cam_to_world, condition)
    if condition.visibility_m is not None:  # lamps glow through fog and rain, and their beams show in it
        ends = np.where(hits.hit, hits.t_m, np.inf)
        glowing = hits.hit & shading_materials()["glows"][hits.material]
        condition.halos(radiance, ends, glowing, (h, w), camera.fy, spray_t)
        if len(lights):  # the ego's two headlamps apart: the camera sees the air just in front of them
            in_air = condition.frame_lights(scene.actors, ego_pose, cam_to_world.translation, street_lights_m,
                                            ego_size_m, ego_lamp_pair=True)
            radiance += beams(cam_to_world.translation, rays[:, 3:6], ends, (h, w), in_air,
                              condition.extinction_per_m()) * np.float32(condition.exposure)
    radiance = radiance.reshape(h, w, 3)
    if exposure is None:
        exposure = auto_exposure(radiance, sensor, compensation, shaded_with=compensation)
    gain = exposure.scale / compensation  # the radiance holds the compensation already
    shutter_s = exposure.time_s
    flow = None
    if ego_speed_mps != 0 or (actor_velocity_mps is not None and np.any(actor_velocity_mps)):
        shift_world = ego_pose.rotation[:, 0] * (ego_speed_mps * shutter_s)
        points = np.where(hits.hit[:, None], dirs_cam * hits.t_m[:, None], np.inf)
        shift_cam = cam_to_world.rotation.T @ shift_world
        if actor_velocity_mps is not None and len(actor_velocity_mps):
            # The camera moves relative to a road user by its own shift less the road user's.
            on_actor = np.flatnonzero(hits.instance_id > 0)
            shift_cam = np.broadcast_to(shift_cam, points.shape).copy()
            moved = np.asarray(actor_velocity_mps, np.float64)[hits.actor_index[on_actor]] * shutter_s
            shift_cam[on_actor] -= moved @ cam_to_world.rotation
        flow = motion_flow(points, shift_cam, camera.fx, camera.fy).reshape(h, w, 2)
        if float(np.abs(flow).max()) < MIN_BLUR_PX:  # a daylight exposure: no pixel moves visibly
            flow = None
    streaks, streak_light, streak_radiance, rain = None, None, 0.0, condition.rain
    if rain is not None and rng is not None:
        # Drops refract light from a wide cone: their radiance is about the mean of the sky's and the scene's.
        streak_radiance = 0.5 * (_sky_level(condition) + float(radiance.mean()))
        streaks, streak_light = streak_coverage(rain.rate_mm_h, rain.wind_mps, exposure.time_s, camera,
                                                cam_to_world, ego_pose.rotation[:, 0] * ego_speed_mps,
                                                depth.reshape(h, w), rng, lights)
    image = apply_post(radiance, condition.lens, rng, flow=flow, streaks=streaks, streak_radiance=streak_radiance,
                       streak_light=streak_light,
                       lens_drops=0 if rain is None else rain.drops, gain=gain,
                       psf_sigma_px=camera.config.psf_sigma_px, sensor=exposure)
    return CameraFrame(
        rgb=to_srgb8(image, "filmic" if indirect else "soft"),
        instance_id=hits.instance_id.reshape(h, w),
        semantic=hits.semantic.reshape(h, w),
        depth_m=depth.reshape(h, w),
        depth_valid=hits.hit.reshape(h, w),
        labels=labels,
        cam_to_world=cam_to_world,
    )


# Anti-aliasing samples go to the edge pixels whose 3x3 window in the pixel centres' 8-bit image spans more than this
# many levels in some channel (window_contrast): within it, the samples' mean would change the pixel by about a level,
# below the sensor's noise. With the lights on (dusk, night) every edge pixel is sampled.
AA_MIN_CONTRAST = 2
MIN_BLUR_PX = 0.25  # motion during the exposure below this everywhere is not blurred (it would not show)
# Edge tests between neighbouring pixel centres (see edge_pixels).
EDGE_INVERSE_DEPTH = 0.02  # |second difference of 1/z| over 1/z: 0 on any plane, large at a silhouette
EDGE_NORMAL_COS = 0.9  # normals of one actor's neighbouring pixels further apart than this: a body crease


def edge_pixels(hits: Hits, depth_m: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels whose colour may change within the pixel, found from the centre rays (``hits``, H*W
    of them, and their (H, W) z-depth ``depth_m``, 0 where nothing was hit). A pixel is on an edge where its
    hit object, semantic class, material or hit/miss differs from a 4-neighbour's; where the surface bends
    or breaks off (second difference of the inverse depth along a row or column beyond EDGE_INVERSE_DEPTH of
    it: zero on a plane at any slant, so the road far ahead is not an edge); or, on actors, where the normal
    turns by more than arccos(EDGE_NORMAL_COS). The set is grown by one pixel (3x3) so both sides of every
    edge are sampled. Shadow and light-cone boundaries within one surface are not edges here."""
    h, w = depth_m.shape
    ids = (hits.instance_id.astype(np.int64) << 24 | hits.semantic.astype(np.int64) << 16
           | hits.material.astype(np.int64)).reshape(h, w)
    inv = np.where(depth_m > 0, 1.0 / np.maximum(depth_m, 1e-6), 0.0).astype(np.float32)
    normal = hits.normal.reshape(h, w, 3)
    on_actor = (hits.instance_id > 0).reshape(h, w)
    edge = np.zeros((h, w), bool)
    for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                 ((slice(None), slice(None, -1)), (slice(None), slice(1, None)))):
        jump = (ids[a] != ids[b]) | (on_actor[a] & (np.einsum("ijk,ijk->ij", normal[a], normal[b]) < EDGE_NORMAL_COS))
        edge[a] |= jump
        edge[b] |= jump
    for bend in (np.abs(inv[:-2] - 2 * inv[1:-1] + inv[2:]) > EDGE_INVERSE_DEPTH * inv[1:-1],
                 np.abs(inv[:, :-2] - 2 * inv[:, 1:-1] + inv[:, 2:]) > EDGE_INVERSE_DEPTH * inv[:, 1:-1]):
        core = (slice(1, -1), slice(None)) if bend.shape[0] == h - 2 else (slice(None), slice(1, -1))
        edge[core] |= bend
    return cv2.dilate(edge.view(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)


def window_contrast(image: np.ndarray) -> np.ndarray:
    """(H, W) uint8: for each pixel of an (H, W, 3) uint8 image, the greatest spread (brightest less darkest) over
    its 3x3 window (clipped to the image), over the channels."""
    kernel3 = np.ones((3, 3), np.uint8)
    return channel_max(cv2.dilate(image, kernel3) - cv2.erode(image, kernel3))


def _centre_sun_shares(scene: FrameScene, rays: np.ndarray, hits: Hits, condition: Condition,
                       image_shape: tuple[int, int], pixel_angle_rad: float) -> np.ndarray:
    """(H * W,) float32: the share of the sun's disc each pixel centre's hit sees, smoothed over penumbrae
    (:func:`pipeline.sensors.shadows.sun_shares`); NaN where the hit does not face the sun."""
    _, lit, share = sun_shares(scene, rays, hits, condition, condition.sun_disc, image_shape, pixel_angle_rad)
    return pixel_shares(len(rays), lit, share)


def _lent(centre: np.ndarray, hits: Hits, sample_hits: Hits, where: np.ndarray, image_shape: tuple[int, int],
          normal_cos: float, depth: float) -> np.ndarray:
    """(K,) float32: for the samples of the pixels ``where``, the ``centre`` value (per pixel centre, smoothed over
    its surface) of the pixel or a neighbour on the sample's surface, by the smoothing's own test of a surface
    (``normal_cos``, ``depth``: :func:`pipeline.sensors.shadows.borrowed_shares`); NaN where there is none (the
    sample traces its own). The sun's share lends with the penumbra filter's test, the sky's visibility with the
    occlusion filter's."""
    h, w = image_shape
    return borrowed_shares(centre, as_input(hits.instance_id, np.int32), as_input(hits.normal, np.float32),
                           as_input(hits.t_m, np.float32), as_input(where, np.int64),
                           as_input(sample_hits.instance_id, np.int32), as_input(sample_hits.normal, np.float32),
                           np.where(sample_hits.hit, sample_hits.t_m, 0.0).astype(np.float32), h, w,
                           np.float32(normal_cos), np.float32(depth))


def _spray_veil(radiance: np.ndarray, clouds: SprayClouds, rays: np.ndarray, hits: Hits, camera: Camera,
                cam_to_world: Transform, condition: Condition) -> np.ndarray:
    """Dim, in place, the (H*W, 3) ``radiance`` of the pixels whose centre ray passes a spray cloud before its hit by
    its transmittance T = exp(-tau) and add the airlight's (1 - T) (:mod:`pipeline.sensors.spray`): the droplets
    scatter the same light as the fog's and the rain's. Returns each pixel's T, (H*W,) float32 (1 where no cloud)."""
    rows, tau = camera_optical_depths(clouds, camera, cam_to_world, rays, np.where(hits.hit, hits.t_m, np.inf))
    met = tau > 0
    rows, transmittance = rows[met], np.exp(-tau[met])[:, None]
    air = np.asarray(condition.airlight_rgb, np.float32) * np.float32(condition.exposure)
    radiance[rows] = radiance[rows] * transmittance + air * (np.float32(1.0) - transmittance)
    every = np.ones(len(rays), np.float32)
    every[rows] = transmittance[:, 0]
    return every


def _sky_level(condition: Condition) -> float:
    """Mean radiance of the sky near the horizon as the camera sees it (the airlight in fog), with the exposure
    compensation: over 8 azimuths, the directions' z = 0.1 (a daylight sky is brighter towards the sun; a gradient is
    the same all round)."""
    if condition.fog_visibility_m is not None:
        level = float(np.mean(condition.airlight_rgb))
    else:
        azimuth = np.arange(8) * (np.pi / 4)
        flat = np.sqrt(1.0 - 0.1 ** 2)
        around = np.column_stack([flat * np.cos(azimuth), flat * np.sin(azimuth), np.full(8, 0.1)])
        level = float(sky(around.astype(np.float32), condition).mean(axis=0).mean())
    return level * condition.exposure


@kernel("Tuple((int32[::1], float32[::1]))(int32[::1], int32[::1], bool_[::1], float32[::1], float32[:, ::1])")
def _actor_image_and_depth(instance_id, actor_index, hit, t_m, directions):
    """Per pixel-centre ray: the hit actor's dense index + 1 (0: no actor) and the z-depth t * d_z (0: no hit),
    from the (N,) hits and the (N, 3) float32 unit ray directions in the optical frame."""
    n = hit.size
    actor_image = np.zeros(n, np.int32)
    depth = np.zeros(n, np.float32)
    for i in range(n):
        if instance_id[i] > 0:
            actor_image[i] = actor_index[i] + 1
        if hit[i]:
            depth[i] = t_m[i] * directions[i, 2]
    return actor_image, depth
