"""Water on surfaces in the rain: a condition's ``wetness`` w in [0, 1] (:attr:`Condition.wetness`: the share of the
road's texture its water fills, :mod:`pipeline.sensors.weather`).

- **Roads** (WET_ROAD_MATERIALS): a wet road is darker (albedo x (1 - 0.55 w): water fills the pores and traps light
  by total internal reflection; Lekner and Dorf 1988), its highlight stronger and sharper (specular raised to at least
  0.6 w, shininess WET_SHININESS). Water stands in the road's hollows: puddles (:func:`puddles`, a share PUDDLE_SHARE
  w^2 of the road, in patches of a few metres) are soaked (darkened as at w = 1) and smooth.
- **Road reflections** (the realistic camera, :func:`road_reflections`): the water's surface mirrors the scene with
  the water's Fresnel weight (Schlick, F0 = 0.02): lamps, lit windows, vehicles and their lights, the sky. The mirror
  rays of the pixel centres on wet road are traced and shaded (sun, sky, glowing lamps, spot lights; no shadows) and
  dimmed by the fog and rain over both legs of the path. A puddle is a sharp mirror; elsewhere the film over the
  texture's peaks is rough, and its reflection spreads along the image's vertical (the streaks of lights on a wet road:
  microfacets tilted towards the camera reflect what lies above and below the mirror point) over GLOSS_SIGMA_RAD x
  (1 - w) + PUDDLE_SIGMA_RAD of angle, and that times the sine of the view's grazing angle across (:func:`_lobes`).
  The reflected share weighs F (w on the film, 1 in puddles), the surface's own radiance 1 - that. The fast camera
  instead adds w * WET_SHEEN * Fresnel * the sky in the mirrored direction (:func:`wet_sheen`; the scene itself is not
  traced there).
- **Vehicles** (WET_VEHICLE_MATERIALS on actors: paint and glass): a water film over the clear coat. Its outer face
  is a second mirror over the coat's: the mirror reflection (:func:`pipeline.sensors.indirect.reflections`) weighs
  F = F_coat + w F_water (1 - F_coat), both Schlick's, the water's with F0 = 0.02 (the layered-coat approximation
  real-time renderers use for wet surfaces; it keeps the coat's own Fresnel as in air, an upper bound: under water
  the coat's face reflects less). At normal incidence that adds ~2 %, at grazing angles much more (at 80 degrees
  0.41 -> 0.61 for w = 0.85): roofs, bonnets and windscreens mirror the grey sky and the street. Paint is a little
  darker (albedo x (1 - WET_PAINT_DARKENING w)): a smooth coat is no porous surface, and the film only wets the
  micro-roughness of its top. Beads and runnels are not modelled.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np

from pipeline.core.jit import as_input
from pipeline.sensors.sky import sky_rays
from pipeline.world.materials import material_index
from pipeline.world.scene import FrameScene, Hits, rowdot

if TYPE_CHECKING:
    from pipeline.sensors.conditions import Condition
    from pipeline.sensors.lights import SpotLights

WET_ROAD_MATERIALS = ("asphalt", "lane_paint", "concrete", "kerb")
WET_ROAD_DARKENING = 0.55
WET_SHININESS = 80.0
WATER_F0 = 0.02
WET_SHEEN = 0.5  # share of the mirrored sky kept on the road: the scene itself (buildings, cars) is not traced
WET_VEHICLE_MATERIALS = ("paint", "glass")
WET_PAINT_DARKENING = 0.15
PUDDLE_SHARE = 0.25  # of the road under standing water at w = 1 (a modelling choice: hollows, ruts, worn patches)
PUDDLE_WAVELENGTHS_M = (4.0, 1.3)  # noise octaves of the puddles' outline
GLOSS_SIGMA_RAD = 0.06  # the film's reflection lobe at w -> 0 (wet asphalt's microfacet spread)
PUDDLE_SIGMA_RAD = 0.002  # a puddle's (ripples)
REFLECTION_RANGE_M = 80.0  # wet road farther from the camera mirrors only the sky (the fast camera's sheen)


@dataclass(frozen=True)
class Wet:
    """Where the rain wets a frame's hits.

    Attributes:
        road: (M,) int64 the hits on wet road-like materials (they get :func:`wet_sheen`).
        film: (N,) float32 per hit, the water film's weight on actors' paint and glass (w there, 0 elsewhere), for
            the mirror reflections.
    """

    road: np.ndarray
    film: np.ndarray


def _hash01(ix: np.ndarray, iy: np.ndarray, seed: int) -> np.ndarray:
    """A value in [0, 1) hashed from integer lattice points (uint32 mixing, the same on every machine)."""
    h = (ix.astype(np.uint32) * np.uint32(0x27D4EB2D)) ^ (iy.astype(np.uint32) * np.uint32(0x165667B1))
    h ^= np.uint32(seed * 0x9E3779B1 & 0xFFFFFFFF)
    h ^= h >> np.uint32(15)
    h *= np.uint32(0x2C1B3C6D)
    h ^= h >> np.uint32(12)
    h *= np.uint32(0x297A2D39)
    h ^= h >> np.uint32(15)
    return h.astype(np.float64) * (1.0 / 4294967296.0)


def _value_noise(x: np.ndarray, y: np.ndarray, seed: int) -> np.ndarray:
    """Value noise in [0, 1) at (x, y) (lattice spacing 1), smoothly interpolated."""
    fx, fy = np.floor(x), np.floor(y)
    ix, iy = fx.astype(np.int64), fy.astype(np.int64)
    u, v = x - fx, y - fy
    u, v = u * u * (3.0 - 2.0 * u), v * v * (3.0 - 2.0 * v)
    a = _hash01(ix, iy, seed) * (1 - u) + _hash01(ix + 1, iy, seed) * u
    b = _hash01(ix, iy + 1, seed) * (1 - u) + _hash01(ix + 1, iy + 1, seed) * u
    return a * (1 - v) + b * v


def _puddle_field(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The puddles' noise at world (x, y), metres: two octaves, weights 2:1."""
    (big, small) = PUDDLE_WAVELENGTHS_M
    return (2.0 * _value_noise(x / big, y / big, 11) + _value_noise(x / small, y / small, 12)) / 3.0


