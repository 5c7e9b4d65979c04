"""Local lights at night: vehicle headlights and street lamps as spot lights, shaded over all hits at once.

A :class:`SpotLights` holds L spot lights (world frame, metres). Each has an elliptical cone about its axis
(half-widths ``tan_h`` / ``tan_v`` measured as tangents in the light's left / up directions) whose edge fades
over the fraction ``soft`` of its radius (smoothstep), an inverse-square fall-off windowed to zero at
``range_m`` ((1 - (d/R)^4)^2, so a light's reach is bounded), and an RGB intensity = irradiance at 1 m where
the beam is brightest. Lamps are downward circular cones of uniform intensity; low beams are wide, flat cones
pitched slightly down with a beam pattern inside (:func:`beam_pattern`): a real low beam concentrates its light just
below its cut-off (ECE R112 asks >= 10,100 cd at 0.57-0.86 deg below the horizon and only >= 1,700 cd at 1.72 deg
down and 9 deg to the side), so that the road far ahead is lit and the road just in front of the car is not glaring;
a uniform cone, whose light on the road falls as 1/d^3, lit a bright pool a few metres ahead and left the road
beyond it dark. Above its cut-off a low beam is faint, not dark: a second, uniform cone of a small share of its peak
(:func:`above_cutoff_lights`) lights what stands a few metres ahead above the lamps' height.

Shading is vectorised over (light, hit) pairs: hit points are bucketed once per call in a 2D grid
(:class:`PointGrid`, radix-sorted cell ids), and each light only visits the points in the cells its range
covers (cells outside its range or, seen from above, outside its horizontal half-angle are skipped), then
a cheap exact test (range, in front, facing) precedes the cone and shading terms, and pairs whose light is
below MIN_IRRADIANCE are dropped. The number of lights per frame is bounded by the condition (the ego, the
nearest ``max_other_vehicles`` vehicles ahead of the camera, the nearest ``max_lamps`` lamps).

Retroreflection: road markings (glass beads), sign sheeting, number plates, reflex reflectors and, weakly, asphalt
send light back towards its source. A driver (or a camera beside the headlamps) sees them far brighter than their
diffuse reflection: a marking 30 m ahead, lit at 1.2 deg grazing incidence, returns about 15 times its Lambertian
radiance. Each material's coefficient of retroreflected luminance R (cd m^-2 lx^-1, at the 1.05 deg observation
angle of the standard 30 m geometry, EN 1436 / CIE 54.2; ``Material.retroreflection``) adds
pi * R * f(alpha) * E_perp * albedo / max(material albedo) to a hit lit by a light with illuminance E_perp
perpendicular to the light's direction there, with alpha the angle at the hit between the light and the camera
and f = (1.05 deg / max(alpha, 0.5 deg)) exp(-(alpha / 6 deg)^2) (glass-bead markings keep about half their R at
2.3 deg; far from the light's direction nothing returns). The pi converts a luminance coefficient into the
renderer's units (a Lambertian albedo rho reflects rho * E here, i.e. rho / pi cd m^-2 lx^-1). Worn paint (its
textured albedo lower) returns less. Without it the road beyond a few metres went dark under low beams, and
markings and plates did not stand out as they do in every night photograph.

Shadow rays (per light family, ``shadows`` in the config): one Embree occlusion call per shadowed light with
ray directions spanning the segment to the light (``t`` in [0, 1]). Shipped conditions cast them for street
lamps (a car's shadow under a lamp is visible) but not for headlights: the ego's lamps sit next to the camera,
which therefore sees almost none of their shadows, and other vehicles' ones cost as much again for little.
The ego is not in the scene, so it shadows nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.core.config.sensors import HeadlightConfig, StreetLampConfig
from pipeline.core.geometry import Transform
from pipeline.core.jit import as_input, kernel
from pipeline.core.photometry import lux_to_irradiance
from pipeline.world.actors import Actors, unit_to_world
from pipeline.world.materials import material_arrays
from pipeline.world.scene import FrameScene, Hits, take_columns

# A vehicle's pair of low beams is modelled as ONE light of twice the intensity at the middle of the front
# (unit box frame: x forward, y left, z up; lamps of the procedural car at 41 % of the height): from a few
# metres on the two cones are indistinguishable, and it halves the work.
HEADLIGHT_UNIT_XYZ = np.array([0.5, 0.0, -0.09])
HEADLIGHT_AHEAD_M = 0.1  # lights sit just ahead of the lamp plaques, so a car never shadows its own beam
HEADLAMP_INSET_M = 0.3  # a lamp's centre from the car's side (where the pair is drawn apart: ego_headlights)
LIT_CLASSES = (ObjectClass.CAR, ObjectClass.VAN, ObjectClass.TRUCK, ObjectClass.BUS, ObjectClass.MOTORCYCLE)
DEFAULT_EGO_SIZE_M = (4.5, 1.8, 1.5)
MIN_DISTANCE_M = 0.5  # the inverse-square law is clamped closer than this
# Light below this is not shaded: 0.05 lx, under one 8-bit step on dark asphalt even at the night camera's longest
# exposure and highest gain (pipeline.sensors.exposure), and far below the illuminance of a lit street (EN 13201).
MIN_IRRADIANCE = lux_to_irradiance(0.05)
RETRO_REFERENCE_RAD = np.radians(1.05)  # observation angle of the 30 m geometry at which R is given
RETRO_MIN_RAD = np.radians(0.5)  # closer to the light's direction R is taken as at this angle
RETRO_WIDTH_RAD = np.radians(6.0)  # beyond a few degrees from the light's direction nothing returns
RETRO_PEAK = float(RETRO_REFERENCE_RAD / RETRO_MIN_RAD)  # the largest value of the angular factor
# How far a shadow segment may stray from the line from its lamp through its start: it leaves 2 mm off its
# surface and stops 5 cm short of the lamp (_lit_pairs), and float32 rounds a point by ~2 mm within 20 km.
SEGMENT_STRAY_M = 0.1


def _retro_per_material() -> np.ndarray:
    """(M,) float32 pi * R / max(albedo) per material (0: not retroreflective); times a hit's albedo it gives the
    retroreflected radiance per unit of perpendicular illuminance at the reference observation angle."""
    mats = material_arrays()
    return (np.pi * mats["retroreflection"] / np.maximum(mats["albedo"].max(axis=1), 1e-6)).astype(np.float32)


_RETRO = _retro_per_material()


def retro_angle_factor(cos_alpha: np.ndarray) -> np.ndarray:
    """(M,) float32 angular factor f of retroreflection for the (M,) cosines of the angle at the hit between the
    directions to the light and to the camera (1 at the reference angle of 1.05 deg, up to ``RETRO_PEAK``)."""
    alpha = np.arccos(np.clip(cos_alpha, -1.0, 1.0)).astype(np.float32)
    ratio = alpha * np.float32(1.0 / RETRO_WIDTH_RAD)
    return np.float32(RETRO_REFERENCE_RAD) / np.maximum(alpha, np.float32(RETRO_MIN_RAD)) * np.exp(-ratio * ratio)


@dataclass(frozen=True)
class SpotLights:
    """L spot lights, struct of arrays (world frame).

    Attributes:
        position_m: (L, 3) float64 light positions. axis: (L, 3) unit beam axes. up: (L, 3) unit vectors
            normal to the axis (the cone's vertical direction).
        rgb: (L, 3) float32 irradiance at 1 m on the axis, linear RGB.
        tan_h, tan_v: (L,) float64 tangents of the cone's horizontal / vertical (below the axis) half-angles.
        tan_up: (L,) float64 tangent of the half-angle above the axis (a low beam's cut-off; = tan_v for lamps).
        soft: (L,) float64 fraction of the cone radius over which the edge fades, in (0, 1].
        range_m: (L,) float64 cut-off distance. shadows: (L,) bool, cast shadow rays.
        peak_band_rad, falloff, spread_h_rad, floor_h: (L,) float64 the beam pattern (:func:`beam_pattern`);
            falloff 0 and spread_h_rad inf give a uniform cone.
    """

    position_m: np.ndarray
    axis: np.ndarray
    up: np.ndarray
    rgb: np.ndarray
    tan_h: np.ndarray
    tan_v: np.ndarray
    tan_up: np.ndarray
    soft: np.ndarray
    range_m: np.ndarray
    shadows: np.ndarray
    peak_band_rad: np.ndarray
    falloff: np.ndarray
    spread_h_rad: np.ndarray
    floor_h: np.ndarray

    def __len__(self) -> int:
        return len(self.position_m)

    @classmethod
    def empty(cls) -> SpotLights:
        z3, z = np.zeros((0, 3)), np.zeros(0)
        return cls(z3, z3, z3, z3.astype(np.float32), z, z, z, z, z, np.zeros(0, bool), z, z, z, z)

    @classmethod
    def concatenate(cls, parts: list[SpotLights]) -> SpotLights:
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in cls.__dataclass_fields__))


def _spots(position, axis, up, rgb, tan_h, tan_v, tan_up, soft, range_m, shadows, peak_band_rad=1.0, falloff=0.0,
           spread_h_rad=np.inf, floor_h=1.0) -> SpotLights:
    n = len(position)
    full = lambda v: np.broadcast_to(np.asarray(v, np.float64), (n,)).copy()  # noqa: E731
    return SpotLights(np.asarray(position, np.float64).reshape(n, 3), np.asarray(axis, np.float64).reshape(n, 3),
                      np.asarray(up, np.float64).reshape(n, 3),
                      np.broadcast_to(np.asarray(rgb, np.float32), (n, 3)).copy(), full(tan_h), full(tan_v),
                      full(tan_up), full(soft), full(range_m), np.broadcast_to(np.asarray(shadows, bool), (n,)).copy(),
                      full(peak_band_rad), full(falloff), full(spread_h_rad), full(floor_h))


def beam_pattern(tan_left: np.ndarray, tan_up: np.ndarray, lights: SpotLights, k: int) -> np.ndarray:
    """(M,) float32 relative intensity of light ``k`` in M directions given as tangents of their angles to its
    left and above its axis ((M,) float32 each): 1 in the peak band (from the cut-off, ``tan_up`` of the light above
    the axis, down to ``peak_band_rad`` below it), below it (peak band / angle below the cut-off) ** ``falloff``;
    across the beam times floor + (1 - floor) exp(-(angle to the side / ``spread_h_rad``)^2). The cone's edges
    (:func:`light_radiance`) cut it off; a uniform cone (falloff 0, spread inf) is 1 everywhere."""
    out = np.ones(len(tan_left), np.float32)
    if lights.falloff[k] > 0:
        below = np.float32(np.arctan(lights.tan_up[k])) - np.arctan(tan_up)
        band = np.float32(lights.peak_band_rad[k])
        out *= (band / np.maximum(below, band)) ** np.float32(lights.falloff[k])
    if np.isfinite(lights.spread_h_rad[k]):
        side = np.arctan(np.abs(tan_left)) * np.float32(1.0 / lights.spread_h_rad[k])
        floor = np.float32(lights.floor_h[k])
        out *= floor + (1 - floor) * np.exp(-side * side)
    return out


def _beam_axes(yaw_rad: np.ndarray, pitch_down_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) beam axes and up vectors of headlights on vehicles with the given yaw (flat road)."""
    p = np.radians(pitch_down_deg)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    axis = np.column_stack([c * np.cos(p), s * np.cos(p), np.full_like(c, -np.sin(p))])
    up = np.column_stack([c * np.sin(p), s * np.sin(p), np.full_like(c, np.cos(p))])
    return axis, up


def _headlight_spots(position: np.ndarray, axis: np.ndarray, up: np.ndarray, lamps: np.ndarray,
                     cfg: HeadlightConfig, shadows: bool) -> SpotLights:
    """One light per vehicle carrying ``lamps`` (n,) lamps' worth of intensity, and with ``cfg.above_cutoff_share``
    a second one for the light above its cut-off (:func:`above_cutoff_lights`)."""
    rgb = cfg.intensity * np.asarray(cfg.color_rgb)[None, :] * np.asarray(lamps, np.float64)[:, None]
    spread = np.inf if cfg.horizontal_falloff_deg is None else np.radians(cfg.horizontal_falloff_deg)
    beams = _spots(position, axis, up, rgb, np.tan(np.radians(cfg.half_angle_h_deg)),
                   np.tan(np.radians(cfg.half_angle_v_deg)), np.tan(np.radians(cfg.half_angle_up_deg)), cfg.soft_edge,
                   cfg.range_m, shadows, np.radians(cfg.peak_band_deg), cfg.vertical_falloff, spread,
                   cfg.horizontal_floor)
    if cfg.above_cutoff_share <= 0 or not len(beams):
        return beams
    return SpotLights.concatenate([beams, above_cutoff_lights(beams, cfg)])


def above_cutoff_lights(beams: SpotLights, cfg: HeadlightConfig) -> SpotLights:
    """The light low ``beams`` send above their cut-off: for each, a uniform cone of ``cfg.above_cutoff_share`` of
    its peak intensity, as wide as the beam, from the beam's axis (so that it overlaps the beam's top, where the
    beam fades out over its soft edge) to ``cfg.above_cutoff_deg`` over the cut-off (fading out over its own soft
    edge). A real low beam is not dark above its cut-off: ECE R112 caps that zone at 625 cd (1 lx at 25 m; 2 % of a
    30,000 cd beam) and asks for some light there to read signs by; it is what lights the back of a van or the body
    of a person standing a few metres ahead above the height of the lamps, which a beam cut off to nothing left
    black at night."""
    # Tilt each beam's axis up, about its left direction, to the middle of that band.
    half = 0.5 * (np.arctan(beams.tan_up) + np.radians(cfg.above_cutoff_deg))
    c, s = np.cos(half)[:, None], np.sin(half)[:, None]
    axis, up = beams.axis * c + beams.up * s, beams.up * c - beams.axis * s
    tan_v = np.tan(half)
    # The beams' colour and strength, scaled down to the share (rgb is the peak's irradiance at 1 m).
    return _spots(beams.position_m, axis, up, beams.rgb * np.float32(cfg.above_cutoff_share), beams.tan_h, tan_v,
                  tan_v, beams.soft, beams.range_m, beams.shadows)


def ego_headlights(ego_pose: Transform, cfg: HeadlightConfig, ego_size_m=DEFAULT_EGO_SIZE_M, *,
                   pair: bool = False) -> SpotLights:
    """The ego's low beams (one light of two lamps; ``pair``: the two lamps, HEADLAMP_INSET_M in from the car's
    sides, as the air in front of them shows them: the beams in fog); ``ego_pose`` maps the ego frame (origin at
    its box centre) to the world. No shadow rays: the camera sits next to the lamps, so it sees almost none of their
    shadows.
    """
    size = np.asarray(ego_size_m, np.float64)
    local = HEADLIGHT_UNIT_XYZ * size + [HEADLIGHT_AHEAD_M, 0.0, 0.0]
    fwd = ego_pose.rotation[:, 0]
    yaw = np.arctan2(fwd[1], fwd[0])
    if not pair:
        axis, up = _beam_axes(np.array([yaw]), cfg.pitch_down_deg)
        return _headlight_spots(ego_pose.apply(local[None]), axis, up, np.array([2.0]), cfg, False)
    side = 0.5 * size[1] - HEADLAMP_INSET_M
    lamps = np.array([local + [0.0, side, 0.0], local - [0.0, side, 0.0]])
    axis, up = _beam_axes(np.array([yaw, yaw]), cfg.pitch_down_deg)
    return _headlight_spots(ego_pose.apply(lamps), axis, up, np.array([1.0, 1.0]), cfg, False)


def vehicle_headlights(
    actors: Actors, cfg: HeadlightConfig, camera_xyz_m: np.ndarray, forward: np.ndarray | None = None
) -> SpotLights:
    """Low beams of the ``cfg.max_other_vehicles`` motor vehicles with their lights on (:attr:`Actors.lights_on`:
    not parked ones) whose beams come nearest the camera: one light per vehicle at the middle of its front face, two
    lamps' worth (one for a motorcycle).

    With ``forward`` (3,) (the ego's heading), vehicles whose lamps are behind the camera are left out: the
    ego (not in the scene, so it casts no shadow) would block most of their light.
    """
    lit = np.isin(actors.class_codes, [list(ObjectClass).index(c) for c in LIT_CLASSES]) & actors.lights_on
    if forward is not None and len(actors):
        yaw_all = actors.boxes.yaw_rad
        front = actors.boxes.center + 0.5 * actors.boxes.size[:, :1] * np.column_stack(
            [np.cos(yaw_all), np.sin(yaw_all), np.zeros(len(actors))])
        lit &= (front - camera_xyz_m) @ np.asarray(forward, np.float64) > 0.0
    lit = np.flatnonzero(lit)
    if not len(lit) or cfg.max_other_vehicles == 0:
        return SpotLights.empty()
    boxes = actors.boxes
    yaw = boxes.yaw_rad[lit]
    fwd = np.column_stack([np.cos(yaw), np.sin(yaw), np.zeros(len(lit))])
    # Distance from the camera to the middle of the lit region (the beam reaches ~range ahead).
    mid = boxes.center[lit] + fwd * (0.5 * boxes.size[lit, :1] + 0.25 * cfg.range_m)
    dist = np.linalg.norm(mid - camera_xyz_m, axis=1) - 0.3 * cfg.range_m
    order = np.argsort(dist, kind="stable")[: cfg.max_other_vehicles]
    chosen = lit[order][dist[order] < cfg.range_m + 60.0]
    if not len(chosen):
        return SpotLights.empty()
    lamps = np.array([1.0 if actors.object_class[i] == ObjectClass.MOTORCYCLE else 2.0 for i in chosen])
    affine = unit_to_world(boxes)[chosen]  # (n, 3, 4)
    yaw_c = boxes.yaw_rad[chosen]
    pos = affine[:, :, :3] @ HEADLIGHT_UNIT_XYZ + affine[:, :, 3]
    pos += np.column_stack([np.cos(yaw_c), np.sin(yaw_c), np.zeros(len(chosen))]) * HEADLIGHT_AHEAD_M
    axis, up = _beam_axes(yaw_c, cfg.pitch_down_deg)
    return _headlight_spots(pos, axis, up, lamps, cfg, cfg.shadows)


def street_lamp_lights(positions_m: np.ndarray, cfg: StreetLampConfig, camera_xyz_m: np.ndarray) -> SpotLights:
    """The ``cfg.max_lamps`` lamps nearest the camera within ``cfg.max_distance_m``: downward cones."""
    positions_m = np.asarray(positions_m, np.float64).reshape(-1, 3)
    if not len(positions_m) or cfg.max_lamps == 0:
        return SpotLights.empty()
    dist = np.linalg.norm(positions_m - camera_xyz_m, axis=1)
    order = np.argsort(dist, kind="stable")[: cfg.max_lamps]
    chosen = positions_m[order[dist[order] <= cfg.max_distance_m]]
    n = len(chosen)
    tan = np.tan(np.radians(cfg.half_angle_deg))
    return _spots(chosen, np.tile([0.0, 0.0, -1.0], (n, 1)), np.tile([1.0, 0.0, 0.0], (n, 1)),
                  cfg.intensity * np.asarray(cfg.color_rgb), tan, tan, tan, cfg.soft_edge, cfg.range_m, cfg.shadows)


class PointGrid:
    """Points bucketed in a 2D (x, y) grid of at most 256 x 256 cells (cell ids radix-sorted once), for range
    queries by light. ``order`` lists the points cell by cell; a query returns positions in that order."""

    def __init__(self, x: np.ndarray, y: np.ndarray, min_cell_m: float = 2.0) -> None:
        self.lo = np.array([x.min(), y.min()], np.float64) if len(x) else np.zeros(2)
        extent = np.array([x.max(), y.max()], np.float64) - self.lo if len(x) else np.zeros(2)
        self.cell = np.maximum(min_cell_m, extent / 255.999)
        self.n = np.minimum(np.floor(extent / self.cell).astype(np.int64) + 1, 256)
        i = np.minimum((x - np.float32(self.lo[0])) * np.float32(1.0 / self.cell[0]), self.n[0] - 1).astype(np.uint16)
        j = np.minimum((y - np.float32(self.lo[1])) * np.float32(1.0 / self.cell[1]), self.n[1] - 1).astype(np.uint16)
        cid = i * np.uint16(self.n[1]) + j
        self.order = np.argsort(cid, kind="stable")  # radix sort on 16-bit keys
        self.start = np.concatenate([[0], np.cumsum(np.bincount(cid, minlength=int(self.n.prod())))])

    def query_cone(self, lights: SpotLights, k: int) -> np.ndarray:
        """Positions (in ``order``) of the points in the cells that light ``k`` may reach: cells within its
        range (horizontally) and, seen from above, inside its horizontal half-angle, each grown by a cell radius
        (vectorised over cells; the exact per-point test is the caller's)."""
        ny = int(self.n[1])
        cells = np.flatnonzero(self.start[1:] > self.start[:-1])  # non-empty cells
        centre = self.lo + (np.column_stack([cells // ny, cells % ny]) + 0.5) * self.cell
        grow = 0.5 * float(np.hypot(*self.cell))
        rel = centre - lights.position_m[k, :2]
        dist = np.hypot(rel[:, 0], rel[:, 1])
        axis = lights.axis[k, :2]
        flat = float(np.hypot(*axis))
        reach = lights.range_m[k]
        if flat < 0.2:  # pointing (nearly) straight down or up: a disc under the cone
            half = np.arctan(max(lights.tan_h[k], lights.tan_v[k]))
            reach = lights.range_m[k] * min(1.0, np.sin(half) + flat)
            near = dist <= reach + grow
        else:
            cos_angle = (rel @ (axis / flat)) / np.maximum(dist, 1e-9)
            spread = np.arctan(lights.tan_h[k]) + np.arcsin(np.clip(grow / np.maximum(dist, 1e-9), 0.0, 1.0))
            near = (dist <= reach + grow) & ((cos_angle >= np.cos(np.minimum(spread, np.pi))) | (dist <= grow))
        cells = cells[near]
        if not len(cells):
            return np.zeros(0, np.int64)
        lengths = self.start[cells + 1] - self.start[cells]
        # Positions of all points of the chosen cells, without a Python loop over cells.
        offsets = np.repeat(self.start[cells] - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
        return np.arange(int(lengths.sum())) + offsets


def spot_strength(lights: SpotLights, k: int, v: list[np.ndarray], d2: np.ndarray, axial: np.ndarray) -> np.ndarray:
    """(M,) float32 irradiance of light ``k`` at M points in units of its ``rgb`` (on a surface facing it): the
    cone's soft edge, the range window, the inverse square (clamped at MIN_DISTANCE_M) and the beam pattern.
    ``v``: the three (M,) float32 components of each point's offset to the light; ``d2`` (M,) its square length;
    ``axial`` (M,) > 0 the point's distance ahead of the light along its axis. The numpy definition that the
    compiled :func:`cone_terms` (the surfaces' and the air's passes) repeats and is tested against."""
    left, up = np.cross(lights.up[k], lights.axis[k]).astype(np.float32), lights.up[k].astype(np.float32)
    # Tangents of the angles to the left of and above the axis (v points from the point to the light).
    tan_left = (v[0] * left[0] + v[1] * left[1] + v[2] * left[2]) / axial
    tan_above = -(v[0] * up[0] + v[1] * up[1] + v[2] * up[2]) / axial
    a = tan_left * np.float32(1.0 / lights.tan_h[k])
    b = tan_above / np.where(tan_above > 0, np.float32(lights.tan_up[k]), np.float32(lights.tan_v[k]))
    edge = np.clip((1.0 - np.sqrt(a * a + b * b)) * np.float32(1.0 / lights.soft[k]), 0.0, 1.0)
    window = np.clip(1.0 - (d2 * np.float32(1.0 / lights.range_m[k] ** 2)) ** 2, 0.0, 1.0) ** 2
    strength = edge * edge * (3.0 - 2.0 * edge) * window / np.maximum(d2, np.float32(MIN_DISTANCE_M ** 2))
    strength *= beam_pattern(tan_left, tan_above, lights, k)
    return strength


def light_radiance(
    scene: FrameScene,
    rays: np.ndarray,
    hits: Hits,
    lights: SpotLights,
    albedo: np.ndarray,
    specular: np.ndarray,
    shininess: np.ndarray,
) -> np.ndarray:
    """(N, 3) float32 radiance that ``lights`` add to N camera hits: albedo * E + specular highlights +
    retroreflection (module docstring; the material of each hit from ``hits.material``).

    Args:
        rays: (N, 6) float32 [origin | unit direction], world. hits: their first hits.
        albedo: (N, 3) float32 per-hit albedo; specular, shininess: (N,) float32 per-hit Blinn-Phong terms.

    The hits are bucketed once (:class:`PointGrid`); per light, one compiled pass (:func:`_lit_pairs`) over its
    grid candidates makes the cheap test (range, in front of the light, facing it), the cone, beam pattern and
    shading terms, in the float32 arithmetic of :func:`spot_strength` and :func:`beam_pattern`; shadow rays then
    drop the pairs an occluder hides.
    """
    n = len(rays)
    hit_idx = np.flatnonzero(hits.hit)
    if not len(lights) or not len(hit_idx):
        return np.zeros((n, 3), np.float32)
    t = hits.t_m[hit_idx]
    ray = take_columns(rays, hit_idx)
    px, py = ray[0] + ray[3] * t, ray[1] + ray[4] * t
    grid = PointGrid(px, py)
    src_all = hit_idx[grid.order]
    # Sorted (3, M) float32 rows: position, normal, view direction (towards the camera).
    pos = np.stack([np.take(c, grid.order) for c in (px, py, ray[2] + ray[5] * t)])
    nrm = np.stack([np.take(hits.normal[:, k], src_all) for k in range(3)]).astype(np.float32)
    view = np.stack([-np.take(ray[3 + k], grid.order) for k in range(3)])
    retro = np.take(_RETRO, np.take(hits.material, src_all))
    spec = as_input(specular, np.float32)
    shine = as_input(shininess, np.float32)
    diffuse = [np.zeros(n, np.float32) for _ in range(3)]
    shiny = [np.zeros(n, np.float32) for _ in range(3)]
    for k in range(len(lights)):  # loop over lights; every point in reach in one compiled pass
        cand = grid.query_cone(lights, k)
        if not len(cand):
            continue
        kept, w, s, start, seg = _lit_pairs(as_input(cand, np.int64), pos, nrm, view, retro, src_all, spec, shine,
                                            light_params(lights, k))
        if not len(kept):
            continue
        src = src_all[kept]
        if lights.shadows[k]:
            # Directions span the segment to the light, so tfar = 1 covers exactly the part that can shadow. Each
            # segment leaves 2 mm off its surface and stops 5 cm short of the lamp (_lit_pairs): it stays within
            # SEGMENT_STRAY_M of the line from the lamp through its start, so its actors come from bins about the lamp.
            lit = ~scene.occluded_rays(np.concatenate([start, seg], axis=1), 1.0,
                                       toward=(lights.position_m[k], SEGMENT_STRAY_M))
            src, w, s = src[lit], w[lit], s[lit]
        for c in range(3):  # ``src`` is unique within one light, so fancy-index accumulation is exact
            diffuse[c][src] += w * np.float32(lights.rgb[k, c])
            shiny[c][src] += s * np.float32(lights.rgb[k, c])
    albedo = cv2.split(np.ascontiguousarray(albedo, np.float32).reshape(-1, 1, 3))
    return cv2.merge([albedo[c].reshape(-1) * diffuse[c] + shiny[c] for c in range(3)]).reshape(-1, 3)


# The float32 parameters of one light for _lit_pairs, in this order.
_PARAMS = ("lp", "ax", "left", "up", "range2", "inv_tan_h", "tan_up", "tan_v", "inv_soft", "inv_range2", "min_d2",
           "falloff", "atan_tan_up", "band", "spread", "inv_spread", "floor", "rgb_max", "min_irradiance",
           "retro_peak")


def light_params(lights: SpotLights, k: int) -> np.ndarray:
    """Light ``k``'s values as :func:`_lit_pairs` reads them (float32, rounded as :func:`spot_strength` and
    :func:`beam_pattern` round them)."""
    f32 = np.float32
    left = np.cross(lights.up[k], lights.axis[k]).astype(np.float32)
    spread = np.isfinite(lights.spread_h_rad[k])
    values = [*lights.position_m[k].astype(np.float32), *lights.axis[k].astype(np.float32), *left,
              *lights.up[k].astype(np.float32), f32(lights.range_m[k] ** 2), f32(1.0 / lights.tan_h[k]),
              f32(lights.tan_up[k]), f32(lights.tan_v[k]), f32(1.0 / lights.soft[k]),
              f32(1.0 / lights.range_m[k] ** 2), f32(MIN_DISTANCE_M ** 2), f32(lights.falloff[k]),
              f32(np.arctan(lights.tan_up[k])), f32(lights.peak_band_rad[k]), f32(spread),
              f32(1.0 / lights.spread_h_rad[k]) if spread else f32(0), f32(lights.floor_h[k]), f32(lights.rgb[k].max()),
              f32(MIN_IRRADIANCE), f32(RETRO_PEAK)]
    return np.array(values, np.float32)


@kernel("UniTuple(float32, 2)(float32[::1], float32, float32, float32, float32, float32)")
def cone_terms(p, v0, v1, v2, d2, axial):
    """Light ``p``'s (:func:`light_params`) terms at a point whose offset to the light is (v0, v1, v2), ``d2`` its
    square length and ``axial`` > 0 its distance ahead along the axis: (the cone's smoothstep edge x the range window,
    the beam pattern), in :func:`spot_strength`'s float32 arithmetic (whose strength is the first over
    max(d2, MIN_DISTANCE_M^2), times the second). (0, 0) outside the cone or at its range. Shared by the surfaces'
    pass (:func:`_lit_pairs`) and the air's (:mod:`pipeline.sensors.beams`)."""
    f = np.float32
    tan_left = (v0 * p[6] + v1 * p[7] + v2 * p[8]) / axial
    tan_above = -(v0 * p[9] + v1 * p[10] + v2 * p[11]) / axial
    a = tan_left * p[13]
    b = tan_above / (p[14] if tan_above > 0 else p[15])
    edge = min(max((f(1.0) - np.sqrt(a * a + b * b)) * p[16], f(0.0)), f(1.0))
    window = min(max(f(1.0) - (d2 * p[17]) * (d2 * p[17]), f(0.0)), f(1.0))
    window = window * window
    if edge <= 0 or window <= 0:
        return f(0.0), f(0.0)
    pattern = f(1.0)
    if p[19] > 0:
        below = p[20] - np.arctan(tan_above)
        pattern *= (p[21] / max(below, p[21])) ** p[19]
    if p[22] > 0:
        side = np.arctan(abs(tan_left)) * p[23]
        pattern *= p[24] + (f(1) - p[24]) * np.exp(-side * side)
    return edge * edge * (f(3.0) - f(2.0) * edge) * window, pattern


@kernel("Tuple((int64[::1], float32[::1], float32[::1], float32[:, ::1], float32[:, ::1]))(int64[::1], "
        "float32[:, ::1], float32[:, ::1], float32[:, ::1], float32[::1], int64[::1], float32[::1], float32[::1], "
        "float32[::1])")
def _lit_pairs(cand, pos, nrm, view, retro, src_all, specular, shininess, p):
    """One light's pairs with the hits ``cand`` (positions in the sorted (3, M) ``pos``, ``nrm``, ``view`` rows and
    (M,) ``retro``; ``src_all`` maps them to hit indices for the (N,) ``specular`` and ``shininess``), the light's
    values ``p`` (:func:`light_params`). Keeps the pairs in range, in front of the light, facing it and bright
    enough (:data:`MIN_IRRADIANCE` with highlights and retroreflection at their most), and gives each its diffuse
    weight w (irradiance x n.l, plus retroreflection) and specular s per unit of the light's rgb, and the start and
    segment of its shadow ray. The arithmetic is :func:`spot_strength`'s, :func:`beam_pattern`'s and
    :func:`retro_angle_factor`'s, in float32, term by term."""
    f = np.float32
    count = cand.size
    kept = np.empty(count, np.int64)
    w_out = np.empty(count, np.float32)
    s_out = np.empty(count, np.float32)
    start = np.empty((count, 3), np.float32)
    seg = np.empty((count, 3), np.float32)
    n = 0
    for q in range(count):
        i = cand[q]
        v0, v1, v2 = p[0] - pos[0, i], p[1] - pos[1, i], p[2] - pos[2, i]
        d2 = v0 * v0 + v1 * v1 + v2 * v2
        axial = -(v0 * p[3] + v1 * p[4] + v2 * p[5])
        n0, n1, n2 = nrm[0, i], nrm[1, i], nrm[2, i]
        n_dot_v = n0 * v0 + n1 * v1 + n2 * v2
        if not (d2 < p[12] and axial > 0 and n_dot_v > 0):
            continue
        inv_d = f(1.0) / np.sqrt(d2)
        cone, pattern = cone_terms(p, v0, v1, v2, d2, axial)
        if cone <= 0:  # outside the cone or at its range: no light (and nothing bright enough)
            continue
        strength = cone / max(d2, p[18])
        strength *= pattern
        r = retro[i]
        gain = f(1.0) + r * p[27]
        if not strength * gain * p[25] > p[26]:
            continue
        h0, h1, h2 = v0 * inv_d + view[0, i], v1 * inv_d + view[1, i], v2 * inv_d + view[2, i]
        n_dot_h = (n0 * h0 + n1 * h1 + n2 * h2) / np.sqrt(h0 * h0 + h1 * h1 + h2 * h2 + f(1e-12))
        src = src_all[i]
        spec = specular[src] * min(max(n_dot_h, f(0.0)), f(1.0)) ** shininess[src]
        w = strength * n_dot_v * inv_d
        if r > 0:  # retroreflectors: E_perp = strength
            cos_alpha = (v0 * view[0, i] + v1 * view[1, i] + v2 * view[2, i]) * inv_d
            alpha = np.arccos(min(max(cos_alpha, f(-1.0)), f(1.0)))
            ratio = alpha * f(1.0 / RETRO_WIDTH_RAD)
            factor = f(RETRO_REFERENCE_RAD) / max(alpha, f(RETRO_MIN_RAD)) * np.exp(-ratio * ratio)
            w += strength * r * factor
        kept[n] = i
        w_out[n] = w
        s_out[n] = strength * spec
        start[n, 0] = pos[0, i] + n0 * f(2e-3)
        start[n, 1] = pos[1, i] + n1 * f(2e-3)
        start[n, 2] = pos[2, i] + n2 * f(2e-3)
        stop = f(1.0) - f(0.05) * inv_d  # stop 5 cm short of the lamp
        seg[n, 0] = v0 * stop
        seg[n, 1] = v1 * stop
        seg[n, 2] = v2 * stop
        n += 1
    return kept[:n].copy(), w_out[:n].copy(), s_out[:n].copy(), start[:n].copy(), seg[:n].copy()
