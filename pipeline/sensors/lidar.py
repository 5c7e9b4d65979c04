"""Rotating LiDAR: ray pattern, intensity model, noise and drop-out; points in the LiDAR frame.

Conventions:

- LiDAR frame: x forward, y left, z up (KITTI velodyne); ``mount`` is its pose in the ego frame.
- Rings: ring 0 is the highest beam (``upper_fov_deg``), ring ``channels - 1`` the lowest; beams are
  evenly spaced in elevation.
- Columns: the head turns clockwise seen from above, starting behind the sensor: column j has azimuth
  pi - j * resolution (CCW from +x) and fires at time j / (columns * rotation_hz) after the sweep start.
  The whole sweep uses one ego pose (no motion distortion).
- Ray order: column-major, ray index = column * channels + ring.
- Intensity I = I0 * exp(-a * d) with I0 = material reflectivity * |cos(incidence)| and d the true range;
  Gaussian noise is added to the reported range; drop-out removes points at random. Both draw from the
  caller's generator, one draw per ray (hit or not), so a change in one part of the scene does not
  reshuffle the noise elsewhere.
- A condition (fog, rain; :class:`pipeline.sensors.conditions.Condition`), when given, scales range,
  attenuation, noise and drop-out, multiplies the intensity and drops returns below its detection threshold.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.core.config.sensors import LidarConditionConfig, LidarConfig
from pipeline.core.geometry import Transform
from pipeline.core.jit import as_input, kernel
from pipeline.sensors.backscatter import BACKSCATTER_PER_EXTINCTION, LIGHT_M_PER_NS, soft_returns
from pipeline.sensors.spray import SprayClouds, sweep_optical_depths, sweep_soft_returns
from pipeline.world.materials import material_arrays
from pipeline.world.scene import FrameScene, make_rays, rectangles_mask

RANGE_MIN_M = 0.5  # returns nearer than this are not reported (the sensor's own housing and blind zone)


@dataclass(frozen=True)
class LidarSweep:
    """One sweep's points (M points), LiDAR frame.

    Attributes:
        points_m: (M, 3) float32 x, y, z, metres (noisy range along the true beam).
        intensity: (M,) float32 in [0, 1].
        ring: (M,) uint8 beam index (0 = top). column: (M,) uint16 azimuth step.
        time_offset_s: (M,) float32 firing time after the sweep start.
        instance_id: (M,) int32 actor track id, 0 = static. semantic: (M,) uint8 SemanticClass value.
        points_per_actor: (K,) int64 points kept per actor of the frame (dense actor order).
        range_max_m: the maximum range the sweep was rendered with (the condition's, when one was given).
    """

    points_m: np.ndarray
    intensity: np.ndarray
    ring: np.ndarray
    column: np.ndarray
    time_offset_s: np.ndarray
    instance_id: np.ndarray
    semantic: np.ndarray
    points_per_actor: np.ndarray
    range_max_m: float

    def __len__(self) -> int:
        return len(self.points_m)


class Lidar:
    """A LiDAR built from the rig's validated :class:`~pipeline.core.config.sensors.LidarConfig` (its one
    definition of every field and check); derived values are properties, the ray pattern is cached.

    Attributes:
        config: the validated config (under a condition, :meth:`pipeline.sensors.conditions.Condition.lidar`
            gives the degraded one).
        elevation_rad: (channels,) float64 beam elevations, ring 0 (``upper_fov_deg``) first.
        azimuth_rad: (columns,) float64 column azimuths, CCW from +x.
    """

    range_min_m = RANGE_MIN_M

    def __init__(self, config: LidarConfig) -> None:
        self.config = config
        self.elevation_rad = np.radians(np.linspace(config.upper_fov_deg, config.lower_fov_deg, config.channels))
        res = np.radians(config.horizontal_resolution_deg)
        self.azimuth_rad = np.pi - res * np.arange(self.columns)

    @property
    def name(self) -> str:
        return self.config.name

    @property
    def columns(self) -> int:
        """Azimuth steps per sweep: 360 / horizontal_resolution_deg."""
        return round(360.0 / self.config.horizontal_resolution_deg)

    @functools.cached_property
    def mount(self) -> Transform:
        """Pose of the LiDAR frame (x forward, y left, z up) in the ego frame."""
        return Transform.from_xyz_rpy(self.config.mount.xyz_m, self.config.mount.rpy_rad)

    @functools.cached_property
    def directions(self) -> np.ndarray:
        """(columns * channels, 3) float32 unit beam directions in the LiDAR frame, column-major."""
        el, az = self.elevation_rad[None, :], self.azimuth_rad[:, None]
        d = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1)
        return d.reshape(-1, 3).astype(np.float32)

    def lidar_to_world(self, ego_pose: Transform) -> Transform:
        return ego_pose @ self.mount

    def actor_ray_mask(self, scene: FrameScene, lidar_to_world: Transform) -> np.ndarray:
        """(columns * channels,) bool superset of the beams that can reach an actor: per actor, the window of
        columns x rings that its bounding sphere's cone covers, widened by one step each side against rounding."""
        boxes = scene.actors.boxes
        cols, chans = self.columns, self.config.channels
        if not len(boxes):
            return np.zeros(cols * chans, bool)
        c = lidar_to_world.inverse().apply(boxes.center)
        radius = 0.5 * np.linalg.norm(boxes.size, axis=1) * 1.001 + 1e-3
        dist = np.linalg.norm(c, axis=1)
        near = dist - radius <= self.config.range_m  # farther actors cannot return a point
        c, radius, dist = c[near], radius[near], dist[near]
        if not len(c):
            return np.zeros(cols * chans, bool)
        alpha = np.arcsin(np.clip(radius / np.maximum(dist, 1e-9), 0.0, 1.0))
        el_c = np.arcsin(np.clip(c[:, 2] / np.maximum(dist, 1e-9), -1.0, 1.0))
        pole = np.abs(el_c) + alpha >= 0.5 * np.pi
        everywhere = (dist <= radius) | pole
        # Columns: azimuth pi - j * res, so the cone's azimuth window |daz| <= half is a window of j (cyclic).
        res = np.radians(self.config.horizontal_resolution_deg)
        half = np.arcsin(np.clip(np.sin(alpha) / np.cos(np.where(pole, 0.0, el_c)), 0.0, 1.0)) / res
        centre = (np.pi - np.arctan2(c[:, 1], c[:, 0])) / res
        first = np.floor(centre - half).astype(np.int64) - 1
        count = np.ceil(centre + half).astype(np.int64) + 2 - first
        whole = everywhere | (count >= cols)
        first, count = np.where(whole, 0, first % cols), np.where(whole, cols, count)
        # Rings: elevations evenly spaced from the top beam down, so |el - el_c| <= alpha is a window of rings.
        step = (self.elevation_rad[-1] - self.elevation_rad[0]) / max(chans - 1, 1)
        if step < 0:
            ring_lo = np.floor((el_c + alpha - self.elevation_rad[0]) / step).astype(np.int64) - 1
            ring_hi = np.ceil((el_c - alpha - self.elevation_rad[0]) / step).astype(np.int64) + 2
        else:  # one beam (or a flat fan): every ring
            ring_lo, ring_hi = np.zeros(len(c), np.int64), np.full(len(c), chans)
        ring_lo, ring_hi = np.where(everywhere, 0, ring_lo), np.where(everywhere, chans, ring_hi)
        # A window past the last column wraps to column 0: two rectangles.
        end = first + count
        lo = np.concatenate([np.column_stack([first, ring_lo]), np.column_stack([np.zeros_like(first), ring_lo])])
        hi = np.concatenate([np.column_stack([np.minimum(end, cols), ring_hi]),
                             np.column_stack([np.maximum(end - cols, 0), ring_hi])])
        return rectangles_mask(cols, chans, lo, hi).reshape(-1)


