"""Cityscapes' label table and the Cityscapes label of each of our semantic classes.

:data:`LABELS` is cityscapesscripts' ``helpers/labels.py`` table (version 2.3.0; the labels with an id >= 0, i.e.
all but ``license plate``, which never appears in an image), copied so that the export does not need
cityscapesscripts (a test extra). tests/exporters/test_cityscapes.py checks the copy against cityscapesscripts'
``labels`` field by field.

:data:`CITYSCAPES_OF` maps every :class:`~pipeline.core.classes.SemanticClass` to a Cityscapes label, following
Cityscapes' class definitions (https://www.cityscapes-dataset.com/dataset-overview/#class-definitions):

- lane markings and zebra crossings are ``road`` ("including the markings on the road"); kerbs are ``sidewalk``
  (Cityscapes' sidewalk includes the curb);
- nothing hit (0) is ``sky``: a camera ray that misses the world looks at the sky, and the image shows sky there;
- our concrete highway barriers are ``guard rail`` ("all types of guard rails / crash barriers"), a class Cityscapes
  does not evaluate;
- a van is a ``car`` (Cityscapes' car includes vans); a motorcycle or bicycle is ``motorcycle`` / ``bicycle`` and
  its rider's pixels (semantic RIDER) ``rider``, an instance of its own (the same track, another label);
- the ego (30, not drawn by the current renderer) is ``ego vehicle``, void.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import SemanticClass


@dataclass(frozen=True)
class CityscapesLabel:
    """One row of Cityscapes' label table (cityscapesscripts' ``Label``, same fields in the same order)."""

    name: str
    id: int
    train_id: int
    category: str
    category_id: int
    has_instances: bool
    ignore_in_eval: bool
    color: tuple[int, int, int]


_L = CityscapesLabel
LABELS: tuple[CityscapesLabel, ...] = (
    _L("unlabeled", 0, 255, "void", 0, False, True, (0, 0, 0)),
    _L("ego vehicle", 1, 255, "void", 0, False, True, (0, 0, 0)),
    _L("rectification border", 2, 255, "void", 0, False, True, (0, 0, 0)),
    _L("out of roi", 3, 255, "void", 0, False, True, (0, 0, 0)),
    _L("static", 4, 255, "void", 0, False, True, (0, 0, 0)),
    _L("dynamic", 5, 255, "void", 0, False, True, (111, 74, 0)),
    _L("ground", 6, 255, "void", 0, False, True, (81, 0, 81)),
    _L("road", 7, 0, "flat", 1, False, False, (128, 64, 128)),
    _L("sidewalk", 8, 1, "flat", 1, False, False, (244, 35, 232)),
    _L("parking", 9, 255, "flat", 1, False, True, (250, 170, 160)),
    _L("rail track", 10, 255, "flat", 1, False, True, (230, 150, 140)),
    _L("building", 11, 2, "construction", 2, False, False, (70, 70, 70)),
    _L("wall", 12, 3, "construction", 2, False, False, (102, 102, 156)),
    _L("fence", 13, 4, "construction", 2, False, False, (190, 153, 153)),
    _L("guard rail", 14, 255, "construction", 2, False, True, (180, 165, 180)),
    _L("bridge", 15, 255, "construction", 2, False, True, (150, 100, 100)),
    _L("tunnel", 16, 255, "construction", 2, False, True, (150, 120, 90)),
    _L("pole", 17, 5, "object", 3, False, False, (153, 153, 153)),
    _L("polegroup", 18, 255, "object", 3, False, True, (153, 153, 153)),
    _L("traffic light", 19, 6, "object", 3, False, False, (250, 170, 30)),
    _L("traffic sign", 20, 7, "object", 3, False, False, (220, 220, 0)),
    _L("vegetation", 21, 8, "nature", 4, False, False, (107, 142, 35)),
    _L("terrain", 22, 9, "nature", 4, False, False, (152, 251, 152)),
    _L("sky", 23, 10, "sky", 5, False, False, (70, 130, 180)),
    _L("person", 24, 11, "human", 6, True, False, (220, 20, 60)),
    _L("rider", 25, 12, "human", 6, True, False, (255, 0, 0)),
    _L("car", 26, 13, "vehicle", 7, True, False, (0, 0, 142)),
    _L("truck", 27, 14, "vehicle", 7, True, False, (0, 0, 70)),
    _L("bus", 28, 15, "vehicle", 7, True, False, (0, 60, 100)),
    _L("caravan", 29, 255, "vehicle", 7, True, True, (0, 0, 90)),
    _L("trailer", 30, 255, "vehicle", 7, True, True, (0, 0, 110)),
    _L("train", 31, 16, "vehicle", 7, True, False, (0, 80, 100)),
    _L("motorcycle", 32, 17, "vehicle", 7, True, False, (0, 0, 230)),
    _L("bicycle", 33, 18, "vehicle", 7, True, False, (119, 11, 32)),
)
BY_NAME = {label.name: label for label in LABELS}

CITYSCAPES_OF: dict[SemanticClass, str] = {
    SemanticClass.NONE: "sky",
    SemanticClass.ROAD: "road",
    SemanticClass.LANE_MARKING: "road",
    SemanticClass.SIDEWALK: "sidewalk",
    SemanticClass.CROSSING: "road",
    SemanticClass.TERRAIN: "terrain",
    SemanticClass.BUILDING: "building",
    SemanticClass.VEGETATION: "vegetation",
    SemanticClass.POLE: "pole",
    SemanticClass.TRAFFIC_LIGHT: "traffic light",
    SemanticClass.BARRIER: "guard rail",
    SemanticClass.KERB: "sidewalk",
    SemanticClass.WEATHER: "unlabeled",  # LiDAR points only: no pixel has it
    SemanticClass.CAR: "car",
    SemanticClass.VAN: "car",
    SemanticClass.TRUCK: "truck",
    SemanticClass.BUS: "bus",
    SemanticClass.MOTORCYCLE: "motorcycle",
    SemanticClass.BICYCLE: "bicycle",
    SemanticClass.PEDESTRIAN: "person",
    SemanticClass.RIDER: "rider",  # the person on a bicycle or motorcycle, as Cityscapes labels one
    SemanticClass.STROLLER: "dynamic",  # Cityscapes' movable things (buggies among them); a person's class holds
    # what the person carries, not what stands on the ground
    SemanticClass.EGO: "ego vehicle",
}
"""Our semantic class -> the name of its Cityscapes label (every SemanticClass has one)."""


def _tables() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    label_id = np.zeros(256, np.uint8)
    known = np.zeros(256, bool)
    for cls, name in CITYSCAPES_OF.items():
        label_id[cls.value], known[cls.value] = BY_NAME[name].id, True
    has_instances = np.zeros(256, bool)
    colors = np.zeros((256, 3), np.uint8)
    for label in LABELS:
        has_instances[label.id], colors[label.id] = label.has_instances, label.color
    return label_id, known, has_instances, colors


LABEL_ID, KNOWN_SEMANTIC, HAS_INSTANCES, COLORS = _tables()
"""Lookup tables: (256,) uint8 Cityscapes id by our semantic value; (256,) bool semantic values that have one;
(256,) bool by Cityscapes id, the label has instances; (256, 3) uint8 RGB colour by Cityscapes id."""
