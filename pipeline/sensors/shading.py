"""Shading of camera hits: Lambert + Blinn-Phong under a sun with shadow rays, sky, ambient, local lights.

Radiance is linear RGB (arbitrary units, ~1 = white paper in full sun after ``exposure``); the image is
tone-mapped to 8-bit sRGB by :func:`to_srgb8`. Directions are world frame (x east, y north, z up).
The condition (:class:`pipeline.sensors.conditions.Condition`: morning / night / fog / rain) gives the sun, sky,
exposure, glow and wetness as properties, and the frame's spot lights (:mod:`pipeline.sensors.lights`: headlights,
street lamps); this module only shades.

In the rain (``Condition.wetness``) roads and vehicles are wet (:mod:`pipeline.sensors.wet`): darker road with a
sheen of the sky, a water film on vehicles' paint and glass that strengthens their mirror reflections.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from pipeline.core.jit import as_input, kernel
from pipeline.core.photometry import luminance_to_radiance, lux_to_irradiance
from pipeline.sensors.indirect import reflections, sky_visibility
from pipeline.sensors.lights import SpotLights, light_radiance
from pipeline.sensors.post import LINEAR_WHITE
from pipeline.sensors.shadows import sun_shares
from pipeline.sensors.sky import sky_rays
from pipeline.sensors.sunlight import sky_and_sun
from pipeline.sensors.textures import textured_albedo
from pipeline.sensors.wet import wet_sheen, wet_surfaces
from pipeline.world.materials import material_arrays, material_index
from pipeline.world.scene import FrameScene, Hits

if TYPE_CHECKING:  # the condition calls nothing here: shading only reads its properties
    from pipeline.sensors.conditions import Condition

BRAKE_LIGHT_RGB = np.array([2.0, 0.08, 0.05], np.float32)
TAIL_LIGHT_RGB = np.array([0.8, 0.03, 0.02], np.float32)
HEAD_LIGHT_RGB = np.array([3.0, 2.9, 2.6], np.float32)
STREET_LAMP_RGB = np.array([3.0, 2.4, 1.5], np.float32)
MARKER_LAMP_RGB = np.array([1.6, 0.7, 0.05], np.float32)  # amber side markers of long vehicles
# A rear plate's lamp: white light on the plate, 30 lx (ECE R4 asks a plate luminance of at least 2.5 cd/m^2 at every
# test point; 30 lx on the retroreflective white plate, albedo ~0.8, gives ~8 cd/m^2).
PLATE_LAMP_RGB = np.full(3, lux_to_irradiance(30.0), np.float32)
# A room lit behind a façade pane: warm (tungsten-like) light times the pane's textured albedo, so each window shows
# its own room, brighter or dimmer, instead of a flat saturated rectangle.
# A lit room seen through its pane has a luminance of some tens of cd/m^2 (rooms lit to 100-500 lx, walls, curtains
# and furniture of albedo 0.2-0.5, a pane passing 70 %); this light times the lit pane's albedo (0.11) gives 20 cd/m^2
# at a glow scale of 1.
ROOM_LIGHT_RGB = (np.array([0.8, 0.55, 0.3]) * luminance_to_radiance(20.0) / 0.11
                  / (0.2126 * 0.8 + 0.7152 * 0.55 + 0.0722 * 0.3)).astype(np.float32)
# What glows with the vehicle lights (dusk, night): material -> (radiance added, the condition's glow scale, on actors
# only).
NIGHT_GLOWS = {
    "taillight": (TAIL_LIGHT_RGB, "tail_glow", True),
    "headlight": (HEAD_LIGHT_RGB, "head_glow", True),
    "lamp": (STREET_LAMP_RGB, "lamp_glow", False),
    "marker_lamp": (MARKER_LAMP_RGB, "tail_glow", True),
}
# What is lit, not glowing, with the lights on: material -> (irradiance, times the hit's albedo; the glow scale; on
# actors only). A rear plate under its plate lamp; a room behind a lit pane (its albedo is the room's, textured).
NIGHT_LIT = {
    "plate_rear": (PLATE_LAMP_RGB, "tail_glow", True),
    "window_lit": (ROOM_LIGHT_RGB, "lamp_glow", False),
}


def sky(directions: np.ndarray, condition: Condition) -> np.ndarray:
    """(N, 3) float32 sky radiance of (N, 3) unit view directions: the condition's (:mod:`pipeline.sensors.sky`)."""
    return sky_rays(directions, condition.sky_params)


