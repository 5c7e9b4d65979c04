"""Pedestrian body families: people of several ages, builds and outfits, each posed through the walk cycle,
standing, the running cycle, and walking and standing under an umbrella (:mod:`.gait`, :mod:`.figures`).

Frame and conventions as :mod:`pipeline.world.actor_shapes` (x forward, y left, z up, ground at z = 0, metres at
a stature of :data:`pipeline.world.gait.MODEL_STATURE_M`; normalised to each actor's box later). A family is a
:class:`PersonFamily`: one mesh per pose (:func:`pipeline.world.gait.person_pose`), picked per frame from the
distance the person walked (:func:`pipeline.world.gait.gait_poses`); the render sizes each person's box to its posed
mesh at the person's stature (:func:`person_statures`, :func:`pipeline.world.posed_people.posed_boxes`).

Who: the families are 10 of men, 10 of women, 2 of teenagers and 2 of children, so that an actor's family (picked
uniformly by its variant) makes about 83 % adults, 8 % teenagers (13-17) and 8 % children (6-12): our estimate of a
weekday city street, where children are fewer than their ~15 % of Europe's population. One person in a hundred
sits in a wheelchair instead and two push a pram or pushchair (:mod:`pipeline.world.wheelchairs`,
:mod:`pipeline.world.prams`; picked by their shares before the uniform pick). Statures
(:data:`STATURE_M`): adults 1.76 m (men) and 1.63 m (women), between the means that NCD Risk Factor Collaboration,
"A century of trends in adult human height", eLife 5:e13410 (2016), gives north-western Europeans born in the 1950s
(about 1.75 and 1.62 m) and in the 1990s (about 1.79 and 1.66 m), as a street's adults span those ages; SD ~7 cm, the
within-country spread of national surveys (e.g. the Health Survey for England); teenagers and children from the WHO
2007 growth reference (median height at 6 y 1.16 m, 9 y 1.33 m, 12 y 1.50 m, 15 y ~1.66 m, sexes averaged) with
the reference's spread (SD ~5-7 cm). A child's head is large for its stature (head height ~0.2 m at 1.3 m against
an adult's 0.23 m at 1.75): its model's head is scaled by ``head_scale``.

What they wear (the outfits below, one per family): the top, coat or dress is ``garment``, the actor's own colour
(:data:`pipeline.traffic.demand.CLOTHES` draws it per person); trousers, jeans, skirts, shoes, hair and skin are
fabric, leather, hair and skin materials (:mod:`pipeline.world.materials`). Over the 24 families: jeans 8, other
trousers 10 (black 6, grey 2, navy 1, beige 1), a skirt or dress 4, shorts 2; a coat 5, a hood (hoodie, parka) 4;
long hair 8, a knitted hat 2; a backpack 6, a shoulder bag 3, a bag in the hand 3; light, medium and dark skin 16, 5,
3; black, brown, blond and grey hair 11, 6, 4, 3.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.core.classes import ObjectClass
from pipeline.world.figures import Outfit, figure
from pipeline.world.gait import (
    STAND_POSES,
    UMBRELLA_FIRST,
    WALK_PHASES,
    PosedFamily,
    person_pose,
    run_clearance_m,
    run_phase,
)
from pipeline.world.mesh import Mesh
from pipeline.world.prams import PRAM_PUSHERS
from pipeline.world.solids import merge
from pipeline.world.wheelchairs import WHEELCHAIRS


@dataclass(frozen=True)
class PersonFamily(PosedFamily):
    """A person's body and outfit in every pose: calling it with a pose index builds that pose's mesh.

    Attributes:
        name: the family's name; group: "man", "woman", "teen" or "child" (its stature's distribution,
            :data:`STATURE_M`); outfit: what the figure wears and carries; lean_deg: the trunk's forward lean walking;
            umbrella: the canopy's material of its umbrella poses (walking and standing in the rain), or None: no
            umbrella poses (:data:`FAMILIES`; :data:`UMBRELLA_FAMILIES` have them).
    """

    lean_deg: float = 3.0
    umbrella: str | None = None

    def __call__(self, pose: int = 0) -> Mesh:
        """The mesh in pose ``pose``, its lowest point (the stance foot's sole) on the ground; in a running pose's
        float, the lower sole :func:`pipeline.world.gait.run_clearance_m` above it."""
        self.check_pose(pose)
        outfit = replace(self.outfit, umbrella=self.umbrella) if pose >= UMBRELLA_FIRST else self.outfit
        mesh = merge(figure(person_pose(pose, self.lean_deg), outfit), ObjectClass.PEDESTRIAN)
        lift = run_clearance_m(run_phase(pose)) if WALK_PHASES + STAND_POSES <= pose < UMBRELLA_FIRST else 0.0
        return mesh.on_ground(lift)


def _o(trousers: str, shins: str | None = None, shoes: str = "trim", hair: str = "hair_black", **kw) -> Outfit:
    """An outfit with a ``garment`` top (the actor's colour) and sleeves unless given."""
    kw.setdefault("top", "garment")
    kw.setdefault("sleeves", kw["top"])
    return Outfit(trousers=trousers, shins=trousers if shins is None else shins, shoes=shoes, hair=hair, **kw)


# Stature (m) per group: (mean, SD, low, high); children's mean is drawn from their age (CHILD_AGE_HEIGHT_M).
STATURE_M = {"man": (1.76, 0.07, 1.55, 2.02), "woman": (1.63, 0.065, 1.45, 1.86), "teen": (1.65, 0.08, 1.45, 1.88),
             "child": (0.0, 0.055, 1.05, 1.6)}
CHILD_AGE_HEIGHT_M = ((6.0, 1.16), (9.0, 1.33), (12.0, 1.50))  # WHO 2007 reference medians, sexes averaged

FAMILIES = (
    PersonFamily("man_jeans", "man", _o("denim", shoes="sneaker_white", hair="hair_brown")),
    PersonFamily("man_suit_coat", "man", _o("fabric_black", shoes="leather", coat_m=-0.42, girth=1.05), 2.0),
    PersonFamily("man_chinos_backpack", "man", _o("fabric_beige", backpack="fabric_black", hair="hair_blond")),
    PersonFamily("man_hoodie", "man", _o("fabric_black", hood=True, shoes="sneaker_white", girth=0.95)),
    PersonFamily("man_summer", "man", _o("fabric_olive", "skin", sleeves="skin", skin="skin_medium", girth=0.92)),
    PersonFamily("man_heavy_jacket", "man", _o("denim", girth=1.15, hair="hair_grey", shoulder_bag="leather"), 4.0),
    PersonFamily("man_grey_trousers", "man", _o("fabric_grey", skin="skin_dark", backpack="fabric_navy")),
    PersonFamily("man_parka_hat", "man", _o("fabric_navy", coat_m=-0.3, hat="fabric_grey", hood=True, girth=1.08)),
    PersonFamily("man_shopping", "man", _o("denim_light", hand_bag="fabric_white", hair="hair_grey"), 5.0),
    PersonFamily("man_dark", "man", _o("fabric_black", skin="skin_dark", shoes="sneaker_white", girth=1.0)),
    PersonFamily("woman_jeans", "woman", _o("denim", long_hair=True, hair="hair_brown", shoulder_bag="leather",
                                            girth=0.9)),
    PersonFamily("woman_coat", "woman", _o("fabric_black", coat_m=-0.5, long_hair=True, hair="hair_blond",
                                           girth=0.92)),
    PersonFamily("woman_skirt", "woman", _o("fabric_navy", "skin", skirt_m=-0.38, hair="hair_brown", girth=0.88)),
    PersonFamily("woman_dress", "woman", _o("garment", "skin", skirt_m=-0.45, long_hair=True, shoes="leather",
                                            girth=0.88)),
    PersonFamily("woman_trousers_bag", "woman", _o("fabric_black", hair="hair_black", skin="skin_medium",
                                                   shoulder_bag="fabric_brown", girth=0.9)),
    PersonFamily("woman_shopping", "woman", _o("denim_light", long_hair=True, hair="hair_black", hand_bag="fabric_red",
                                               girth=0.95)),
    PersonFamily("woman_parka", "woman", _o("fabric_black", coat_m=-0.35, hood=True, hair="hair_brown",
                                            skin="skin_dark", girth=0.95)),
    PersonFamily("woman_backpack", "woman", _o("denim", long_hair=True, hair="hair_blond", backpack="fabric_grey",
                                               shoes="sneaker_white", girth=0.88)),
    PersonFamily("woman_older", "woman", _o("fabric_grey", coat_m=-0.45, hair="hair_grey", hand_bag="leather",
                                            girth=1.05), 5.0),
    PersonFamily("woman_skirt_hat", "woman", _o("fabric_brown", "fabric_black", skirt_m=-0.4, hat="fabric_red",
                                                long_hair=True, skin="skin_medium", girth=0.9)),
    PersonFamily("teen_hoodie", "teen", _o("denim", hood=True, backpack="fabric_black", shoes="sneaker_white",
                                           skin="skin_medium", girth=0.88, head_scale=1.05)),
    PersonFamily("teen_shorts", "teen", _o("fabric_grey", "skin", sleeves="skin", long_hair=True, hair="hair_brown",
                                           backpack="fabric_red", girth=0.85, head_scale=1.05)),
    PersonFamily("child_jeans", "child", _o("denim", hair="hair_blond", backpack="fabric_red", shoes="sneaker_white",
                                            girth=0.85, head_scale=1.18), 2.0),
    PersonFamily("child_skirt", "child", _o("fabric_navy", "fabric_grey", skirt_m=-0.33, long_hair=True,
                                            hair="hair_brown", skin="skin_medium", girth=0.85, head_scale=1.18), 2.0),
)
# The canopy's colour per family in the rain (in FAMILIES' order): black 12, navy 4, grey 3, red 2, beige, white,
# brown 1 each (our estimate: most umbrellas on a city street are black or dark; no survey).
UMBRELLAS = ("fabric_black", "fabric_navy", "fabric_black", "fabric_grey", "fabric_black", "fabric_red",
             "fabric_black", "fabric_navy", "fabric_black", "fabric_beige", "fabric_black", "fabric_grey",
             "fabric_black", "fabric_navy", "fabric_black", "fabric_red", "fabric_black", "fabric_white",
             "fabric_black", "fabric_navy", "fabric_black", "fabric_grey", "fabric_black", "fabric_brown")
# Every pedestrian family: the walking people, then the wheelchair users (pipeline.world.wheelchairs) and the people
# pushing a pram (pipeline.world.prams), picked by their shares instead of uniformly
# (pipeline.world.actors.ActorMeshes.family_codes); the pushers come after the wheelchair users, so that adding them
# left every wheelchair user's draw as it was.
PEDESTRIANS = FAMILIES + WHEELCHAIRS + PRAM_PUSHERS
# The same families with their umbrella poses: the meshes of a rain that asks for umbrellas
# (pipeline.world.actors.umbrella_meshes); the others carry none, so that their meshes cost no memory. A wheelchair
# user's and a pram pusher's "umbrella poses" hold no umbrella (both hands are on the rims, or on the handle): the
# layout of poses is the same.
UMBRELLA_FAMILIES = tuple(replace(f, umbrella=u) for f, u in zip(FAMILIES, UMBRELLAS, strict=True)) + tuple(
    replace(w, umbrella="fabric_black") for w in WHEELCHAIRS + PRAM_PUSHERS)


def person_statures(group: np.ndarray, track_id: np.ndarray, seed: int) -> np.ndarray:
    """(N,) float64 statures in metres for N people of ``group`` (names of :data:`STATURE_M`), one draw per person
    from ``numpy.random.default_rng([seed, STATURE_TAG, track id])`` (the same in every frame and shard), truncated
    to the group's range by redrawing."""
    out = np.zeros(len(track_id))
    for i, (g, t) in enumerate(zip(np.asarray(group).tolist(), np.asarray(track_id).tolist(), strict=True)):
        rng = np.random.default_rng([int(seed), STATURE_TAG, int(t)])
        mean, sd, low, high = STATURE_M[g]
        if g == "child":
            age, height = zip(*CHILD_AGE_HEIGHT_M, strict=True)
            mean = float(np.interp(rng.uniform(age[0], age[-1]), age, height))
        for _ in range(100):
            out[i] = mean + sd * rng.standard_normal()
            if low <= out[i] <= high:
                break
        out[i] = min(max(out[i], low), high)
    return out


STATURE_TAG = 0x57A7
