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
    pd.testing.assert_frame_equal(car.drop(columns=["pose", "model", "person"]), table[table["track_id"] == 2])
    assert (car["pose"] == 0).all()
    assert car["model"].nunique() == 1 and car["model"].iloc[0] in {"sedan", "hatchback", "estate", "suv", "coupe",
                                                                    "pickup"} and (car["person"] == "").all()
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


def _crowd(people: int = 400, frames: int = 3) -> pd.DataFrame:
    """An ego and ``people`` pedestrians walking north-east at 1.3 m/s on ground at z = 2 (SUMO's box)."""
    rows = []
    yaw = 0.7
    for f in range(frames):
        t = 0.1 * f
        rows.append({"frame": f, "time_s": t, "track_id": 1, "is_ego": True, "cls": "car", "x_m": 5.0 * t, "y_m": 0.0,
                     "z_m": 2.75, "length_m": 4.5, "width_m": 1.8, "height_m": 1.5, "yaw_rad": 0.0, "color_r": 30,
                     "color_g": 30, "color_b": 30, "braking": False, "speed_mps": 5.0, "parked": False,
                     "actor_id": "ego"})
        for k in range(people):
            rows.append({"frame": f, "time_s": t, "track_id": 10 + k, "is_ego": False, "cls": "pedestrian",
                         "x_m": 3.0 * k + 1.3 * t * np.cos(yaw), "y_m": 10.0 + 1.3 * t * np.sin(yaw),
                         "z_m": 2.0 + 1.719 / 2, "length_m": 0.215, "width_m": 0.478, "height_m": 1.719,
                         "yaw_rad": yaw, "color_r": 90, "color_g": 20, "color_b": 20, "braking": False,
                         "speed_mps": 1.3, "parked": False, "actor_id": f"ped{k}"})
    return pd.DataFrame(rows)


def test_a_pram_pusher_gets_a_stroller_in_the_hands_every_frame():
    """Strollers (pipeline.world.prams) are actors of their own, derived per row from the people whose family pushes
    one: about 2 % of the people, each with one stroller in each of its rows, ahead along its heading by the reach
    of its hands at its stature, on its ground, its track id the pusher's + 32768; everyone else as without them,
    and a frame's rows alone (the driving environment renders one frame at a time) give the same strollers."""
    from pipeline.stages.render_frames import STROLLER_TRACK_OFFSET, with_strollers
    from pipeline.world.people import person_statures
    from pipeline.world.prams import STROLLER_SIZE_M, stroller_offset_m

    table = _crowd()
    out = with_strollers(table, DEFAULT_MESHES, seed=7)
    pd.testing.assert_frame_equal(out.iloc[:len(table)], table)  # the simulated rows first, as they were
    strollers = out.iloc[len(table):]
    assert (strollers["cls"] == "stroller").all()
    pushers = np.unique(strollers["track_id"].to_numpy() - STROLLER_TRACK_OFFSET)
    assert 1 <= len(pushers) <= 25  # 2 % of 400 is 8; binomial 99.9 % bounds 1..19
    assert len(strollers) == 3 * len(pushers)
    families = [DEFAULT_MESHES.families[f] for f in DEFAULT_MESHES.family_codes(_people_actors(pushers, seed=7))]
    assert all(getattr(f, "pram", False) for f in families)
    statures = person_statures(np.array([f.group for f in families], object), pushers, seed=7)
    ahead = dict(zip(pushers.tolist(), stroller_offset_m(statures).tolist(), strict=True))
    person = table.set_index(["frame", "track_id"])
    for row in strollers.itertuples():
        p = person.loc[(row.frame, row.track_id - STROLLER_TRACK_OFFSET)]
        d = ahead[row.track_id - STROLLER_TRACK_OFFSET]
        assert 0.5 < d < 1.3
        np.testing.assert_allclose([row.x_m, row.y_m], [p.x_m + d * np.cos(0.7), p.y_m + d * np.sin(0.7)], atol=1e-9)
        assert row.yaw_rad == p.yaw_rad and row.speed_mps == p.speed_mps and row.actor_id == p.actor_id + "/stroller"
        np.testing.assert_allclose(row.z_m - row.height_m / 2, 2.0, atol=1e-9)  # on the pusher's ground
        np.testing.assert_allclose([row.length_m, row.width_m, row.height_m], STROLLER_SIZE_M)
    assert strollers.groupby("track_id")[["color_r", "color_g", "color_b"]].nunique().max().max() == 1
    for f in range(3):
        alone = with_strollers(table[table["frame"] == f], DEFAULT_MESHES, seed=7)
        pd.testing.assert_frame_equal(alone[alone["cls"] == "stroller"].reset_index(drop=True),
                                      strollers[strollers["frame"] == f].reset_index(drop=True))
    # Another seed, other pushers; the strollers pass through the render's posing with pose 0 and their boxes.
    other = with_strollers(table, DEFAULT_MESHES, seed=8)
    assert set(other.loc[other["cls"] == "stroller", "track_id"]) != set(strollers["track_id"])
    posed = body_sized_trajectories(table, DEFAULT_MESHES, seed=7)
    mine = posed[posed["cls"] == "stroller"]
    assert (mine["pose"] == 0).all()
    np.testing.assert_allclose(mine[["x_m", "y_m", "z_m", "length_m"]].to_numpy(),
                               strollers[["x_m", "y_m", "z_m", "length_m"]].to_numpy())


