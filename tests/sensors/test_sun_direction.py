"""The shipped conditions put the sun where their descriptions say (azimuth counter-clockwise from east)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from pipeline.core.config import ConditionConfig, load_config
from pipeline.sensors.conditions import SHIPPED, Condition
from tests.sensors.conftest import condition

# The 16 compass points and their bearings (degrees clockwise from north), longest names first for matching.
_POINTS = ["north", "north-north-east", "north-east", "east-north-east", "east", "east-south-east", "south-east",
           "south-south-east", "south", "south-south-west", "south-west", "west-south-west", "west",
           "west-north-west", "north-west", "north-north-west"]
BEARING_DEG = {name: 22.5 * k for k, name in enumerate(_POINTS)}
_NAMED = re.compile(r"\b(" + "|".join(sorted(BEARING_DEG, key=len, reverse=True)) + r")\b")


def named_bearing(description: str) -> float | None:
    found = _NAMED.findall(description)
    if len(set(found)) > 1:
        raise ValueError(f"{description!r} names several directions: {found}")
    return BEARING_DEG[found[0]] if found else None


def test_the_direction_reader():
    assert named_bearing("low warm sun (12 deg) from the east-north-east, long shadows") == 67.5
    assert named_bearing("setting sun in the west, street lamps on") == 270.0
    assert named_bearing("thick fog") is None


def test_azimuth_counts_counter_clockwise_from_east():
    for azimuth, towards in [(0, (1, 0)), (90, (0, 1)), (180, (-1, 0)), (270, (0, -1))]:
        d = condition(sun={"azimuth_deg": azimuth, "elevation_deg": 0.0}).sun_direction
        np.testing.assert_allclose(d, [*towards, 0.0], atol=1e-7)


def _described(name: str) -> ConditionConfig:
    return load_config(ConditionConfig, name, "conditions")[0]


# Conditions whose description names where the sun is (night, fog and rain name none).
WITH_DIRECTION = [n for n in SHIPPED if named_bearing(_described(n).description) is not None]


def test_the_day_conditions_name_a_direction():
    assert {"morning", "noon", "dusk"} <= set(WITH_DIRECTION)


@pytest.mark.parametrize("name", WITH_DIRECTION)
def test_the_sun_is_where_the_description_says(name):
    cfg = _described(name)
    bearing = named_bearing(cfg.description)
    sun = Condition(cfg).sun_direction  # towards the sun, world frame (x east, y north)
    named = np.array([np.sin(np.radians(bearing)), np.cos(np.radians(bearing))])  # compass: x = sin, y = cos
    horizontal = sun[:2] / np.linalg.norm(sun[:2])
    # within half a compass octant (22.5 deg) of the named direction
    assert np.degrees(np.arccos(np.clip(horizontal @ named, -1, 1))) <= 22.5


def test_the_shipped_directions_by_sign():
    sun = {n: Condition(load_config(ConditionConfig, n, "conditions")[0]).sun_direction
           for n in ("morning", "noon", "dusk")}
    assert sun["morning"][0] > 0 and sun["morning"][0] > abs(sun["morning"][1])  # east (a little north)
    assert sun["noon"][1] < 0 and abs(sun["noon"][1]) > abs(sun["noon"][0])  # south
    assert sun["dusk"][0] < 0 and abs(sun["dusk"][0]) > abs(sun["dusk"][1])  # west
