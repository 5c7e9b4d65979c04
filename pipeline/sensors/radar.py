"""Automotive radar: a ray-cast scan with RCS, Doppler, SNR, detection, noise and resolution cells.

The radar casts a grid of rays (:class:`pipeline.core.config.RadarConfig`) into the same frame scene as the
cameras and LiDARs and turns the returns into detections. The model, each part a stated simplification:

- **Frame**: the radar frame is its mount's body frame (x forward, y left, z up). azimuth = atan2(y, x),
  elevation = asin(z / range). Rays are row-major: ray index = elevation row * azimuth columns + column.
- **RCS of a patch**: each ray stands for the patch of surface in its solid angle dOmega = step^2 cos(elevation),
  of area A = r^2 dOmega seen across the ray. Its RCS is sigma = A (gamma_m + s_m cos^SPECULAR_EXPONENT(theta)),
  theta the incidence angle: gamma_m the material's diffuse (constant-gamma) backscatter, s_m its glint (smooth
  metal and glass facing the radar). :data:`RADAR_MATERIALS` holds both per material; they put a car at about
  10 dBsm, a truck higher and a pedestrian near -8 dBsm.
- **Doppler**: radial velocity v_r = (v_target - v_radar) . u with u the unit ray direction: **negative =
  approaching**. The ego-motion-compensated v_r,comp = v_target . u (0 for the static world). Velocities are each
  vehicle's speed along its heading (SUMO gives no lateral speed nor yaw rate); the radar moves with the ego's
  centre (the yaw rate's lever arm is ignored). Actors are rigid: no wheel micro-Doppler.
- **Cells**: returns are merged per (range, azimuth, radial velocity) cell of the config's resolutions; elevation
  is not resolved. A cell's RCS is the sum of its patches (incoherent: no interference), its position and radial
  velocities the means of its returns weighted by received power (sigma / r^4), its instance and class those of
  the object (or static class) returning most of its power: ``instance_id`` 0 = clutter (road, guard rails,
  poles, signs, buildings, vegetation).
- **SNR** = ``snr_0dbsm_100m_db`` + 10 log10(sigma / 1 m^2) - 40 log10(r / 100 m) - 2 r alpha: the radar
  equation with the two-way weather attenuation alpha (dB per metre; :func:`weather_attenuation_db_per_km`).
- **Detection**: probability Pd = Pfa^(1 / (1 + SNR)) (Swerling 1, square-law detector); one uniform draw per
  cell. The false-alarm probability sets the threshold only: no noise-only detections are made.
- **Noise**: Gaussian on range, azimuth, elevation and radial velocity (the compensated one gets the same draw),
  standard deviations the config's accuracies, truncated at NOISE_CLIP_SIGMA; x, y, z follow from the noisy
  range and angles, so range = |(x, y, z)| and azimuth = atan2(y, x) hold exactly.
- **Limit**: at most ``max_detections``, the highest SNR first; detections are ordered by cell (range, azimuth,
  radial velocity).
- Not modelled: multipath and ghost targets, range/Doppler ambiguity, sidelobes, interference between radars.

Draws come from the caller's generator in a fixed order (one uniform and four normals per cell, for every cell),
so the same scene and seed give the same scan.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.core.config.sensors import ConditionConfig, RadarConfig
from pipeline.core.geometry import Transform
from pipeline.world.actors import Actors
from pipeline.world.materials import MATERIAL_NAMES, PERSON_MATERIALS, material_index
from pipeline.world.scene import FrameScene, make_rays, rectangles_mask

SPECULAR_EXPONENT = 8.0  # glint lobe: cos^8 falls to a half at 23 degrees off the normal
NOISE_CLIP_SIGMA = 3.0
REFERENCE_RANGE_M = 100.0

# Per material: (diffuse gamma, glint s), RCS per square metre of patch seen across the ray. Car bodies (paint,
# plates, rims) and street furniture (metal) are metal sheet; barriers are (weathered) concrete; people are weak,
# diffuse scatterers; smooth road surfaces backscatter little at grazing incidence. Materials not listed are diffuse
# at DEFAULT_RADAR_MATERIAL.
DEFAULT_RADAR_MATERIAL = (0.05, 0.0)
RADAR_MATERIALS: dict[str, tuple[float, float]] = {
    "asphalt": (0.004, 0.0), "lane_paint": (0.004, 0.0), "concrete": (0.02, 0.0), "kerb": (0.05, 0.3),
    "grass": (0.03, 0.0), "foliage": (0.03, 0.0), "bark": (0.05, 0.0),
    "building": (0.05, 0.5), "building_glass": (0.05, 2.0), "building_light": (0.05, 0.5), "building_dark": (0.05, 0.5),
    "metal": (0.3, 8.0), "barrier": (0.03, 2.0), "paint": (0.3, 8.0), "plate": (0.3, 8.0), "plate_rear": (0.3, 8.0),
    "rim": (0.3, 8.0),
    "cargo": (0.3, 8.0), "lamp": (0.3, 4.0), "glass": (0.1, 1.0), "rubber": (0.05, 0.0), "trim": (0.1, 0.5),
    "headlight": (0.1, 1.0), "taillight": (0.1, 1.0), "reflector_red": (0.1, 1.0), "reflector_white": (0.1, 1.0),
    "marker_lamp": (0.1, 1.0),
    **{name: (0.15, 0.1) for name in PERSON_MATERIALS},
}

_PAINT, _CLOTH = material_index("paint"), material_index("cloth")

# Weather near 77 GHz. Rain: specific attenuation k R^a at the condition's rain rate R (ITU-R P.838 coefficients at
# 77 GHz, horizontal). Fog: liquid water content from the
# visibility (Eldridge: V_km = 0.024 M^-0.65, M in g/m^3) times ITU-R P.840's specific attenuation near 77 GHz.
RAIN_K, RAIN_ALPHA = 1.1, 0.71
FOG_DB_PER_KM_PER_G_M3 = 2.5


@dataclass(frozen=True)
class RadarScan:
    """One scan's K detections, radar frame (x forward, y left, z up).

    Attributes:
        points_m: (K, 3) float32 x, y, z, metres (from the noisy range, azimuth and elevation).
        range_m, azimuth_rad, elevation_rad: (K,) float32; azimuth = atan2(y, x), elevation = asin(z / range).
        radial_velocity_mps: (K,) float32 relative radial velocity, negative = approaching.
        radial_velocity_comp_mps: (K,) float32 the same compensated for the ego's motion (0 for static things).
        rcs_dbsm: (K,) float32 radar cross section, dB relative to 1 m^2. snr_db: (K,) float32.
        instance_id: (K,) int32 actor track id, 0 = clutter. semantic: (K,) uint8 SemanticClass value.
        detections_per_actor: (A,) int64 detections per actor of the frame (dense actor order).
    """

    points_m: np.ndarray
    range_m: np.ndarray
    azimuth_rad: np.ndarray
    elevation_rad: np.ndarray
    radial_velocity_mps: np.ndarray
    radial_velocity_comp_mps: np.ndarray
    rcs_dbsm: np.ndarray
    snr_db: np.ndarray
    instance_id: np.ndarray
    semantic: np.ndarray
    detections_per_actor: np.ndarray

    def __len__(self) -> int:
        return len(self.range_m)


def mount(config: RadarConfig) -> Transform:
    """The radar frame -> ego frame (``T_ego_sensor``)."""
    return Transform.from_xyz_rpy(config.mount.xyz_m, config.mount.rpy_rad)


@functools.lru_cache(maxsize=8)
def ray_pattern(config: RadarConfig) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) float32 unit ray directions in the radar frame (row-major: elevation row, azimuth column) and (N,)
    float64 the solid angle each ray stands for, steradians."""
    el, az = config.elevation_rad[:, None], config.azimuth_rad[None, :]
    d = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)), axis=-1)
    step = np.radians(config.ray_step_deg)
    solid = np.broadcast_to(step * step * np.cos(el), (len(config.elevation_rad), len(config.azimuth_rad)))
    return d.reshape(-1, 3).astype(np.float32), solid.reshape(-1).astype(np.float64)


