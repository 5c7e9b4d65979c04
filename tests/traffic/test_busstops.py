"""Bus stops on a real netgenerate grid with sidewalks, and the people waiting at them (pipeline.traffic.busstops)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.core.config import ScenarioConfig, load_config
from pipeline.core.config.scenario import BusStopConfig
from pipeline.traffic.busstops import (
    MIN_STOP_FROM_START_M,
    SHELTER_LENGTH_M,
    STOP_SPREAD_M,
    WAITING_AT_KERB,
    WAITING_FACING_RAD,
    WAITING_FACING_SHARES,
    WAITING_JITTER_M,
    WAITING_MARGIN_M,
    WAITING_SLOT_M,
    WAITING_TURN_RAD,
    bus_route_stops,
    bus_stop_lanes,
    choose_bus_stops,
    waiting_people,
)
from pipeline.traffic.demand import CLOTHES, CLOTHES_SHARES, build_demand
from pipeline.traffic.networks import build_network
from pipeline.traffic.roadgeometry import load_road_geometry, read_network_geometry, write_road_geometry


@pytest.fixture(scope="module")
def grid(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tool = shutil.which("netgenerate", path=str(Path(sys.executable).parent)) or shutil.which("netgenerate")
    if tool is None:
        pytest.skip("SUMO's netgenerate not found")
    net = tmp_path_factory.mktemp("grid") / "g.net.xml"
    subprocess.run([tool, "--grid", "--grid.number", "4", "--grid.length", "120", "--default.lanenumber", "2",
                    "--sidewalks.guess", "true", "--crossings.guess", "true", "-o", str(net), "--no-warnings"],
                   check=True, capture_output=True)
    return net


def test_stops_lie_near_the_middle_of_the_long_sidewalks_the_same_for_every_run(grid):
    lanes = read_network_geometry(grid).lanes
    walks = lanes[(lanes.kind == "sidewalk") & (lanes.function == "normal")]
    assert walks.edge_id.is_unique  # one sidewalk per edge here: each is its edge's first
    every = choose_bus_stops(lanes, BusStopConfig(share=1.0, min_sidewalk_m=60.0))
    long = walks[walks.length_m >= 60.0]
    assert len(long) == len(walks) > 40  # a regular grid: every sidewalk ~100 m
    assert choose_bus_stops(lanes, BusStopConfig(share=1.0, min_sidewalk_m=walks.length_m.max() + 0.01)).empty
    assert sorted(every.lane_id) == sorted(long.lane_id) and every.stop_id.is_unique
    length = every.lane_length_m.to_numpy()
    np.testing.assert_array_equal(length, long.set_index("lane_id").loc[every.lane_id, "length_m"].to_numpy())
    assert (np.abs(every.pos_m - length / 2) <= STOP_SPREAD_M + 0.005).all()
    assert every.pos_m.nunique() > len(every) // 2  # drawn, not all at the middle
    some = choose_bus_stops(lanes, BusStopConfig(share=0.3))
    pd.testing.assert_frame_equal(some, choose_bus_stops(lanes, BusStopConfig(share=0.3)))  # no run seed: the same
    assert 0 < len(some) < len(every) and set(some.lane_id) <= set(every.lane_id)
    assert choose_bus_stops(lanes, None).empty and choose_bus_stops(lanes, BusStopConfig(share=0.0)).empty


def test_the_stops_round_trip_beside_the_road_geometry_and_an_old_folder_is_named(grid, tmp_path):
    stops = choose_bus_stops(read_network_geometry(grid).lanes, BusStopConfig(share=0.5))
    write_road_geometry(grid, tmp_path / "roads", stops)
    pd.testing.assert_frame_equal(load_road_geometry(tmp_path / "roads").bus_stops, stops, check_dtype=False)
    write_road_geometry(grid, tmp_path / "none")
    assert load_road_geometry(tmp_path / "none").bus_stops.empty
    (tmp_path / "none" / "bus_stops.parquet").unlink()
    with pytest.raises(FileNotFoundError, match=r"missing bus_stops.parquet \(a simulation made before bus stops"):
        load_road_geometry(tmp_path / "none")


def test_people_wait_at_their_stop_in_places_of_their_own_facing_the_road_or_up_it():
    config = load_config(ScenarioConfig, "urban", "scenarios")[0].demand
    spec = config.bus_stops
    assert spec is not None and spec.waiting_mean > 0
    n = 400
    stops = pd.DataFrame({"stop_id": [f"bus{i:03d}" for i in range(n)], "edge_id": [f"e{i}" for i in range(n)],
                          "lane_id": [f"e{i}_0" for i in range(n)], "pos_m": np.full(n, 40.0),
                          "lane_length_m": np.full(n, 90.0), "lane_width_m": np.full(n, 2.5)})
    people = waiting_people(stops, config, 750, 3, CLOTHES, CLOTHES_SHARES)
    assert list(people.person_id[:2]) == ["ped0750", "ped0751"] and people.person_id.is_unique
    per_stop = people.groupby("stop_lane").size().reindex(stops.lane_id, fill_value=0)
    assert abs(per_stop.mean() - spec.waiting_mean) < 4 * np.sqrt(spec.waiting_mean / n)  # Poisson, below its cap
    assert per_stop.max() <= int((SHELTER_LENGTH_M + 1.0) / WAITING_SLOT_M) + 1
    assert (people.route == people.stop_lane.str[:-2]).all() and (people.depart_s == 0.0).all()
    for _, group in people.groupby("stop_lane"):
        place = np.sort(group.stop_pos_m.to_numpy())
        assert (np.abs(place - 40.0) <= (SHELTER_LENGTH_M + 1.0) / 2 + WAITING_JITTER_M + 0.005).all()
        assert (np.diff(place) >= WAITING_SLOT_M - 2 * WAITING_JITTER_M - 0.01).all()  # each a place of its own
    half = 1.25 - WAITING_MARGIN_M
    kerb = np.isclose(people.stand_dy_m, -half)
    assert ((people.stand_dy_m >= -half - 1e-9) & (people.stand_dy_m <= half + 1e-9)).all()
    assert (people.stand_dy_m[~kerb] >= 0.0).all()  # the others between the centre line and the shelter
    assert abs(kerb.mean() - WAITING_AT_KERB) < 4 * np.sqrt(WAITING_AT_KERB * (1 - WAITING_AT_KERB) / len(people))
    off = np.angle(np.exp(1j * (people.stand_face_rad.to_numpy()[:, None] - np.array(WAITING_FACING_RAD)[None])))
    nearest = np.argmin(np.abs(off), axis=1)
    assert (np.abs(off[np.arange(len(people)), nearest]) <= WAITING_TURN_RAD + 1e-4).all()
    for k, share in enumerate(WAITING_FACING_SHARES):
        assert abs(np.mean(nearest == k) - share) < 4 * np.sqrt(share * (1 - share) / len(people))
    assert ((people.stop_s >= 180.0) & (people.stop_s <= 900.0)).all()
    pd.testing.assert_frame_equal(people, waiting_people(stops, config, 750, 3, CLOTHES, CLOTHES_SHARES))
    assert not people.equals(waiting_people(stops, config, 750, 4, CLOTHES, CLOTHES_SHARES))


def test_the_waiting_people_join_the_demand_and_leave_everyone_else_as_they_were(tmp_path):
    scenario = load_config(ScenarioConfig, "urban", "scenarios")[0]
    config = scenario.demand.model_copy(update={"vehicles": 20, "pedestrians": 30, "standing_pedestrians": 10})
    net = build_network(scenario.network, tmp_path)
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
    with_stops = build_demand(config, net, tmp_path / "a", tmp_path / "a" / "work", 5)
    without = build_demand(config.model_copy(update={"bus_stops": None}), net, tmp_path / "b", tmp_path / "b" / "work",
                           5)
    assert len(with_stops.bus_stops) > 0 and without.bus_stops.empty
    waiting = with_stops.persons.iloc[40:]
    assert len(waiting) > 0 and set(waiting.stop_lane) <= set(with_stops.bus_stops.lane_id)
    pd.testing.assert_frame_equal(with_stops.persons.iloc[:40], without.persons)
    pd.testing.assert_frame_equal(with_stops.vehicles, without.vehicles)
    assert with_stops.actor_table().index[-1] == waiting.person_id.iloc[-1]


def test_a_bus_stops_at_each_stop_on_its_route(grid):
    """bus_stop_lanes puts each stop on its edge's rightmost driving lane at the same share of the length;
    bus_route_stops lists a route's stops in route order, not one at the very start of its first edge."""
    lanes = read_network_geometry(grid).lanes
    stops = choose_bus_stops(lanes, BusStopConfig(share=0.5))
    on_lanes = bus_stop_lanes(lanes, stops)
    assert len(on_lanes) == len(stops)
    table = lanes.set_index("lane_id")
    for stop, lane in zip(stops.itertuples(), on_lanes.itertuples(), strict=True):
        row = table.loc[lane.lane_id]
        assert row.edge_id == stop.edge_id and row.kind == "driving"
        assert row["index"] == lanes[(lanes.edge_id == stop.edge_id) & (lanes.kind == "driving")]["index"].min()
        assert lane.pos_m == pytest.approx(stop.pos_m / stop.lane_length_m * row.length_m, abs=0.006)
    a, b = on_lanes.edge_id.iloc[0], on_lanes.edge_id.iloc[1]
    route = f"x {b} y {a}"
    assert bus_route_stops(route, on_lanes) == [(on_lanes.lane_id.iloc[1], on_lanes.pos_m.iloc[1]),
                                                (on_lanes.lane_id.iloc[0], on_lanes.pos_m.iloc[0])]
    early = on_lanes.assign(pos_m=MIN_STOP_FROM_START_M - 1.0)
    assert bus_route_stops(f"{a} y", early) == [] and len(bus_route_stops(f"y {a}", early)) == 1


