"""Water on surfaces in the rain: a condition's ``wetness`` w in [0, 1] (:attr:`Condition.wetness`).

- **Roads** (WET_ROAD_MATERIALS): a wet road is darker (albedo x (1 - 0.55 w): water fills the pores and traps light
  by total internal reflection; Lekner and Dorf 1988), its highlight stronger and sharper (specular raised to at least
  0.6 w, shininess WET_SHININESS), and it mirrors the sky: w * WET_SHEEN * Fresnel (Schlick, water F0 = 0.02) * the sky
  in the mirrored direction (:func:`wet_sheen`; the scene itself is not traced there).
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
from dataclasses import dataclass

import numpy as np

from pipeline.sensors.sky import sky_rays
from pipeline.world.materials import material_index
from pipeline.world.scene import Hits, rowdot

WET_ROAD_MATERIALS = ("asphalt", "lane_paint", "concrete", "kerb")
WET_ROAD_DARKENING = 0.55
WET_SHININESS = 80.0
WATER_F0 = 0.02
WET_SHEEN = 0.5  # share of the mirrored sky kept on the road: the scene itself (buildings, cars) is not traced
WET_VEHICLE_MATERIALS = ("paint", "glass")
WET_PAINT_DARKENING = 0.15


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


def wet_surfaces(hits: Hits, mats: dict[str, np.ndarray], wetness: float
                 ) -> tuple[Wet, Hits, dict[str, np.ndarray]]:
    """The wet hits, the hits with their albedo darkened there, and the material tables with the roads' highlight
    raised (copies; the inputs are left as they were)."""
    road_ids = np.array([material_index(n) for n in WET_ROAD_MATERIALS])
    road = np.flatnonzero(hits.hit & np.isin(hits.material, road_ids))
    vehicle = hits.hit & (hits.instance_id > 0) & np.isin(hits.material,
                                                          [material_index(n) for n in WET_VEHICLE_MATERIALS])
    color = hits.color.copy()
    color[road] *= np.float32(1.0 - WET_ROAD_DARKENING * wetness)
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
