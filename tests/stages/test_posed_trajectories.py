"""The render's actor columns: people's boxes posed per row, a pose column, other actors as simulated."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.core.config import ConditionConfig, load_config
from pipeline.sensors.conditions import Condition
from pipeline.stages.render_frames import ACTOR_COLUMNS, Trajectories, body_sized_trajectories
from pipeline.world.actors import DEFAULT_MESHES, umbrella_meshes
from pipeline.world.gait import UMBRELLA_FIRST, WALK_PHASES


def _table(frames: int = 20) -> pd.DataFrame:
    """An ego, a car and a pedestrian walking east at 1.4 m/s on ground at z = 0, SUMO's pedestrian box."""
    rows = []
    for f in range(frames):
        t = 0.1 * f
        for track, cls, x, size, speed, ego in ((1, "car", 5.0 * t, (4.5, 1.8, 1.5), 5.0, True),
                                                 (2, "car", 20.0, (4.4, 1.8, 1.45), 0.0, False),
                                                 (3, "pedestrian", 1.4 * t, (0.215, 0.478, 1.719), 1.4, False)):
            rows.append({"frame": f, "time_s": t, "track_id": track, "is_ego": ego, "cls": cls, "x_m": x,
                         "y_m": 5.0 * (cls == "pedestrian"), "z_m": size[2] / 2, "length_m": size[0],
                         "width_m": size[1], "height_m": size[2], "yaw_rad": 0.0, "color_r": 30, "color_g": 30,
                         "color_b": 30, "braking": False, "speed_mps": speed, "parked": False})
    return pd.DataFrame(rows)


def test_people_are_posed_per_row_and_the_rest_kept():
    table = _table()
    out = body_sized_trajectories(table, DEFAULT_MESHES, seed=4)
    person, car = out[out["cls"] == "pedestrian"], out[out["track_id"] == 2]
    assert set(person["pose"]) <= set(range(WALK_PHASES)) and person["pose"].nunique() >= 3
    # The box follows the pose (its depth changes through the stride), the soles stay on the ground.
    assert person["length_m"].nunique() >= 3
    np.testing.assert_allclose(person["z_m"] - person["height_m"] / 2, 0.0, atol=1e-9)
    assert (person["height_m"] > 1.0).all() and (person["height_m"] < 2.1).all()
    pd.testing.assert_frame_equal(car.drop(columns="pose"), table[table["track_id"] == 2])
    assert (car["pose"] == 0).all()
    # The frame's actor columns carry the pose; the same table in another row order poses the same.
    _, others = Trajectories(out).frame(7)
    assert set(ACTOR_COLUMNS) <= set(others) and others["pose"][others["track_id"] == 3][0] == \
        person.loc[person["frame"] == 7, "pose"].iloc[0]
    shuffled = body_sized_trajectories(table.sample(frac=1.0, random_state=1), DEFAULT_MESHES, seed=4)
    pd.testing.assert_frame_equal(shuffled.sort_index(), out)


def test_in_the_rain_the_person_walks_under_an_umbrella_that_the_box_encloses():
    """The rain's ``umbrellas`` (off unless asked for: the shipped conditions have none) reaches the posed
    trajectories: with a share of 1 the walker takes the umbrella poses of the umbrella models (the default models
    have none, and are refused), taller by the canopy (~1.18 x), soles on the ground; with 0 the same table poses as
    without rain."""
    rain = load_config(ConditionConfig, "rain", "conditions")[0]
    assert Condition(rain).umbrellas == 0.0
    asked = rain.model_copy(update={"rain": rain.rain.model_copy(update={"umbrellas": 0.6})})
    assert Condition(asked).umbrellas == 0.6
    assert Condition(load_config(ConditionConfig, "morning", "conditions")[0]).umbrellas == 0.0
    table = _table()
    dry = body_sized_trajectories(table, DEFAULT_MESHES, seed=4)
    pd.testing.assert_frame_equal(body_sized_trajectories(table, DEFAULT_MESHES, seed=4, umbrellas=0.0), dry)
    with pytest.raises(ValueError, match="no umbrella poses"):  # the default models carry none: no memory for them
        body_sized_trajectories(table, DEFAULT_MESHES, seed=4, umbrellas=1.0)
    assert all(getattr(f, "umbrella", None) is None for f in DEFAULT_MESHES.families)
    wet = body_sized_trajectories(table, umbrella_meshes(), seed=4, umbrellas=1.0)
    person, before = wet[wet["cls"] == "pedestrian"], dry[dry["cls"] == "pedestrian"]
    np.testing.assert_array_equal(person["pose"], before["pose"] + UMBRELLA_FIRST)
    ratio = person["height_m"].to_numpy() / before["height_m"].to_numpy()
    assert (ratio > 1.12).all() and (ratio < 1.25).all()
    np.testing.assert_allclose(person["z_m"] - person["height_m"] / 2, 0.0, atol=1e-9)
    pd.testing.assert_frame_equal(wet[wet["cls"] != "pedestrian"], dry[dry["cls"] != "pedestrian"])