@functools.lru_cache(maxsize=1)
def material_tables() -> tuple[np.ndarray, np.ndarray]:
    """(M,) float64 diffuse gamma and (M,) glint s per material index (:data:`RADAR_MATERIALS`)."""
    table = np.array([RADAR_MATERIALS.get(name, DEFAULT_RADAR_MATERIAL) for name in MATERIAL_NAMES], np.float64)
    return table[:, 0], table[:, 1]


def weather_attenuation_db_per_km(condition: ConditionConfig) -> float:
    """One-way specific attenuation of the radar's signal under ``condition`` (rain and fog), dB per km."""
    alpha = 0.0
    if condition.rain is not None:
        alpha += RAIN_K * condition.rain.rate_mm_h ** RAIN_ALPHA
    if condition.fog is not None:
        water_g_m3 = (condition.fog.visibility_m / 1000.0 / 0.024) ** (-1.0 / 0.65)
        alpha += FOG_DB_PER_KM_PER_G_M3 * water_g_m3
    return float(alpha)


def heading_velocity(speed_mps: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """(N, 3) float64 world velocities of things moving at ``speed_mps`` along their heading ``yaw_rad``."""
    speed_mps, yaw_rad = np.asarray(speed_mps, np.float64), np.asarray(yaw_rad, np.float64)
    return np.column_stack([speed_mps * np.cos(yaw_rad), speed_mps * np.sin(yaw_rad), np.zeros_like(speed_mps)])


def actors_in_radar_reach(actors: Actors, ego_pose: Transform, radars: list[RadarConfig]) -> np.ndarray:
    """(A,) bool: the actors whose bounding sphere comes within some radar's maximum range (a conservative test:
    OR it into the frame scene's ``active`` mask, see :mod:`pipeline.sensors.reach`)."""
    reach = np.zeros(len(actors), bool)
    if not len(actors):
        return reach
    radius = 0.5 * np.linalg.norm(actors.boxes.size, axis=1) * 1.001 + 1e-3
    for config in radars:
        origin = (ego_pose @ mount(config)).translation
        reach |= np.linalg.norm(actors.boxes.center - origin, axis=1) - radius <= config.range_max_m
    return reach


def actor_ray_mask(scene: FrameScene, config: RadarConfig, radar_to_world: Transform) -> np.ndarray:
    """(N,) bool superset of the rays (:func:`ray_pattern` order) that can reach an actor of ``scene``: per placed
    actor, the window of elevation rows x azimuth columns its bounding sphere's cone covers (azimuth also shifted by
    +-2 pi against wrapping), widened by a ray each side against rounding."""
    az_rays, el_rays = config.azimuth_rad, config.elevation_rad
    height, width = len(el_rays), len(az_rays)
    placed = np.flatnonzero(scene.active)
    if not len(placed):
        return np.zeros(height * width, bool)
    boxes = scene.actors.boxes
    c = radar_to_world.inverse().apply(boxes.center[placed])
    radius = 0.5 * np.linalg.norm(boxes.size[placed], axis=1) * 1.001 + 1e-3
    dist = np.linalg.norm(c, axis=1)
    near = dist - radius <= config.range_max_m
    c, radius, dist = c[near], radius[near], dist[near]
    if not len(c):
        return np.zeros(height * width, bool)
    step = np.radians(config.ray_step_deg)
    alpha = np.arcsin(np.clip(radius / np.maximum(dist, 1e-9), 0.0, 1.0))
    el_c = np.arcsin(np.clip(c[:, 2] / np.maximum(dist, 1e-9), -1.0, 1.0))
    everywhere = (dist <= radius) | (np.abs(el_c) + alpha >= 0.5 * np.pi)
    half = np.arcsin(np.clip(np.sin(alpha) / np.cos(np.where(everywhere, 0.0, el_c)), 0.0, 1.0))
    az_c = np.arctan2(c[:, 1], c[:, 0])
    rows = [np.floor((el_rays[0] - (el_c + alpha)) / step) - 1, np.ceil((el_rays[0] - (el_c - alpha)) / step) + 2]
    lo, hi = [], []
    for shift in (-2 * np.pi, 0.0, 2 * np.pi):  # columns run from az_rays[0] (left) rightwards
        col_lo = np.floor((az_rays[0] - (az_c + shift + half)) / step) - 1
        col_hi = np.ceil((az_rays[0] - (az_c + shift - half)) / step) + 2
        lo.append(np.column_stack([np.where(everywhere, 0, rows[0]), np.where(everywhere, 0, col_lo)]))
        hi.append(np.column_stack([np.where(everywhere, height, rows[1]), np.where(everywhere, width, col_hi)]))
    return rectangles_mask(height, width, np.concatenate(lo), np.concatenate(hi)).reshape(-1)


def render_radar(
    scene: FrameScene, config: RadarConfig, ego_pose: Transform, rng: np.random.Generator, *,
    ego_velocity_mps: np.ndarray | None = None, actor_velocity_mps: np.ndarray | None = None,
    attenuation_db_per_km: float = 0.0,
) -> RadarScan:
    """Scan with the radar ``config`` on the ego at ``ego_pose`` (ego -> world).

    ``ego_velocity_mps`` (3,) and ``actor_velocity_mps`` (A, 3, one per actor of ``scene``): world velocities
    (zero when left out); ``attenuation_db_per_km``: the one-way weather attenuation
    (:func:`weather_attenuation_db_per_km`). See the module docstring for the model.
    """
    n_actors = len(scene.actors)
    v_ego = np.zeros(3) if ego_velocity_mps is None else np.asarray(ego_velocity_mps, np.float64).reshape(3)
    v_actor = np.zeros((n_actors, 3)) if actor_velocity_mps is None else np.asarray(actor_velocity_mps, np.float64)
    if v_actor.shape != (n_actors, 3):
        raise ValueError(f"actor_velocity_mps must be ({n_actors}, 3), one per actor; got shape {v_actor.shape}")
    to_world = ego_pose @ mount(config)
    dirs, solid = ray_pattern(config)
    rays = make_rays(to_world.translation, dirs, to_world.rotation)
    hits = scene.cast_rays(rays, actor_rays=actor_ray_mask(scene, config, to_world))
    idx = np.flatnonzero(hits.hit & (hits.t_m >= config.range_min_m) & (hits.t_m <= config.range_max_m))
    r = hits.t_m[idx].astype(np.float64)
    u_world = rays[idx, 3:].astype(np.float64)
    gamma, glint = material_tables()
    material = hits.material[idx]
    # A pedestrian's "paint" is the actor colour of its clothes, not sheet metal.
    material = np.where((hits.semantic[idx] == SemanticClass.PEDESTRIAN) & (material == _PAINT), _CLOTH, material)
    cos_inc = np.abs(np.einsum("ij,ij->i", hits.normal[idx].astype(np.float64), u_world))
    sigma = r * r * solid[idx] * (gamma[material] + glint[material] * cos_inc ** SPECULAR_EXPONENT)
    instance, actor = hits.instance_id[idx], hits.actor_index[idx]
    v_target = np.where((instance > 0)[:, None], v_actor[actor] if n_actors else 0.0, 0.0)
    vr_comp = np.einsum("ij,ij->i", v_target, u_world)
    vr = vr_comp - u_world @ v_ego
    cells = _cells(config, r, idx, vr, sigma, dirs, instance, hits.semantic[idx], vr_comp)
    return _detect(config, cells, rng, actor, n_actors, attenuation_db_per_km)


@dataclass(frozen=True)
class _Cells:
    """Per resolution cell (C of them, in cell order): summed RCS (m^2), power-weighted position (C, 3) in the radar
    frame and radial velocities, and the dominant return's instance, class and ray (a return of that instance)."""

    sigma_m2: np.ndarray
    position_m: np.ndarray
    vr_mps: np.ndarray
    vr_comp_mps: np.ndarray
    instance_id: np.ndarray
    semantic: np.ndarray
    dominant: np.ndarray


def _cells(config: RadarConfig, r, idx, vr, sigma, dirs, instance, semantic, vr_comp) -> _Cells:
    if not len(r):
        empty = np.zeros(0)
        return _Cells(empty, np.zeros((0, 3)), empty, empty, np.zeros(0, np.int32), np.zeros(0, np.uint8),
                      np.zeros(0, np.int64))
    az = config.azimuth_rad[idx % len(config.azimuth_rad)]
    range_bin = np.floor(r / config.range_resolution_m).astype(np.int64)
    azimuth_bin = np.floor((az + np.radians(0.5 * config.azimuth_fov_deg))
                           / np.radians(config.azimuth_resolution_deg)).astype(np.int64)
    velocity_bin = np.floor(vr / config.velocity_resolution_mps).astype(np.int64)
    velocity_bin -= velocity_bin.min()
    # One int64 key per cell, ordered by range, then azimuth, then velocity (bins are small: no overflow).
    key = (range_bin * (azimuth_bin.max() + 1) + azimuth_bin) * (velocity_bin.max() + 1) + velocity_bin
    _, cell = np.unique(key, return_inverse=True)
    count = int(cell.max()) + 1
    power = sigma / r ** 4
    total = np.bincount(cell, power, count)
    points = dirs[idx].astype(np.float64) * r[:, None]
    position = np.column_stack([np.bincount(cell, power * points[:, c], count) for c in range(3)]) / total[:, None]
    # The dominant (instance, class) of each cell: the pair returning most power.
    _, who = np.unique(instance.astype(np.int64) << 8 | semantic, return_inverse=True)
    pairs, first_return, pair = np.unique(cell * (who.max() + 1) + who, return_index=True, return_inverse=True)
    pair_cell = pairs // (who.max() + 1)
    pair_power = np.bincount(pair, power, len(pairs))
    order = np.lexsort((-pair_power, pair_cell))  # by cell, the strongest pair first
    strongest = order[np.r_[True, pair_cell[order[1:]] != pair_cell[order[:-1]]]]
    dominant = first_return[strongest]  # a return of that pair
    return _Cells(
        sigma_m2=np.bincount(cell, sigma, count), position_m=position,
        vr_mps=np.bincount(cell, power * vr, count) / total,
        vr_comp_mps=np.bincount(cell, power * vr_comp, count) / total,
        instance_id=instance[dominant].astype(np.int32), semantic=semantic[dominant].astype(np.uint8),
        dominant=dominant,
    )


def _detect(config: RadarConfig, cells: _Cells, rng: np.random.Generator, actor: np.ndarray, n_actors: int,
            attenuation_db_per_km: float) -> RadarScan:
    count = len(cells.sigma_m2)
    draw = rng.random(count)
    noise = np.clip(rng.standard_normal((count, 4)), -NOISE_CLIP_SIGMA, NOISE_CLIP_SIGMA)
    true_range = np.linalg.norm(cells.position_m, axis=1)
    snr_db = (config.snr_0dbsm_100m_db + 10.0 * np.log10(np.maximum(cells.sigma_m2, 1e-30))
              - 40.0 * np.log10(true_range / REFERENCE_RANGE_M) - 2.0 * true_range * attenuation_db_per_km / 1000.0)
    pd = config.false_alarm_probability ** (1.0 / (1.0 + 10.0 ** (snr_db / 10.0)))
    detected = np.flatnonzero(draw < pd)
    if len(detected) > config.max_detections:
        strongest = detected[np.argsort(-snr_db[detected], kind="stable")[:config.max_detections]]
        detected = np.sort(strongest)
    p = cells.position_m[detected]
    rng_m = true_range[detected] + noise[detected, 0] * config.range_accuracy_m
    rng_m = np.maximum(rng_m, 0.0)
    az = np.arctan2(p[:, 1], p[:, 0]) + noise[detected, 1] * np.radians(config.azimuth_accuracy_deg)
    el = np.arcsin(np.clip(p[:, 2] / np.maximum(true_range[detected], 1e-12), -1.0, 1.0)) \
        + noise[detected, 2] * np.radians(config.elevation_accuracy_deg)
    dv = noise[detected, 3] * config.velocity_accuracy_mps
    points = np.column_stack([rng_m * np.cos(el) * np.cos(az), rng_m * np.cos(el) * np.sin(az), rng_m * np.sin(el)])
    instance = cells.instance_id[detected]
    per_actor = np.bincount(actor[cells.dominant[detected]][instance > 0], minlength=n_actors).astype(np.int64)
    f32 = np.float32
    return RadarScan(
        points_m=points.astype(f32), range_m=rng_m.astype(f32),
        azimuth_rad=np.arctan2(points[:, 1], points[:, 0]).astype(f32),
        elevation_rad=el.astype(f32), radial_velocity_mps=(cells.vr_mps[detected] + dv).astype(f32),
        radial_velocity_comp_mps=(cells.vr_comp_mps[detected] + dv).astype(f32),
        rcs_dbsm=(10.0 * np.log10(np.maximum(cells.sigma_m2[detected], 1e-30))).astype(f32),
        snr_db=snr_db[detected].astype(f32), instance_id=instance, semantic=cells.semantic[detected],
        detections_per_actor=per_actor,
    )