def render_lidar(
    scene: FrameScene, lidar: Lidar, ego_pose: Transform, rng: np.random.Generator, *, condition=None,
    spray: SprayClouds | None = None,
) -> LidarSweep:
    """Cast one sweep of ``lidar`` on the ego at ``ego_pose`` (ego -> world) and apply the sensor model.

    ``condition`` (a :class:`pipeline.sensors.conditions.Condition`, optional) degrades the sweep; do not also
    build ``lidar`` from ``condition.lidar(...)``, which would apply the factors twice. ``spray`` (the frame's
    clouds, :mod:`pipeline.sensors.spray`): a pulse through a cloud of optical depth tau loses exp(-2 tau) of its
    intensity, and its return is lost where that loss takes it below what the LiDAR detects at its range R in the
    condition's air of extinction beta: kept while ln t + beta t + tau <= ln R + beta R (the power ~ exp(-2 beta t
    - 2 tau) / t^2, as :func:`pipeline.sensors.conditions.lidar_range_m`).
    """
    cfg = lidar.config if condition is None else condition.lidar(lidar)
    effects = LidarConditionConfig() if condition is None else condition.lidar_effects
    to_world = lidar.lidar_to_world(ego_pose)
    dirs_l = lidar.directions
    n = len(dirs_l)
    rays = make_rays(to_world.translation, dirs_l, to_world.rotation)
    hits = scene.cast_rays(rays, actor_rays=lidar.actor_ray_mask(scene, to_world))
    normal = rng.standard_normal(n, dtype=np.float32)
    noise = normal * np.float32(cfg.range_noise_std_m)
    drop = rng.random(n) < cfg.dropout if cfg.dropout else np.zeros(n, bool)
    keep, t, reflected = _returns(as_input(hits.hit, bool), as_input(hits.t_m, np.float32), as_input(hits.normal,
                                  np.float32), as_input(rays, np.float32), as_input(hits.material, np.int32),
                                  as_input(material_arrays()["reflectivity"], np.float32), drop,
                                  np.float32(lidar.range_min_m), np.float32(cfg.range_m))
    intensity = reflected * np.exp(-cfg.attenuation_per_m * t) * np.float32(effects.intensity_factor)
    beta = 0.0 if condition is None else condition.extinction_per_m(cfg.wavelength_nm)
    tau = np.zeros(len(keep))
    if spray is not None and len(spray) and len(keep):
        tau = sweep_optical_depths(spray, rays, as_input(hits.t_m, np.float64), keep)[keep].astype(np.float64)
        seen = np.log(t) + beta * t + tau <= np.log(cfg.range_m) + beta * cfg.range_m
        intensity = intensity * np.exp(-2.0 * tau).astype(np.float32)
        keep, t, intensity, reflected, tau = keep[seen], t[seen], intensity[seen], reflected[seen], tau[seen]
    if effects.min_intensity > 0:  # returns too weak to detect are lost
        strong = intensity >= effects.min_intensity
        keep, t, intensity, reflected, tau = keep[strong], t[strong], intensity[strong], reflected[strong], tau[strong]
    instance_id, semantic_class = as_input(hits.instance_id, np.int32), as_input(hits.semantic, np.uint8)
    if beta > 0:  # the droplets' own returns near the sensor
        surface_m = np.where(as_input(hits.hit, bool), as_input(hits.t_m, np.float64), np.inf)
        surface_power = reflected / np.pi * np.exp(-2.0 * (beta * t + tau)) / np.square(t.astype(np.float64))
        keep, t, intensity, noise, instance_id, semantic_class = _weather_returns(
            lidar, cfg, beta, effects.intensity_factor, surface_m, drop, keep, t, intensity, surface_power, normal,
            noise, instance_id, semantic_class, spray=spray, rays=rays)
    points, ring, column, time_offset, instance, semantic, per_actor = _points(
        keep, t, noise, as_input(dirs_l, np.float32), instance_id, semantic_class,
        as_input(hits.actor_index, np.int32), cfg.channels, float(lidar.columns * cfg.rotation_hz), len(scene.actors))
    return LidarSweep(
        points_m=points,
        intensity=intensity.astype(np.float32),
        ring=ring,
        column=column,
        time_offset_s=time_offset,
        instance_id=instance,
        semantic=semantic,
        points_per_actor=per_actor,
        range_max_m=float(cfg.range_m),
    )


