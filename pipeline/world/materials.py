"""Surface materials: colour for the camera, reflectivity for the LiDAR.

Meshes carry a material index per triangle (:func:`material_index`); the renderer turns the table
into arrays (:func:`material_arrays`) and gathers by index for all hits at once.
Actor body paint is the material ``paint``; its colour comes from the actor, not from this table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Material:
    """Attributes:
    albedo_rgb: diffuse colour, linear RGB in [0, 1].
    specular: strength of the specular highlight in [0, 1] (wet road, glass, paint).
    shininess: Phong exponent of the highlight.
    reflectivity: LiDAR reflectivity I0 at normal incidence in [0, 1] (905 nm).
    emissive_rgb: light emitted (lamps, lit tail lights), linear RGB, may exceed 1.
    fresnel_f0: mirror reflectance at normal incidence (Schlick's F0; 0: no mirror reflection traced): clear-coat
        paint and glass ~0.04-0.05, metals far more (:mod:`pipeline.sensors.indirect`).
    retroreflection: coefficient of retroreflected luminance R, cd m^-2 lx^-1, at the 1.05 deg observation angle of
        the 30 m geometry (EN 1436 R_L for markings; the coefficient of retroreflection R_A of sheeting and
        reflectors, per unit area); 0: none. Lit by a lamp near the camera, such a surface returns far more than
        its diffuse light (:mod:`pipeline.sensors.lights`).
    """

    albedo_rgb: tuple[float, float, float]
    specular: float = 0.0
    shininess: float = 16.0
    reflectivity: float = 0.2
    emissive_rgb: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fresnel_f0: float = 0.0
    retroreflection: float = 0.0


# Road surfaces by day: weathered asphalt reflects 0.10-0.20 of sunlight (fresh 0.05; US EPA, "Reducing Urban Heat
# Islands: Compendium of Strategies", Cool Pavements, 2012), white road paint about pi x its luminance coefficient Qd,
# 0.4-0.6 (EN 1436 asks Qd >= 0.13 cd/m^2/lx of dry white markings). An asphalt of 0.09 with 0.85 paint made streets
# near black with zebra stripes the detector read as cars (docs/realism.md).
# Retroreflection R at 1.05 deg observation (cd m^-2 lx^-1): worn dry white markings 0.1 (EN 1436 class R2 asks
# >= 0.1 of permanent white markings, new ones reach 0.15-0.3); asphalt 0.01, an order below the markings (our
# estimate: the background that markings' night contrast is specified against). Sheeting, plates and reflectors are
# given at 0.2-0.33 deg in their standards (ASTM D4956 type I white sheeting ~70, ECE R104 tape and R3 reflex
# reflectors far more) and fall steeply with the angle; at 1.05 deg our values (plates and sign faces 4, white tape
# 20, red tape 4, a tail lamp's reflex reflector over its whole lens 0.5) are estimates of that fall.
MATERIALS: dict[str, Material] = {
    "asphalt": Material((0.17, 0.17, 0.17), specular=0.05, reflectivity=0.12, retroreflection=0.01),
    "lane_paint": Material((0.6, 0.6, 0.57), specular=0.05, reflectivity=0.75, retroreflection=0.1),
    "concrete": Material((0.45, 0.44, 0.42), reflectivity=0.35),
    "kerb": Material((0.55, 0.55, 0.53), reflectivity=0.40),
    "grass": Material((0.10, 0.22, 0.06), reflectivity=0.45),
    "building": Material((0.50, 0.42, 0.36), reflectivity=0.30),
    "building_glass": Material((0.08, 0.10, 0.12), specular=0.6, shininess=64.0, reflectivity=0.08,
                               fresnel_f0=0.08),
    "foliage": Material((0.07, 0.18, 0.05), reflectivity=0.40),
    "bark": Material((0.20, 0.13, 0.08), reflectivity=0.30),
    "metal": Material((0.40, 0.41, 0.43), specular=0.4, shininess=32.0, reflectivity=0.50),
    "barrier": Material((0.40, 0.40, 0.38), specular=0.1, reflectivity=0.60),  # weathered concrete
    "paint": Material((0.5, 0.5, 0.5), specular=0.5, shininess=256.0, reflectivity=0.45, fresnel_f0=0.05),
    "glass": Material((0.03, 0.035, 0.04), specular=0.8, shininess=1024.0, reflectivity=0.05, fresnel_f0=0.05),
    "rubber": Material((0.03, 0.03, 0.03), reflectivity=0.05),
    "plate": Material((0.80, 0.80, 0.75), reflectivity=0.90, retroreflection=4.0),
    "headlight": Material((0.3, 0.32, 0.35), specular=0.9, shininess=96.0, reflectivity=0.80,  # clear lens
                          fresnel_f0=0.05),
    "taillight": Material((0.5, 0.015, 0.015), specular=0.5, shininess=96.0, reflectivity=0.70, fresnel_f0=0.05,
                          retroreflection=0.5),
    "lamp": Material((0.9, 0.85, 0.7), reflectivity=0.5),
    "skin": Material((0.60, 0.45, 0.35), reflectivity=0.30),
    "cloth": Material((0.20, 0.22, 0.30), reflectivity=0.25),
    # Appended by the actor meshes (pipeline/world/actor_shapes.py).
    "cargo": Material((0.70, 0.70, 0.68), specular=0.2, reflectivity=0.55),
    # Appended by the static world (pipeline/world/static.py): signal lamps (the renderer swaps signal_off for
    # the lit colour per frame from the TLS state), building facade variants.
    "signal_off": Material((0.03, 0.03, 0.03), specular=0.6, shininess=64.0, reflectivity=0.10),
    "signal_red": Material((0.6, 0.05, 0.03), specular=0.6, reflectivity=0.10, emissive_rgb=(6.0, 0.3, 0.1)),
    "signal_yellow": Material((0.6, 0.4, 0.03), specular=0.6, reflectivity=0.10, emissive_rgb=(6.0, 3.5, 0.2)),
    "signal_green": Material((0.05, 0.6, 0.2), specular=0.6, reflectivity=0.10, emissive_rgb=(0.3, 6.0, 2.0)),
    "building_light": Material((0.66, 0.62, 0.55), reflectivity=0.35),
    "building_dark": Material((0.30, 0.28, 0.28), reflectivity=0.25),
    # Appended by the lofted vehicle bodies (pipeline/world/loft.py): alloy rims, black plastic trim (bumpers'
    # lower bands, sills, grilles, hubs).
    "rim": Material((0.55, 0.56, 0.58), specular=0.6, shininess=48.0, reflectivity=0.60, fresnel_f0=0.3),
    "trim": Material((0.035, 0.035, 0.04), specular=0.15, shininess=24.0, reflectivity=0.10),
    # Appended by the trucks' conspicuity markings (retroreflective tape; pipeline/world/actor_shapes.py).
    "reflector_red": Material((0.55, 0.04, 0.03), specular=0.3, reflectivity=0.95, retroreflection=4.0),
    "reflector_white": Material((0.85, 0.85, 0.82), specular=0.3, reflectivity=0.95, retroreflection=20.0),
    # Amber side marker lamps of long vehicles (ECE R48; glow with the vehicle lights: pipeline/sensors/shading.py).
    "marker_lamp": Material((0.6, 0.3, 0.02), specular=0.5, shininess=96.0, reflectivity=0.70, fresnel_f0=0.05),
    # A vehicle's rear number plate: the plate, lit by its plate lamp with the vehicle lights (shading.py).
    "plate_rear": Material((0.80, 0.80, 0.75), reflectivity=0.90, retroreflection=4.0),
    # Appended by the façades (pipeline/world/facades.py): wall colours (plaster, brick, render; albedo 0.2-0.7 like
    # real façades), window frames, tinted curtain-wall glass, a pane with a blind or curtain behind it, a pane lit
    # from inside (glass by day; it glows with the lamps at dusk and night: pipeline/sensors/shading.py), doors.
    "brick": Material((0.38, 0.15, 0.09), reflectivity=0.30),
    "brick_dark": Material((0.30, 0.16, 0.11), reflectivity=0.28),
    "plaster_white": Material((0.68, 0.66, 0.62), reflectivity=0.40),
    "plaster_ochre": Material((0.58, 0.44, 0.24), reflectivity=0.35),
    "plaster_grey": Material((0.40, 0.41, 0.42), reflectivity=0.32),
    "plaster_rose": Material((0.60, 0.42, 0.36), reflectivity=0.34),
    "frame_dark": Material((0.05, 0.05, 0.055), specular=0.3, shininess=32.0, reflectivity=0.30),
    "frame_white": Material((0.65, 0.65, 0.63), specular=0.2, shininess=32.0, reflectivity=0.50),
    "glass_tinted": Material((0.03, 0.05, 0.06), specular=0.7, shininess=64.0, reflectivity=0.08, fresnel_f0=0.10),
    "window_blind": Material((0.42, 0.40, 0.36), specular=0.6, shininess=64.0, reflectivity=0.15, fresnel_f0=0.08),
    "window_lit": Material((0.11, 0.10, 0.09), specular=0.6, shininess=64.0, reflectivity=0.08, fresnel_f0=0.08),
    "door": Material((0.09, 0.07, 0.06), specular=0.2, shininess=24.0, reflectivity=0.20),
    # Appended by the trees (pipeline/world/trees.py): foliage of other species (lighter lime or birch green, dark
    # conifer green).
    "foliage_light": Material((0.11, 0.22, 0.06), reflectivity=0.42),
    "foliage_dark": Material((0.04, 0.11, 0.05), reflectivity=0.38),
    # Appended by the curtainsider semi-trailers (pipeline/world/actor_shapes.py): a PVC-coated polyester curtain,
    # matte, a light blue-grey (bright in the LiDAR's near infrared, as light fabrics are).
    "tarpaulin": Material((0.50, 0.53, 0.58), specular=0.08, shininess=12.0, reflectivity=0.5),
    # Appended by the people (pipeline/world/people.py, figures.py): matte fabrics, leather, hair and skin. Diffuse
    # albedos of clothing in the visible lie between ~0.02 (black cloth) and ~0.6 (white cotton); dyed fabrics are
    # bright in the near infrared whatever their visible colour (the LiDAR's 905 nm), black ones less so. Skin: light,
    # medium and dark tones, albedos from spectrophotometry of the inner arm across the Fitzpatrick scale (reflectance
    # at 550 nm ~0.45, ~0.25, ~0.08). ``garment`` takes the actor's colour (its per-person top, coat or dress), as
    # ``paint`` does a vehicle's, but matte (no clear coat: no highlight, no mirror).
    "garment": Material((0.5, 0.5, 0.5), specular=0.03, shininess=8.0, reflectivity=0.45),
    "denim": Material((0.05, 0.08, 0.16), specular=0.02, shininess=8.0, reflectivity=0.45),
    "denim_light": Material((0.17, 0.23, 0.36), specular=0.02, shininess=8.0, reflectivity=0.5),
    "fabric_black": Material((0.022, 0.022, 0.026), specular=0.03, shininess=8.0, reflectivity=0.2),
    "fabric_grey": Material((0.16, 0.16, 0.17), specular=0.02, shininess=8.0, reflectivity=0.4),
    "fabric_navy": Material((0.022, 0.03, 0.075), specular=0.02, shininess=8.0, reflectivity=0.35),
    "fabric_beige": Material((0.42, 0.34, 0.22), specular=0.02, shininess=8.0, reflectivity=0.55),
    "fabric_brown": Material((0.11, 0.065, 0.04), specular=0.02, shininess=8.0, reflectivity=0.45),
    "fabric_olive": Material((0.085, 0.095, 0.045), specular=0.02, shininess=8.0, reflectivity=0.45),
    "fabric_white": Material((0.62, 0.62, 0.6), specular=0.02, shininess=8.0, reflectivity=0.65),
    "fabric_red": Material((0.36, 0.03, 0.04), specular=0.02, shininess=8.0, reflectivity=0.5),
    "leather": Material((0.035, 0.025, 0.02), specular=0.25, shininess=32.0, reflectivity=0.15),
    "sneaker_white": Material((0.6, 0.6, 0.58), specular=0.1, shininess=16.0, reflectivity=0.6),
    "hair_black": Material((0.018, 0.015, 0.013), specular=0.15, shininess=24.0, reflectivity=0.15),
    "hair_brown": Material((0.07, 0.04, 0.024), specular=0.15, shininess=24.0, reflectivity=0.25),
    "hair_blond": Material((0.33, 0.24, 0.12), specular=0.15, shininess=24.0, reflectivity=0.4),
    "hair_grey": Material((0.3, 0.3, 0.3), specular=0.15, shininess=24.0, reflectivity=0.4),
    "skin_medium": Material((0.36, 0.23, 0.15), reflectivity=0.3),
    "skin_dark": Material((0.12, 0.07, 0.045), reflectivity=0.25),
}

MATERIAL_NAMES: tuple[str, ...] = tuple(MATERIALS)
# Materials whose colour is the actor's (Actors.color_rgb) rather than the table's albedo.
TINTED_MATERIALS = ("paint", "garment")
# What people are made of (the radar scatters off them as off cloth and skin: pipeline/sensors/radar.py).
PERSON_MATERIALS = ("skin", "cloth", *(n for n in MATERIALS if n.startswith(("fabric_", "denim", "hair_", "skin_"))),
                    "garment", "leather", "sneaker_white")


def material_index(name: str) -> int:
    """Index of a material by name; unknown names fail listing the known ones."""
    try:
        return MATERIAL_NAMES.index(name)
    except ValueError:
        raise KeyError(f"unknown material {name!r}; known: {', '.join(MATERIAL_NAMES)}") from None


def material_arrays() -> dict[str, np.ndarray]:
    """The table as arrays indexed by material index: albedo (M, 3), specular (M,), shininess (M,),
    reflectivity (M,), emissive (M, 3), fresnel_f0 (M,), retroreflection (M,), all float32."""
    mats = [MATERIALS[n] for n in MATERIAL_NAMES]
    return {
        "albedo": np.array([m.albedo_rgb for m in mats], dtype=np.float32),
        "specular": np.array([m.specular for m in mats], dtype=np.float32),
        "shininess": np.array([m.shininess for m in mats], dtype=np.float32),
        "reflectivity": np.array([m.reflectivity for m in mats], dtype=np.float32),
        "emissive": np.array([m.emissive_rgb for m in mats], dtype=np.float32),
        "fresnel_f0": np.array([m.fresnel_f0 for m in mats], dtype=np.float32),
        "retroreflection": np.array([m.retroreflection for m in mats], dtype=np.float32),
    }