@functools.lru_cache(maxsize=1)
def _field_quantiles() -> np.ndarray:
    """(1001,) the puddle field's quantiles 0, 0.001, .., 1, measured once on a fixed grid of 1 km^2."""
    g = np.arange(0.0, 1000.0, 0.9)
    x, y = np.meshgrid(g, g * 1.0007 + 0.31)
    return np.quantile(_puddle_field(x.ravel(), y.ravel()), np.linspace(0.0, 1.0, 1001))


def puddles(x: np.ndarray, y: np.ndarray, wetness: float) -> np.ndarray:
    """(N,) bool: the road points at world (x, y), metres, under standing water (a share PUDDLE_SHARE w^2 of them)."""
    share = PUDDLE_SHARE * wetness ** 2
    if share <= 0:
        return np.zeros(np.shape(x), bool)
    return _puddle_field(np.asarray(x, np.float64), np.asarray(y, np.float64)) > np.interp(
        1.0 - share, np.linspace(0.0, 1.0, 1001), _field_quantiles())


def wet_surfaces(hits: Hits, mats: dict[str, np.ndarray], wetness: float, rays: np.ndarray | None = None
                 ) -> tuple[Wet, Hits, dict[str, np.ndarray]]:
    """The wet hits, the hits with their albedo darkened there (more in puddles, given the (N, 6) ``rays`` that
    locate them), and the material tables with the roads' highlight raised (copies; the inputs are left as they
    were)."""
    road_ids = np.array([material_index(n) for n in WET_ROAD_MATERIALS])
    road = np.flatnonzero(hits.hit & np.isin(hits.material, road_ids))
    vehicle = hits.hit & (hits.instance_id > 0) & np.isin(hits.material,
                                                          [material_index(n) for n in WET_VEHICLE_MATERIALS])
    color = hits.color.copy()
    color[road] *= np.float32(1.0 - WET_ROAD_DARKENING * wetness)
    if rays is not None and len(road):
        t = hits.t_m[road].astype(np.float64)
        standing = road[puddles(rays[road, 0] + rays[road, 3] * t, rays[road, 1] + rays[road, 4] * t, wetness)]
        color[standing] *= np.float32((1.0 - WET_ROAD_DARKENING) / (1.0 - WET_ROAD_DARKENING * wetness))
    paint = np.flatnonzero(vehicle & (hits.material == material_index("paint")))
    color[paint] *= np.float32(1.0 - WET_PAINT_DARKENING * wetness)
    mats = dict(mats)
    mats["specular"] = mats["specular"].copy()
    mats["shininess"] = mats["shininess"].copy()
    mats["specular"][road_ids] = np.maximum(mats["specular"][road_ids], 0.6 * wetness)
    mats["shininess"][road_ids] = WET_SHININESS
    film = np.where(vehicle, np.float32(wetness), np.float32(0.0)).astype(np.float32)
    return Wet(road, film), dataclasses.replace(hits, color=color), mats