def test_buses_stand_at_their_stops_for_their_dwell_in_sumo(tmp_path):
    """A real run of buses only, a stop on every long sidewalk: each bus that drives through one of its stops while
    recorded stands still at it (its centre half its length before the stop's position) for its dwell time."""
    import xml.etree.ElementTree as ET

    from pipeline.core.classes import ObjectClass
    from pipeline.stages.simulate import resolve_scenario, simulate

    config, _ = resolve_scenario("urban", vehicles=30, duration_s=50.0, warmup_s=10.0)
    demand = config.demand.model_copy(update={
        "classes": {ObjectClass.BUS: config.demand.classes[ObjectClass.BUS].model_copy(update={"share": 1.0})},
        "pedestrians": 0, "standing_pedestrians": 0, "parked": None, "depart_window_s": 10.0,
        "bus_stops": BusStopConfig(share=1.0, waiting_mean=0.0)})
    config = config.model_copy(update={"demand": demand, "ego": config.ego.model_copy(
        update={"cls": ObjectClass.BUS, "min_neighbours": 0, "route_margin": 1.0})})
    simulate(config, 2, tmp_path / "run", progress=False)
    root = ET.parse(tmp_path / "run" / "demand.rou.xml").getroot()
    shapes = {lane.get("id"): np.array([[float(c) for c in p.split(",")[:2]] for p in lane.get("shape").split()])
              for lane in ET.parse(tmp_path / "run" / "network.net.xml").getroot().iter("lane")}
    traj = pd.read_parquet(tmp_path / "run" / "trajectories.parquet")
    seen = 0
    for vehicle in root.iter("vehicle"):
        track = traj[traj.actor_id == vehicle.get("id")]
        for stop in vehicle.iter("stop"):
            on = track[track.lane_id == stop.get("lane")]
            line = shapes[stop.get("lane")]
            assert len(line) == 2  # straight lanes: a place along one is a projection
            d = line[1] - line[0]
            s = (on[["x_m", "y_m"]].to_numpy() - line[0]) @ d / np.linalg.norm(d)
            at = float(stop.get("endPos")) - on.length_m.iloc[0] / 2 if len(on) else 0.0
            if not len(on) or s.min() > at - 5.0 or s.max() < at + 5.0:
                continue  # it did not drive through this stop while recorded
            still = on[(np.abs(s - at) < 1.5) & (on.speed_mps < 0.01)]
            assert len(still) * 0.1 >= float(stop.get("duration")) - 1.0
            seen += 1
    assert seen >= 2