def _people_actors(track_id: np.ndarray, seed: int):
    from pipeline.core.geometry import Boxes3D
    from pipeline.world.actors import Actors, actor_variants

    n = len(track_id)
    return Actors(track_id, ["pedestrian"] * n, Boxes3D(np.zeros((n, 3)), np.tile([0.215, 0.478, 1.719], (n, 1)),
                                                        np.zeros(n)),
                  np.zeros((n, 3), np.float32), np.zeros(n, bool), actor_variants(track_id, seed))


def test_track_ids_too_large_for_strollers_are_refused():
    from pipeline.stages.render_frames import STROLLER_TRACK_OFFSET, with_strollers

    table = _crowd(people=400, frames=1)
    table.loc[table["track_id"] == 409, "track_id"] = STROLLER_TRACK_OFFSET
    with pytest.raises(ValueError, match="must be below"):
        with_strollers(table, DEFAULT_MESHES, seed=7)


def test_labels_name_each_actor_s_body_and_who_a_pedestrian_is():
    """``model`` is the body family's name and ``person`` who a pedestrian is, one value per track: the families'
    groups over 400 people (children, teenagers, adults, wheelchair users), a stroller's own family and no person."""
    from pipeline.core.classes import Person

    out = body_sized_trajectories(_crowd(), DEFAULT_MESHES, seed=7)
    assert (out.groupby("track_id")[["model", "person"]].nunique() == 1).all().all()
    people = out[out["cls"] == "pedestrian"].drop_duplicates("track_id")
    family = {f.name: f for f in DEFAULT_MESHES.families if hasattr(f, "group")}
    expected = ["wheelchair_user" if m.startswith("wheelchair_") else
                {"man": "adult", "woman": "adult"}.get(family[m].group, family[m].group) for m in people["model"]]
    assert people["person"].tolist() == expected
    counts = people["person"].value_counts()
    assert set(counts.index) <= {p.value for p in Person}
    assert counts["adult"] > 250 and 10 <= counts.get("child", 0) <= 60 and 10 <= counts.get("teen", 0) <= 60
    assert counts.get("wheelchair_user", 0) >= 1  # 1 % of them: 4 at this seed
    assert people["model"].str.startswith("child_").sum() == counts["child"]
    strollers = out[out["cls"] == "stroller"]
    assert len(strollers) and set(strollers["model"]) <= {"pram", "pushchair"} and (strollers["person"] == "").all()
    ego = out[out["is_ego"]]
    assert (ego["person"] == "").all()