def _weather_returns(lidar, cfg, beta, intensity_factor, surface_m, drop, keep, t, intensity, surface_power,
                     normal, noise, instance_id, semantic_class, *, spray=None, rays=None):
    """The sweep's returns with the droplets' (:mod:`pipeline.sensors.backscatter`): a beam whose droplets return
    at least the detection threshold's power, and more than the surface it kept (if any), reports them instead, at
    their range, labelled WEATHER with track id 0. Their intensity follows the rig's law at that range for the
    reflectivity that returns the same power in clear air; their range scatters with the rig's noise and the
    ranging error of a return of rise time tau_H at the peak-to-threshold ratio P / P_th, c tau_H / 2 x P_th / P
    (Amann et al. 2001's c t_rise / (2 SNR), the threshold taken for the unit of the SNR), from the beam's own
    normal draw. A beam through a vehicle's spray (``spray``, the frame's clouds; ``rays`` the sweep's) takes the
    return of the spray and the air together (:func:`pipeline.sensors.spray.sweep_soft_returns`). The condition's
    ``min_intensity`` (an intensity floor of the surfaces' returns) does not apply: the droplets' detection is the
    power threshold's. Returns keep, t, intensity, noise, instance_id and semantic_class for :func:`_points`."""
    r1, r2 = cfg.overlap_m
    window_m = LIGHT_M_PER_NS * cfg.pulse_half_width_ns
    table = soft_returns(beta, BACKSCATTER_PER_EXTINCTION * beta, cfg.pulse_half_width_ns, r1, r2)
    power, range_m = table.at(surface_m)
    threshold = cfg.range_reflectivity / np.pi / lidar.config.range_m ** 2
    if spray is not None and len(spray):
        # Farther than this, not even the densest cloud's return (~ ratio beta w / 2 / t^2) reaches the threshold.
        far_m = np.sqrt(BACKSCATTER_PER_EXTINCTION * (spray.peak_per_m.max() + beta) * window_m / threshold)
        through, spray_power, spray_range = sweep_soft_returns(
            spray, rays, surface_m, beta, BACKSCATTER_PER_EXTINCTION, window_m, cfg.overlap_m, far_m + window_m,
            float(table.power[-1]), threshold)
        power[through], range_m[through] = spray_power, spray_range
    stronger = power.copy()
    stronger[keep] -= surface_power
    weather = (power >= threshold) & (stronger > 0) & ~drop & (range_m >= lidar.range_min_m)
    if not weather.any():
        return keep, t, intensity, noise, instance_id, semantic_class
    beams = np.flatnonzero(weather)
    p, r = power[beams], range_m[beams]
    n = len(surface_m)
    t_all = np.zeros(n, np.float32)
    i_all = np.zeros(n, np.float32)
    t_all[keep], i_all[keep] = t, intensity
    t_all[beams] = r
    equivalent = np.minimum(np.pi * p * r * r * np.exp(2.0 * beta * r), 1.0)  # the reflectivity of that power
    i_all[beams] = equivalent * np.exp(-cfg.attenuation_per_m * r) * intensity_factor
    noise = noise.copy()
    jitter = 0.5 * window_m * threshold / p
    noise[beams] = normal[beams] * np.hypot(cfg.range_noise_std_m, jitter)
    returned = np.zeros(n, bool)
    returned[keep] = True
    near = r + noise[beams] < lidar.range_min_m  # the strongest return scattered into the blind zone: no point
    returned[beams[near]] = False
    beams = beams[~near]
    returned[beams] = True
    instance_id, semantic_class = instance_id.copy(), semantic_class.copy()
    instance_id[beams], semantic_class[beams] = 0, SemanticClass.WEATHER
    keep = np.flatnonzero(returned)
    return keep, t_all[keep], i_all[keep], noise, instance_id, semantic_class