def shade(
    scene: FrameScene, rays: np.ndarray, hits: Hits, condition: Condition, lights: SpotLights | None = None,
    indirect: bool = False, pixel_angle_rad: float = 0.0, image_shape: tuple[int, int] | None = None,
    sunlit: np.ndarray | None = None, sky_visible: np.ndarray | None = None, period: int | None = None,
) -> np.ndarray:
    """(N, 3) float32 linear radiance of N camera rays ((N, 6) float32 [origin | unit direction], world).

    radiance = albedo * (ambient + sun * max(n.l, 0) * sunlit) + sun * specular * sunlit + emission + the
    ``lights``' diffuse and specular terms (:func:`pipeline.sensors.lights.light_radiance`); misses see the
    sky (:mod:`pipeline.sensors.sky`). ``sunlit`` is the share of the sun's disc a hit sees
    (:mod:`pipeline.sensors.shadows`; with ``indirect`` the sun is a disc, else a point); the ``sunlit`` argument
    ((N,) float32, optional) gives it per ray (NaN: traced here). With ``indirect``, the ambient term is scaled by
    the sky's visibility (``sky_visible``, (N,) float32, optional: given where not NaN, and its NaN rows are filled
    in place with what is traced here, so that a pass can lend it on) and mirror reflections are blended in
    (:mod:`pipeline.sensors.indirect`; ``image_shape``
    (H, W): the rays are a camera's pixel centres, row-major, and the sky occlusion and the penumbrae are smoothed
    over each surface). A positive ``pixel_angle_rad`` (the camera's angle per pixel) textures the static world's
    albedo (:mod:`pipeline.sensors.textures`). ``period``: the rays are passes of this many rays stacked (the
    anti-aliasing samples, shaded in one call), each shaded as its pass alone would be (the sun's disc direction and
    the sky occlusion's pattern are chosen by a ray's place in its pass); default N.
    The sun's and the sky's terms are compiled passes over the rays
    (:mod:`pipeline.sensors.sunlight`); the few glowing hits, the spot lights and the
    wet sheen add theirs with numpy.
    """
    mats = shading_materials()
    if pixel_angle_rad > 0:
        hits = dataclasses.replace(hits, color=textured_albedo(rays, hits.t_m, hits.hit, hits.instance_id,
                                                               hits.material, hits.normal, hits.color, pixel_angle_rad))
    wet = None
    if condition.wetness > 0:
        wet, hits, mats = wet_surfaces(hits, mats, condition.wetness, rays)
    sun = condition.sun_direction
    mat = hits.material
    rays = as_input(rays, np.float32)
    normal = as_input(hits.normal, np.float32)
    # The realistic camera's sun is a disc (soft shadows: pipeline.sensors.shadows); the fast preset's a point.
    disc = condition.sun_disc if indirect else sun[None]
    n_dot_l, lit, sunlit = sun_shares(scene, rays, hits, condition, disc, image_shape, pixel_angle_rad, sunlit,
                                      period)
    rgb = [np.asarray(c, np.float32) for c in (condition.sun_rgb, condition.ambient_rgb)] + [condition.sky_params]
    out = sky_and_sun(rays, as_input(hits.hit, bool), normal, as_input(mat, np.int32),
                      as_input(hits.color, np.float32), n_dot_l, lit, sunlit, mats["specular"],
                      mats["shininess"], sun, *rgb)
    if indirect:
        # The sky fill shut out by nearby geometry, then one bounce of mirror reflection (pipeline.sensors.indirect).
        visibility = sky_visibility(scene, rays, hits, image_shape, sky_visible, period)
        if sky_visible is not None:
            sky_visible[:] = visibility
        dim = np.flatnonzero(visibility < 1.0)
        out[dim] -= hits.color[dim] * rgb[1] * (1.0 - visibility[dim])[:, None]
        reflections(scene, rays, hits, out, mats["fresnel_f0"], sun, rgb, mats["specular"], mats["shininess"],
                    None if wet is None else wet.film)
    glowing = np.flatnonzero(mats["glows"][mat] & hits.hit)
    out[glowing] += np.take(mats["emissive"], mat[glowing], axis=0)
    on_actor = hits.instance_id[glowing] > 0
    tail = glowing[(mat[glowing] == material_index("taillight")) & on_actor]
    out[tail[scene.actors.brake[hits.actor_index[tail]]]] += BRAKE_LIGHT_RGB
    if condition.lights_on:
        # A vehicle's own lamps glow only where its lights are on (a parked vehicle's are off).
        on_actor = on_actor.copy()
        on_actor[on_actor] = scene.actors.lights_on[hits.actor_index[glowing[on_actor]]]
        for name, (rgb, scale, actors_only) in NIGHT_GLOWS.items():
            which = mat[glowing] == material_index(name)
            out[glowing[which & on_actor if actors_only else which]] += rgb * np.float32(getattr(condition, scale))
        for name, (rgb, scale, actors_only) in NIGHT_LIT.items():
            which = mat[glowing] == material_index(name)
            under_lamp = glowing[which & on_actor if actors_only else which]
            out[under_lamp] += hits.color[under_lamp] * (rgb * np.float32(getattr(condition, scale)))
    if lights is not None and len(lights):
        out += light_radiance(scene, rays, hits, lights, hits.color, mats["specular"][mat], mats["shininess"][mat])
    if wet is not None and len(wet.road) and not indirect:  # the realistic camera traces them (wet.road_reflections)
        out[wet.road] += wet_sheen(np.take(rays, wet.road, axis=0), np.take(hits.normal, wet.road, axis=0),
                                   condition.sky_params, condition.wetness)
    if condition.exposure != 1.0:
        out *= condition.exposure
    return out


