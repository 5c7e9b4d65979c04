"""The simulate stage on a small real highway run: outputs, determinism, replay in plain sumo."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from pipeline.stages.simulate import resolve_scenario, simulate
from pipeline.traffic.sumo_tools import binary, run_tool
from tests.conftest import tree_hashes

EXPECTED_FILES = {
    "network.net.xml", "demand.rou.xml", "run.sumocfg", "trajectories.parquet", "tls_states.parquet",
    "vehicles.parquet", "stats.json", "meta.json", "roads/lanes.parquet", "roads/junctions.parquet",
    "roads/traffic_lights.parquet", "roads/bus_stops.parquet", "roads/network.json",
}


def test_outputs_and_columns(small_highway_run):
    files = set(tree_hashes(small_highway_run))
    assert files >= EXPECTED_FILES
    traj = pd.read_parquet(small_highway_run / "trajectories.parquet")
    assert traj["frame"].nunique() == 30
    assert traj["is_ego"].groupby(traj["frame"]).sum().eq(1).all()
    assert traj.groupby("frame")["track_id"].apply(lambda s: s.is_monotonic_increasing and s.is_unique).all()
    assert np.all(traj["yaw_rad"].between(-np.pi, np.pi, inclusive="left"))
    stats = json.loads((small_highway_run / "stats.json").read_text())
    assert stats["frames"] == 30 and stats["vehicles_configured"] == 40
    assert stats["recorded_actor_states"] == len(traj)
    meta = json.loads((small_highway_run / "meta.json").read_text())
    assert meta["seed"] == 7 and meta["config"]["demand"]["vehicles"] == 40
    assert meta["versions"]["sumo"] and len(meta["config_hash"]) == 64


def test_same_seed_same_bytes_and_other_seed_differs(small_highway_run, tmp_path):
    config, _ = resolve_scenario("highway", vehicles=40, duration_s=3.0, warmup_s=20.0)
    simulate(config, 7, tmp_path / "again", progress=False)
    first, second = tree_hashes(small_highway_run), tree_hashes(tmp_path / "again")
    meta_a = json.loads((small_highway_run / "meta.json").read_text())
    meta_b = json.loads((tmp_path / "again" / "meta.json").read_text())
    meta_a.pop("command"), meta_b.pop("command")  # the command line is informational, not output
    assert meta_a == meta_b
    first.pop("meta.json"), second.pop("meta.json")
    assert first == second
    simulate(config, 8, tmp_path / "other", progress=False)
    other = tree_hashes(tmp_path / "other")
    assert other["trajectories.parquet"] != first["trajectories.parquet"]
    assert other["demand.rou.xml"] != first["demand.rou.xml"]
    assert other["network.net.xml"] == first["network.net.xml"]  # the network does not depend on the seed


def test_plain_sumo_replays_the_recorded_positions(small_highway_run, tmp_path):
    """sumo -c run.sumocfg with FCD output reproduces the recorded front positions."""
    run_tool([binary("sumo"), "-c", str(small_highway_run / "run.sumocfg"), "--fcd-output", str(tmp_path / "fcd.xml"),
              "--no-warnings", "true"], cwd=small_highway_run)
    traj = pd.read_parquet(small_highway_run / "trajectories.parquet")
    rows = []
    for step in ET.parse(tmp_path / "fcd.xml").getroot().iter("timestep"):
        t = float(step.get("time"))
        rows += [(round(t, 3), v.get("id"), float(v.get("x")), float(v.get("y")), float(v.get("angle")))
                 for v in step.iter("vehicle")]
    fcd = pd.DataFrame(rows, columns=["time_s", "actor_id", "fx", "fy", "angle"])
    merged = traj.assign(time_s=traj["time_s"].round(3)).merge(fcd, on=["time_s", "actor_id"], how="left")
    assert merged["fx"].notna().all(), "every recorded state must appear in the replay"
    front_x = merged["x_m"] + 0.5 * merged["length_m"] * np.cos(merged["yaw_rad"])
    front_y = merged["y_m"] + 0.5 * merged["length_m"] * np.sin(merged["yaw_rad"])
    # FCD output is written with 2 decimals.
    np.testing.assert_allclose(front_x, merged["fx"], atol=0.006)
    np.testing.assert_allclose(front_y, merged["fy"], atol=0.006)


def test_failed_run_leaves_nothing_behind(tmp_path):
    config, _ = resolve_scenario("highway", vehicles=5, duration_s=1.0, warmup_s=0.0)
    bad = config.model_copy(update={"ego": config.ego.model_copy(update={"vehicle_id": "no_such_vehicle"})})
    with pytest.raises(RuntimeError, match="no_such_vehicle"):
        simulate(bad, 1, tmp_path / "out", progress=False)
    assert list(tmp_path.iterdir()) == []


def test_urban_run_records_pedestrians_cyclists_and_lights(tmp_path):
    config, _ = resolve_scenario("urban", vehicles=60, duration_s=1.0, warmup_s=30.0)
    stats = simulate(config, 3, tmp_path / "urban", progress=False)
    traj = pd.read_parquet(tmp_path / "urban" / "trajectories.parquet")
    assert (traj["cls"] == "pedestrian").any()
    departs = [float(p.get("depart")) for p in ET.parse(tmp_path / "urban" / "demand.rou.xml").getroot().iter("person")]
    bus_stops = pd.read_parquet(tmp_path / "urban" / "roads" / "bus_stops.parquet")
    others = config.demand.pedestrians + config.demand.standing_pedestrians
    waiting = len(departs) - others  # at the bus stops (pipeline.traffic.busstops)
    assert len(bus_stops) > 5 and waiting > len(bus_stops)
    routes = ET.parse(tmp_path / "urban" / "demand.rou.xml").getroot()
    stops = [stop for person in routes.iter("person") for stop in person.iter("stop")]  # (buses stop too)
    assert 0 < len(stops) - waiting <= config.demand.standing_pedestrians  # those who stand first
    # Those standing now stand on their sidewalk (SUMO draws them 3 m to the right of its centre line, in the verge).
    lanes = list(ET.parse(tmp_path / "urban" / "network.net.xml").getroot().iter("lane"))
    shapes = {lane.get("id"): np.array([[float(v) for v in xy.split(",")[:2]] for xy in lane.get("shape").split()])
              for lane in lanes}
    widths = {lane.get("id"): float(lane.get("width", "3.2")) for lane in lanes}
    rows = traj.set_index(["actor_id", "frame"])
    checked = 0
    for person in ET.parse(tmp_path / "urban" / "demand.rou.xml").getroot().iter("person"):
        stop = person.find("stop")
        depart = float(person.get("depart"))
        if stop is None or not depart + 0.5 <= 30.0 <= depart + float(stop.get("duration")) - 0.5:
            continue
        row = rows.loc[(person.get("id"), 0)]
        assert row["speed_mps"] == 0.0
        lane = stop.get("lane")
        assert _distance_to_polyline((row["x_m"], row["y_m"]), shapes[lane]) < 0.5 * widths[lane]
        checked += 1
    assert checked > 0
    # The members of a standing group stand in its formation, facing each other (pipeline.traffic.demand): a pair's
    # recorded centres lie FORMATION_PAIR_M apart plus a person's length (SUMO places a person's front), each
    # heading towards the other.
    from pipeline.traffic.demand import FORMATION_PAIR_M

    pairs = 0
    groups: dict[tuple, list[str]] = {}
    for person in ET.parse(tmp_path / "urban" / "demand.rou.xml").getroot().iter("person"):
        if person.find("param") is not None and int(person.get("id")[3:]) < others:
            groups.setdefault((person.get("depart"), person.find("stop").get("lane")), []).append(person.get("id"))
    frame0 = traj[traj["frame"] == 0].set_index("actor_id")
    for ids in groups.values():
        if len(ids) != 2 or not all(i in frame0.index and frame0.loc[i, "speed_mps"] == 0.0 for i in ids):
            continue
        a, b = frame0.loc[ids[0]], frame0.loc[ids[1]]
        gap = np.array([b["x_m"] - a["x_m"], b["y_m"] - a["y_m"]])
        assert np.linalg.norm(gap) == pytest.approx(FORMATION_PAIR_M + a["length_m"], abs=0.01)
        for who, towards in ((a, gap), (b, -gap)):
            heading = np.array([np.cos(who["yaw_rad"]), np.sin(who["yaw_rad"])])
            assert heading @ towards / np.linalg.norm(towards) > 0.999
        pairs += 1
    assert pairs > 0
    # One standing alone faces the way drawn for it (its parameter's face: radians from the sidewalk's direction
    # towards its right), not along the sidewalk as SUMO has a waiting person.
    alone = 0
    for (_, lane), ids in groups.items():
        pid = ids[0]
        if len(ids) != 1 or pid not in frame0.index or frame0.loc[pid, "speed_mps"] != 0.0:
            continue
        person = next(p for p in ET.parse(tmp_path / "urban" / "demand.rou.xml").getroot().iter("person")
                      if p.get("id") == pid)
        face = float(person.find("param").get("value").split()[2])
        row, shape = frame0.loc[pid], shapes[lane]
        xy = (row["x_m"], row["y_m"])
        seg = np.argmin([_distance_to_polyline(xy, shape[i:i + 2]) for i in range(len(shape) - 1)])
        along = np.arctan2(*(shape[seg + 1] - shape[seg])[::-1])
        assert np.cos(row["yaw_rad"] - (along - face)) > 0.999
        alone += 1
    assert alone > 0
    # The people at the bus stops stand at their places (dy right of the sidewalk's centre line: towards the shelter,
    # or at the kerb) and face their way, all the run long; SUMO places a person's front, so the recorded centre lies
    # half a person's length behind the place along the way it faces.
    for person in ET.parse(tmp_path / "urban" / "demand.rou.xml").getroot().iter("person"):
        if int(person.get("id")[3:]) < others:
            continue
        lane, pos = person.find("stop").get("lane"), float(person.find("stop").get("endPos"))
        assert lane in set(bus_stops.lane_id)
        stop = bus_stops[bus_stops.lane_id == lane].iloc[0]
        assert abs(pos - stop.pos_m) <= 2.5 + 0.16
        _, dy, face = (float(v) for v in person.find("param").get("value").split())
        track = traj[traj["actor_id"] == person.get("id")]
        assert len(track) == traj["frame"].nunique() and (track["speed_mps"] == 0.0).all()
        row, shape = track.iloc[0], shapes[lane]
        xy = (row["x_m"], row["y_m"])
        seg = np.argmin([_distance_to_polyline(xy, shape[i:i + 2]) for i in range(len(shape) - 1)])
        direction = (shape[seg + 1] - shape[seg]) / np.linalg.norm(shape[seg + 1] - shape[seg])
        along = np.arctan2(direction[1], direction[0])
        assert np.cos(row["yaw_rad"] - (along - face)) > 0.999
        front = np.array([row["x_m"], row["y_m"]]) + 0.5 * row["length_m"] * np.array([np.cos(row["yaw_rad"]),
                                                                                        np.sin(row["yaw_rad"])])
        right = np.array([direction[1], -direction[0]])
        assert (front - shape[seg]) @ right == pytest.approx(dy, abs=0.05)
    last_frame_s = 30.0 + 1.0 - 0.1  # the run stops after the last recorded frame
    assert stats["persons_inserted"] == sum(d <= last_frame_s + 1e-9 for d in departs)
    tls = pd.read_parquet(tmp_path / "urban" / "tls_states.parquet")
    assert tls["tls_id"].nunique() == stats["network"]["traffic_lights"]
    assert set("".join(tls["state"])) <= set("rRyYgGuoOs")


def _distance_to_polyline(point, polyline: np.ndarray) -> float:
    p = np.asarray(point, np.float64)
    a, b = polyline[:-1], polyline[1:]
    t = np.clip(np.einsum("ij,ij->i", p - a, b - a) / np.maximum(np.einsum("ij,ij->i", b - a, b - a), 1e-12), 0, 1)
    return float(np.min(np.linalg.norm(a + t[:, None] * (b - a) - p, axis=1)))


def test_recorded_command_line_names_the_program_not_its_path():
    """meta.json's command (also embedded in MCAP exports) must not depend on where the checkout lives."""
    from pipeline.stages.common import command_line

    argv = ["/home/a/clone/.venv/bin/roadsynth", "export", "--out", "data/exports/runs.mcap"]
    assert command_line(argv) == ["roadsynth", "export", "--out", "data/exports/runs.mcap"]
    assert command_line([]) == []
