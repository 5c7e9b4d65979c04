"""Object classes, their COCO category ids, and the semantic classes of the rendered world.

Category ids follow COCO's 80-class ids where the class exists there (person 1, bicycle 2, car 3,
motorcycle 4, bus 6, truck 8), so that a COCO-trained detector is scored without remapping. The finer
class (e.g. van) stays as an attribute (``subclass``). Ids are never 0: a class COCO has no category for (a
stroller) has category id 0 in the labels, and COCO-style exports leave its rows out, saying how many.
"""

from __future__ import annotations

import enum


class ObjectClass(str, enum.Enum):
    """Classes of simulated actors (the ``cls`` column of trajectories and labels)."""

    CAR = "car"
    VAN = "van"
    TRUCK = "truck"
    BUS = "bus"
    MOTORCYCLE = "motorcycle"
    BICYCLE = "bicycle"
    PEDESTRIAN = "pedestrian"
    STROLLER = "stroller"  # a pram or pushchair pushed by a pedestrian (pipeline.world.prams); COCO has no category

    @property
    def coco_id(self) -> int:
        """COCO category id (van counts as car); 0 for a class COCO has no category for (stroller)."""
        return _COCO_ID.get(self, 0)

    @property
    def coco_name(self) -> str:
        """COCO category name; a KeyError for a class without one (:attr:`coco_id` 0)."""
        return COCO_CATEGORIES[self.coco_id][0]

    @property
    def semantic(self) -> SemanticClass:
        return SemanticClass[self.name]


# id -> (name, supercategory), COCO 2017 instances.
COCO_CATEGORIES: dict[int, tuple[str, str]] = {
    1: ("person", "person"),
    2: ("bicycle", "vehicle"),
    3: ("car", "vehicle"),
    4: ("motorcycle", "vehicle"),
    6: ("bus", "vehicle"),
    8: ("truck", "vehicle"),
}

_COCO_ID = {
    ObjectClass.CAR: 3,
    ObjectClass.VAN: 3,
    ObjectClass.TRUCK: 8,
    ObjectClass.BUS: 6,
    ObjectClass.MOTORCYCLE: 4,
    ObjectClass.BICYCLE: 2,
    ObjectClass.PEDESTRIAN: 1,
}


RIDER = "rider"
"""The ``cls`` of a camera label row of the person riding a bicycle or motorcycle (COCO's person; its cycle's row
holds cycle and rider, as KITTI's Cyclist and nuScenes box them); never a simulated actor's class."""
RIDER_TRACK_OFFSET = 1 << 15
"""A rider's track id: its cycle's plus this (as a stroller's is its pusher's plus the same: a track is one class,
so the two never meet)."""


class Person(str, enum.Enum):
    """Who a pedestrian is (labels.parquet ``person``; empty for every other class): an adult, a teenager (13-17), a
    child (6-12), or a wheelchair user (an adult seated in a wheelchair, labelled with it as one pedestrian). The
    body family decides (pipeline.world.people); exports with finer person categories read it (nuScenes:
    human.pedestrian.child, human.pedestrian.wheelchair)."""

    ADULT = "adult"
    TEEN = "teen"
    CHILD = "child"
    WHEELCHAIR_USER = "wheelchair_user"


class SemanticClass(enum.IntEnum):
    """Per-pixel / per-point semantic labels (uint8 in images and point clouds). 0 is 'nothing hit'."""

    NONE = 0  # sky or out of range
    ROAD = 1
    LANE_MARKING = 2
    SIDEWALK = 3
    CROSSING = 4
    TERRAIN = 5
    BUILDING = 6
    VEGETATION = 7
    POLE = 8
    TRAFFIC_LIGHT = 9
    BARRIER = 10
    KERB = 11
    WEATHER = 12  # a LiDAR return from the air: fog, mist or rain droplets (pipeline.sensors.backscatter)
    CAR = 20
    VAN = 21
    TRUCK = 22
    BUS = 23
    MOTORCYCLE = 24
    BICYCLE = 25
    PEDESTRIAN = 26
    STROLLER = 27
    RIDER = 28  # the person on a bicycle or motorcycle (its triangles: pipeline.world.mesh.RIDER)
    EGO = 30

    @property
    def is_actor(self) -> bool:
        return 20 <= self.value < 30