def shading_materials() -> dict[str, np.ndarray]:
    """The material tables (:func:`pipeline.world.materials.material_arrays`) with ``glows``: (M,) bool, the
    materials that glow or are lit by their own lamp (emissive, NIGHT_GLOWS, NIGHT_LIT)."""
    mats = material_arrays()
    lights = [material_index(n) for n in (*NIGHT_GLOWS, *NIGHT_LIT)]
    mats["glows"] = (mats["emissive"].max(axis=1) > 0) | np.isin(np.arange(len(mats["specular"])), lights)
    return mats


def _srgb_lut(size: int = 1 << 16, max_linear: float = LINEAR_WHITE) -> np.ndarray:
    x = np.linspace(0.0, max_linear, size, dtype=np.float64)
    x = np.where(x > 0.8, 0.8 + 0.2 * np.tanh((x - 0.8) / 0.2), x)  # soft shoulder for highlights
    return _encode_srgb(x)


def _encode_srgb(x: np.ndarray) -> np.ndarray:
    """Display-linear values in [0, 1] to 8-bit sRGB (the standard's piecewise curve, rounded)."""
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(np.maximum(x, 0.0031308), 1 / 2.4) - 0.055)
    return np.clip(np.rint(srgb * 255.0), 0, 255).astype(np.uint8)


FILMIC_GAIN = 0.6  # scene-linear values are scaled by this before the filmic curve (its mid-grey sits higher)


def _filmic_lut(size: int = 1 << 16, max_linear: float = LINEAR_WHITE) -> np.ndarray:
    """A filmic tone curve, as a camera's image processor applies one: a toe that deepens the shadows, a long
    shoulder that rolls highlights off instead of clipping them; Narkowicz's fit of the ACES reference rendering
    transform, y = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), of ``FILMIC_GAIN`` times the scene value."""
    x = FILMIC_GAIN * np.linspace(0.0, max_linear, size, dtype=np.float64)
    return _encode_srgb(np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0))


_LUTS = {"soft": _srgb_lut(), "filmic": _filmic_lut()}
_LUT_SCALE = (len(_LUTS["soft"]) - 1) / LINEAR_WHITE
TONE_CURVES = tuple(_LUTS)


def to_srgb8(linear: np.ndarray, curve: str = "soft") -> np.ndarray:
    """Linear RGB (any shape (..., 3)) to 8-bit sRGB through a tone ``curve`` (values above LINEAR_WHITE = 4 clip, NaN
    is 0): "soft", linear with a soft shoulder above 0.8, or "filmic" (:func:`_filmic_lut`); a 65536-entry lookup
    table (finer than one 8-bit step everywhere)."""
    if curve not in _LUTS:
        raise ValueError(f"unknown tone curve {curve!r}; known: {', '.join(_LUTS)}")
    x = as_input(linear, np.float32)
    return _lookup(x.reshape(-1), _LUTS[curve], np.float32(_LUT_SCALE)).reshape(x.shape)


@kernel("uint8[::1](float32[::1], uint8[::1], float32)")
def _lookup(x, lut, scale):
    """``lut[int(clip(x * scale, 0, len(lut) - 1))]``, NaN -> ``lut[0]``: (N,) float32 -> (N,) uint8."""
    out = np.empty(x.size, np.uint8)
    top = np.float32(lut.size - 1)
    for i in range(x.size):
        v = x[i] * scale
        if not v > 0:  # also NaN
            v = np.float32(0)
        elif v > top:
            v = top
        out[i] = lut[np.int64(v)]
    return out