def wet_sheen(rays: np.ndarray, normal: np.ndarray, sky_params: np.ndarray, wetness: float) -> np.ndarray:
    """(M, 3) float32 sky mirrored by a road's water film: wetness * WET_SHEEN * Fresnel(Schlick, WATER_F0) * the
    sky (``sky_params``: :mod:`pipeline.sensors.sky`) in the reflected direction, for (M, 6) rays meeting surfaces
    with (M, 3) unit normals."""
    d = rays[:, 3:]
    cos_v = np.clip(-rowdot(d, normal), 0.0, 1.0)
    fresnel = WATER_F0 + (1.0 - WATER_F0) * (1.0 - cos_v) ** 5
    reflected = d + 2.0 * cos_v[:, None] * normal
    return (sky_rays(reflected, sky_params) * (WET_SHEEN * wetness * fresnel)[:, None]).astype(np.float32)


@dataclass(frozen=True)
class RoadReflection:
    """The wet road's reflection on a frame's pixels: radiance[rows] = radiance[rows] * keep + add.

    Attributes:
        rows: (K,) int64 pixels (row-major) on wet road. keep: (K, 1) float32 the surface's own share (1 - F).
        add: (K, 3) float32 the reflected radiance times its weight F.
    """

    rows: np.ndarray
    keep: np.ndarray
    add: np.ndarray

    def apply(self, radiance: np.ndarray, only: np.ndarray | None = None) -> None:
        """Blend the reflection into (H*W, 3) ``radiance`` in place; ``only`` (sorted (M,) int64 pixels): there only."""
        pick = slice(None) if only is None else np.isin(self.rows, only)
        rows = self.rows[pick]
        radiance[rows] = radiance[rows] * self.keep[pick] + self.add[pick]