@kernel("Tuple((int64[::1], float32[::1], float32[::1]))(bool_[::1], float32[::1], float32[:, ::1], float32[:, ::1], "
        "int32[::1], float32[::1], bool_[::1], float32, float32)")
def _returns(hit, t_m, normal, rays, material, reflectivity, drop, range_min_m, range_max_m):
    """The beams that return a point: hit within [range_min_m, range_max_m] and not dropped. Returns their indices
    (K,) int64, ranges (K,) float32 and reflectivity x |cos incidence| (K,) float32 (the intensity before
    attenuation), from the sweep's (N,) hits (``rays`` (N, 6) float32 [origin | unit direction], ``normal`` (N, 3)
    float32) and the (M,) float32 reflectivity per material."""
    n = t_m.size
    count = 0
    for i in range(n):
        if hit[i] and t_m[i] >= range_min_m and t_m[i] <= range_max_m and not drop[i]:
            count += 1
    keep = np.empty(count, np.int64)
    t = np.empty(count, np.float32)
    reflected = np.empty(count, np.float32)
    j = 0
    for i in range(n):
        if hit[i] and t_m[i] >= range_min_m and t_m[i] <= range_max_m and not drop[i]:
            cos_inc = abs(normal[i, 0] * rays[i, 3] + normal[i, 1] * rays[i, 4] + normal[i, 2] * rays[i, 5])
            keep[j] = i
            t[j] = t_m[i]
            reflected[j] = reflectivity[material[i]] * cos_inc
            j += 1
    return keep, t, reflected


@kernel("Tuple((float32[:, ::1], uint8[::1], uint16[::1], float32[::1], int32[::1], uint8[::1], int64[::1]))("
        "int64[::1], float32[::1], float32[::1], float32[:, ::1], int32[::1], uint8[::1], int32[::1], int64, float64, "
        "int64)")
def _points(keep, t, noise, directions, instance_id, semantic, actor_index, channels, columns_per_s, actors):
    """The sweep's points from its K returns (beam indices ``keep``, column-major over ``channels`` rings; true
    ranges ``t``): each along its beam's (N, 3) float32 unit direction at max(range + noise[beam], 0); ring, column
    and firing time (column / ``columns_per_s``); the beam's instance id and class; and points per actor (of
    ``actors``; ``actor_index`` is valid where the instance id is > 0)."""
    k = keep.size
    points = np.empty((k, 3), np.float32)
    ring = np.empty(k, np.uint8)
    column = np.empty(k, np.uint16)
    time_offset = np.empty(k, np.float32)
    instance = np.empty(k, np.int32)
    sem = np.empty(k, np.uint8)
    per_actor = np.zeros(actors, np.int64)
    for j in range(k):
        i = keep[j]
        r = t[j] + noise[i]
        if not r > 0:
            r = np.float32(0)
        for c in range(3):
            points[j, c] = directions[i, c] * r
        col = i // channels
        ring[j] = i - col * channels
        column[j] = col
        time_offset[j] = col / columns_per_s
        instance[j] = instance_id[i]
        sem[j] = semantic[i]
        if instance_id[i] > 0:
            per_actor[actor_index[i]] += 1
    return points, ring, column, time_offset, instance, sem, per_actor
