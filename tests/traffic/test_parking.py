"""Kerbside parking on a small real urban run: the parking lane in the network, parked vehicles' placement,
their rows in trajectories, determinism; and the ego's neighbour rule."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from pipeline.core.config.scenario import DemandConfig, DepartPosition, ParkedConfig
from pipeline.stages.simulate import resolve_scenario, simulate
from pipeline.traffic.parking import ParkingError, parking_lanes, place_parked
from pipeline.traffic.simulation import neighbours_ahead
from tests.conftest import tree_hashes


@pytest.fixture(scope="module")
def urban_run(tmp_path_factory):
    config, _ = resolve_scenario("urban", vehicles=30, duration_s=0.5, warmup_s=15.0)
    out = tmp_path_factory.mktemp("urban_parking") / "sim"
    simulate(config, 5, out, progress=False)
    return out


def _corners(row) -> np.ndarray:
    """(4, 2) footprint corners of a box row."""
    c, s = np.cos(row.yaw_rad), np.sin(row.yaw_rad)
    u, v = np.array([c, s]) * row.length_m / 2, np.array([-s, c]) * row.width_m / 2
    centre = np.array([row.x_m, row.y_m])
    return np.array([centre + u + v, centre + u - v, centre - u - v, centre - u + v])


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test of two convex quadrilaterals (4, 2)."""
    for poly in (a, b):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            axis = np.array([-edge[1], edge[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() <= pb.min() or pb.max() <= pa.min():
                return False
    return True


def test_parking_lanes_are_closed_to_traffic_and_right_turns_stay(urban_run):
    root = ET.parse(urban_run / "network.net.xml").getroot()
    parking = {lane_id for lane_id, _, _ in parking_lanes(urban_run / "network.net.xml")}
    assert len(parking) == 120  # one per normal edge of the 4x4 grid with its approach roads
    conns = list(root.iter("connection"))
    assert not [c for c in conns if f"{c.get('from')}_{c.get('fromLane')}" in parking]
    # Right turns leave from the right driving lane (index 2: sidewalk 0, parking 1).
    assert any(c.get("dir") == "r" and c.get("fromLane") == "2" for c in conns)
    lanes = pd.read_parquet(urban_run / "roads" / "lanes.parquet")
    assert set(lanes.loc[lanes.lane_id.isin(parking), "kind"]) == {"parking"}
    stats = json.loads((urban_run / "stats.json").read_text())
    assert stats["network"]["parking_lanes"] == 120


def test_parked_vehicles_stay_inside_their_lane_and_never_overlap(urban_run):
    parked = pd.read_parquet(urban_run / "parked.parquet")
    assert len(parked) > 300 and set(parked["cls"]) <= {"car", "van"}
    lanes = {lane_id: (width, line) for lane_id, width, line in parking_lanes(urban_run / "network.net.xml")}
    for row in parked.itertuples():
        width, line = lanes[row.lane_id]
        start, direction = line[0, :2], (line[-1, :2] - line[0, :2]) / np.linalg.norm(line[-1, :2] - line[0, :2])
        normal = np.array([-direction[1], direction[0]])
        rel = _corners(row) - start
        along, across = rel @ direction, rel @ normal
        length = np.linalg.norm(line[-1, :2] - line[0, :2])  # grid lanes are straight
        assert along.min() >= 5.0 - 1e-6 and along.max() <= length - 5.0 + 1e-6
        assert np.abs(across).max() <= width / 2 + 1e-6  # never into the driving lane or onto the sidewalk
        assert across.mean() <= 0  # on the kerb (right) side of the lane centre
    for _, group in parked.groupby("lane_id"):
        boxes = [_corners(r) for r in group.itertuples()]
        for i in range(len(boxes) - 1):
            assert not _overlap(boxes[i], boxes[i + 1])
    # Different lanes' vehicles: no overlap either (checked among all near pairs).
    xy = parked[["x_m", "y_m"]].to_numpy()
    near = np.argwhere(np.triu(np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1)) < 7.0, k=1))
    rows = list(parked.itertuples())
    for i, j in near:
        assert not _overlap(_corners(rows[i]), _corners(rows[j]))


def test_parked_vehicles_are_in_every_frame_of_trajectories(urban_run):
    traj = pd.read_parquet(urban_run / "trajectories.parquet")
    parked = pd.read_parquet(urban_run / "parked.parquet")
    frames = traj["frame"].nunique()
    rows = traj[traj["parked"]]
    assert len(rows) == frames * len(parked)
    assert (rows["speed_mps"] == 0).all() and not rows["is_ego"].any() and not rows["braking"].any()
    moving = traj[~traj["parked"]]
    assert rows["track_id"].min() > moving["track_id"].max()
    first = rows[rows["frame"] == rows["frame"].min()].sort_values("track_id")
    np.testing.assert_array_equal(first[["x_m", "y_m", "yaw_rad", "length_m"]].to_numpy(),
                                  parked[["x_m", "y_m", "yaw_rad", "length_m"]].to_numpy())
    assert traj.groupby("frame")["track_id"].apply(lambda s: s.is_monotonic_increasing and s.is_unique).all()
    stats = json.loads((urban_run / "stats.json").read_text())
    assert stats["parked_vehicles"] == len(parked) == sum(stats["parked_by_class"].values())


def test_same_seed_same_bytes_other_seed_other_parking(urban_run, tmp_path):
    config, _ = resolve_scenario("urban", vehicles=30, duration_s=0.5, warmup_s=15.0)
    simulate(config, 5, tmp_path / "again", progress=False)
    first, second = tree_hashes(urban_run), tree_hashes(tmp_path / "again")
    first.pop("meta.json"), second.pop("meta.json")
    assert first == second
    demand = config.demand
    a = place_parked(demand, urban_run / "network.net.xml", 5)
    b = place_parked(demand, urban_run / "network.net.xml", 6)
    assert not a[["x_m", "y_m"]].equals(b[["x_m", "y_m"]])


def test_occupancy_and_a_network_without_parking_lanes(urban_run, small_highway_run):
    config, _ = resolve_scenario("urban")
    full = config.demand.model_copy(update={"parked": ParkedConfig(occupancy=1.0)})
    empty = config.demand.model_copy(update={"parked": ParkedConfig(occupancy=0.0)})
    net = urban_run / "network.net.xml"
    assert len(place_parked(empty, net, 1)) == 0
    many = place_parked(full, net, 1)
    assert len(many) > len(pd.read_parquet(urban_run / "parked.parquet"))
    with pytest.raises(ParkingError, match="no parking lane"):
        place_parked(full, small_highway_run / "network.net.xml", 1)


def test_parked_classes_need_a_size_distribution():
    config, _ = resolve_scenario("urban")
    data = config.demand.model_dump(mode="json")
    data["parked"] = {"classes": {"car": 1.0, "truck": 0.5}}
    del data["classes"]["truck"]
    with pytest.raises(ValueError, match="truck"):
        DemandConfig.model_validate(data)


def test_neighbours_ahead_counts_only_traffic_in_front_driving_the_same_way_within_the_radius():
    xy = np.array([[0.0, 0.0], [10.0, 0.0]])
    yaw = np.array([0.0, np.pi])  # east, west
    others = np.array([[0.0, 0.0], [5.0, 0.0], [-5.0, 0.0], [0.0, 5.0], [30.0, 0.0], [10.0, 0.0], [8.0, 1.0]])
    others_yaw = np.array([0.0, 0.0, np.pi, 0.0, 0.0, np.pi, 0.0])
    # Vehicle 0 (east): (5, 0) ahead, same way; (0, 5) is beside (projection 0); (30, 0) beyond 20 m; (10, 0)
    # ahead but oncoming; (8, 1) ahead, same way.
    # Vehicle 1 (west, at x=10): ahead within 20 m are (0,0), (5,0), (-5,0), (0,5), (8,1); only (-5,0) drives west.
    np.testing.assert_array_equal(neighbours_ahead(xy, yaw, others, others_yaw, 20.0), [2, 1])


def test_highway_ego_drives_with_traffic_ahead(dense_highway_run):
    """highway.yaml: the ego drives >= 15 m/s with >= 3 vehicles its way within 60 m ahead at frame 0 (the state
    it was chosen in), or, where no candidate has 3, as many as any candidate has (logged)."""
    traj = pd.read_parquet(dense_highway_run / "trajectories.parquet")
    first = traj[traj["frame"] == 0]
    ego = first[first["is_ego"]].iloc[0]
    assert ego["speed_mps"] >= 15.0
    others = first[~first["is_ego"] & (first["cls"] != "pedestrian")]
    # Trajectories hold box centres; the rule used front bumpers, so allow the half-lengths' difference.
    front = lambda r: np.c_[r["x_m"] + np.cos(r["yaw_rad"]) * r["length_m"] / 2,  # noqa: E731
                            r["y_m"] + np.sin(r["yaw_rad"]) * r["length_m"] / 2]
    count = neighbours_ahead(front(ego.to_frame().T.astype({"x_m": float, "y_m": float, "yaw_rad": float,
                                                              "length_m": float})),
                             np.array([ego["yaw_rad"]], dtype=float), front(others), others["yaw_rad"].to_numpy(), 60.0)
    assert count[0] >= 3


def test_random_free_departures_let_all_200_highway_vehicles_in(dense_highway_run, tmp_path):
    """highway.yaml inserts at a random free place of the first edge: nearly all 200 vehicles are in by the end
    of the warm-up; from the edge start (base) the entries hold a quarter of them back."""
    stats = json.loads((dense_highway_run / "stats.json").read_text())
    routes = ET.parse(dense_highway_run / "demand.rou.xml").getroot()
    assert {v.get("departPos") for v in routes.iter("vehicle")} == {"random_free"}
    assert stats["vehicles_inserted"] >= 190
    config, _ = resolve_scenario("highway", vehicles=200, duration_s=1.0, warmup_s=90.0)
    base = config.model_copy(update={"demand": config.demand.model_copy(update={"depart_pos": DepartPosition.BASE})})
    assert simulate(base, 3, tmp_path / "base", progress=False)["vehicles_inserted"] < 170


def test_no_vehicle_parks_at_a_bus_stop_and_the_others_stay(urban_run):
    """With the urban run's bus stops (roads/bus_stops.parquet) no parked vehicle's body lies within BUS_STOP_CLEAR_M
    of a stop along its edge's parking lane, and every vehicle parked elsewhere is the one parked without them."""
    from pipeline.traffic.parking import BUS_STOP_CLEAR_M, parking_lanes

    config, _ = resolve_scenario("urban")
    full = config.demand.model_copy(update={"parked": ParkedConfig(occupancy=1.0)})
    net = urban_run / "network.net.xml"
    stops = pd.read_parquet(urban_run / "roads" / "bus_stops.parquet")
    assert len(stops) > 5
    cleared, kept = place_parked(full, net, 1, stops), place_parked(full, net, 1)
    lanes = {lane_id: line for lane_id, _, line in parking_lanes(net)}
    inside = 0
    for row in kept.itertuples():
        line = lanes[row.lane_id][:, :2]
        assert len(line) == 2  # the urban grid's lanes are straight: a vehicle's place along one is a projection
        length = float(np.linalg.norm(line[1] - line[0]))
        s = float((np.array([row.x_m, row.y_m]) - line[0]) @ (line[1] - line[0])) / length
        here = stops[stops.edge_id == row.lane_id.rsplit("_", 1)[0]]
        at = here.pos_m.to_numpy() / here.lane_length_m.to_numpy() * length
        near = np.any(np.abs(s - at) < BUS_STOP_CLEAR_M + row.length_m / 2 - 0.5)
        clear_of = np.all(np.abs(s - at) > BUS_STOP_CLEAR_M + row.length_m / 2 + 0.5) if len(at) else True
        match = ((cleared.x_m == row.x_m) & (cleared.y_m == row.y_m)).any()
        if near:
            inside += 1
            assert not match
        elif clear_of:
            assert match
    assert inside >= len(stops)  # a full lane has a vehicle or more in each stop's clearway without it
    assert len(cleared) < len(kept) and set(cleared.lane_id) <= set(kept.lane_id)