def road_reflections(scene: FrameScene, rays: np.ndarray, hits: Hits, condition: Condition,
                     lights: SpotLights | None, image_shape: tuple[int, int], fy_px: float) -> RoadReflection | None:
    """The wet road's reflections on a frame's H*W pixel-centre rays (row-major) and their ``hits`` (module
    docstring); None where nothing is wet. ``fy_px``: the camera's focal length in pixels (the lobes' spread)."""
    from pipeline.sensors.indirect import mirror_rays
    from pipeline.sensors.shading import shade

    wetness = condition.wetness
    road_ids = np.array([material_index(n) for n in WET_ROAD_MATERIALS])
    rows = np.flatnonzero(hits.hit & np.isin(hits.material, road_ids) & (hits.t_m < REFLECTION_RANGE_M))
    if wetness <= 0 or not len(rows):
        return None
    t = np.where(hits.hit, hits.t_m, 0.0).astype(np.float32)
    f0 = np.full(len(rows), WATER_F0, np.float32)
    mirror, fresnel = mirror_rays(as_input(rays, np.float32), t, as_input(hits.normal, np.float32), rows, f0,
                                  np.zeros(len(rows), np.float32), np.float32(WATER_F0))
    bounce = scene.cast_rays(mirror)
    env = shade(scene, mirror, bounce, condition, lights)
    env = condition.fog(env, np.where(bounce.hit, bounce.t_m, np.inf) + t[rows], bounce.hit)
    tr = t[rows].astype(np.float64)
    standing = puddles(rays[rows, 0] + rays[rows, 3] * tr, rays[rows, 1] + rays[rows, 4] * tr, wetness)
    h, w = image_shape
    keep = np.ones((len(rows), 1), np.float32)
    add = np.zeros((len(rows), 3), np.float32)
    # Sharp puddles, then the rough film: each reflection (weighted) and its weight spread over the road's pixels and
    # divided by the road's spread mask, so that the lobes do not bleed off the road.
    # The view's grazing angle at each hit (sin: its cosine to the surface's normal) narrows the lobe across.
    grazing = np.abs(rowdot(rays[rows, 3:6], hits.normal[rows]))
    for where, weight, sigma_rad in ((standing, 1.0, PUDDLE_SIGMA_RAD),
                                     (~standing, wetness, GLOSS_SIGMA_RAD * (1.0 - wetness) + PUDDLE_SIGMA_RAD)):
        sel = rows[where]
        if not len(sel):
            continue
        f = (fresnel[where] * np.float32(weight))[:, None]
        layer = np.zeros((h, w, 4), np.float32)
        layer.reshape(-1, 4)[sel, :3] = env[where] * f
        layer.reshape(-1, 4)[sel, 3] = f[:, 0]
        mask = np.zeros((h, w), np.float32)
        mask.reshape(-1)[sel] = 1.0
        sigma_v = max(2.0 * sigma_rad * fy_px, 0.3)
        spread = _lobes(layer, mask, sel, grazing[where], sigma_v)
        keep[where] = 1.0 - spread[:, 3:4]
        add[where] = spread[:, :3]
    return RoadReflection(rows, keep, add)


# Bands of the view's grazing angle (its sine) over which the lobe's width across is taken as one.
GRAZING_BANDS = (0.0, 0.04, 0.08, 0.16, 0.32, 1.0)
MIN_GRAZING = 0.02  # the first band's lower end, for its middle


def _lobes(layer: np.ndarray, mask: np.ndarray, sel: np.ndarray, grazing: np.ndarray, sigma_v: float) -> np.ndarray:
    """(len(sel), 4): the (H, W, 4) ``layer`` (weighted reflection, weight) spread over the road (``mask``) as a
    rough surface's lobe, read at the road's pixels ``sel``, divided by the spread mask (the lobes do not bleed off
    the road). A facet tilted by d turns the mirror direction by 2 d up or down, but across by only 2 d sin g at a
    grazing angle g (a glitter path: the streaks of lamps on a wet road, long and thin): the lobe is ``sigma_v``
    pixels along the image's vertical and sigma_v sin g across, g taken per GRAZING_BANDS band (its geometric
    middle) of the receiving pixel, each band blurred over its own rows and those its lobe reaches."""
    h, w = mask.shape
    out = np.zeros((len(sel), 4), np.float32)
    reach = int(np.ceil(4.0 * sigma_v)) + 1  # OpenCV's Gaussian kernel reaches 4 sigma (float images)
    row = sel // w
    for lo, hi in itertools.pairwise(GRAZING_BANDS):
        band = np.flatnonzero((grazing >= lo) & (grazing < hi) if hi < 1.0 else grazing >= lo)
        if not len(band):
            continue
        r0, r1 = max(int(row[band].min()) - reach, 0), min(int(row[band].max()) + reach + 1, h)
        sigma_h = max(sigma_v * float(np.sqrt(max(lo, MIN_GRAZING) * hi)), 0.3)
        blur = functools.partial(cv2.GaussianBlur, ksize=(0, 0), sigmaX=sigma_h, sigmaY=sigma_v,
                                 borderType=cv2.BORDER_REPLICATE)
        local = sel[band] - r0 * w
        spread = blur(layer[r0:r1]).reshape(-1, 4)[local]
        spread /= np.maximum(blur(mask[r0:r1]).reshape(-1)[local], 1e-6)[:, None]
        out[band] = spread
    return out
