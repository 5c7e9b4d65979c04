"""The front-bumper to box-centre conversion and the yaw convention, on a hand-made network.

Two vehicles stop on a straight east-bound lane and a straight north-bound lane. SUMO stops a vehicle
within POSITION_EPS (0.1 m) of a stop's ``endPos``, so the front bumper's exact lane offset is read
independently with ``vehicle.getLanePosition`` in a second, identical libsumo run; the recorded box
centres must then lie half a length behind it along the lane (geometry from sumolib), with yaw CCW
from east.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest
import sumolib

from pipeline.core.config import EgoConfig, SimulationConfig
from pipeline.traffic.simulation import run, to_trajectories, write_sumocfg
from pipeline.traffic.sumo_tools import binary, run_tool

LENGTH_M, HEIGHT_M = 5.0, 1.5
STOP_EAST_M, STOP_NORTH_M = 250.0, 100.0


@pytest.fixture(scope="module")
def stopped_run(tmp_path_factory) -> tuple[pd.DataFrame, sumolib.net.Net, dict[str, float]]:
    work: Path = tmp_path_factory.mktemp("conventions")
    (work / "n.nod.xml").write_text(
        '<nodes><node id="a" x="0" y="0"/><node id="b" x="500" y="0"/><node id="c" x="500" y="500"/></nodes>'
    )
    (work / "e.edg.xml").write_text(
        '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="15" width="3.2"/>'
        '<edge id="bc" from="b" to="c" numLanes="1" speed="15" width="3.2"/></edges>'
    )
    run_tool([binary("netconvert"), "-n", "n.nod.xml", "-e", "e.edg.xml", "-o", "net.net.xml"], cwd=work)
    (work / "r.rou.xml").write_text(f"""<routes>
  <vType id="box" length="{LENGTH_M}" width="1.8" height="{HEIGHT_M}" carFollowModel="IDM"/>
  <vehicle id="east" type="box" depart="0"><route edges="ab"/>
    <stop lane="ab_0" endPos="{STOP_EAST_M}" duration="1000"/></vehicle>
  <vehicle id="north" type="box" depart="0"><route edges="bc"/>
    <stop lane="bc_0" endPos="{STOP_NORTH_M}" duration="1000"/></vehicle>
</routes>""")
    sim = SimulationConfig(warmup_s=60.0, duration_s=1.0)
    cfg = write_sumocfg(work, "net.net.xml", "r.rou.xml", sim, seed=1)
    vehicles, persons, _, _, ego = run(cfg, sim, EgoConfig(vehicle_id="east"), ["east"], 1, progress=False)
    actors = pd.DataFrame(
        {"track_id": [1, 2], "cls": ["car", "car"], "length_m": LENGTH_M, "width_m": 1.8, "height_m": HEIGHT_M,
         "color_r": 0, "color_g": 0, "color_b": 0},
        index=["east", "north"],
    )
    traj = to_trajectories(vehicles, persons, actors, ego)
    return traj, sumolib.net.readNet(str(work / "net.net.xml")), _front_lane_positions(cfg, sim)


def _front_lane_positions(cfg: Path, sim: SimulationConfig) -> dict[str, float]:
    import libsumo

    libsumo.start([binary("sumo"), "-c", str(cfg), "--no-warnings", "true"])
    try:
        # libsumo's clock runs one step ahead of SUMO's output time (see pipeline.traffic.simulation).
        libsumo.simulationStep(sim.warmup_s + sim.step_length_s)
        return {vid: libsumo.vehicle.getLanePosition(vid) for vid in ("east", "north")}
    finally:
        libsumo.close()


def _lane_point(net, lane_id: str, pos: float) -> tuple[float, float]:
    return sumolib.geomhelper.positionAtShapeOffset(net.getLane(lane_id).getShape(), pos)


def test_centre_is_half_a_length_behind_the_front_bumper(stopped_run):
    traj, net, front = stopped_run
    first = traj[traj["frame"] == 0].set_index("actor_id")
    assert front["east"] == pytest.approx(STOP_EAST_M, abs=0.1)  # the stop held where it was asked
    ex, ey = _lane_point(net, "ab_0", front["east"] - LENGTH_M / 2)
    nx, ny = _lane_point(net, "bc_0", front["north"] - LENGTH_M / 2)
    assert first.loc["east", "x_m"] == pytest.approx(ex, abs=1e-3)
    assert first.loc["east", "y_m"] == pytest.approx(ey, abs=1e-3)
    assert first.loc["north", "x_m"] == pytest.approx(nx, abs=1e-3)
    assert first.loc["north", "y_m"] == pytest.approx(ny, abs=1e-3)


def test_yaw_is_ccw_from_east(stopped_run):
    traj, _, _ = stopped_run
    first = traj[traj["frame"] == 0].set_index("actor_id")
    assert first.loc["east", "yaw_rad"] == pytest.approx(0.0, abs=1e-9)
    assert first.loc["north", "yaw_rad"] == pytest.approx(math.pi / 2, abs=1e-9)


def test_centre_z_is_road_plus_half_height_and_ego_flagged(stopped_run):
    traj, _, _ = stopped_run
    assert traj["z_m"].to_numpy() == pytest.approx(HEIGHT_M / 2)
    assert traj.loc[traj["is_ego"], "actor_id"].unique().tolist() == ["east"]
    assert traj["frame"].nunique() == 10  # 1 s at 10 Hz
    assert (traj["speed_mps"] == 0).all()
