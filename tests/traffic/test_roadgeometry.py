"""Road geometry tables from real SUMO networks built by netconvert/netgenerate into tmp_path."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.traffic.roadgeometry import load_road_geometry, read_network_geometry, write_road_geometry


def _sumo_tool(name: str) -> str:
    found = shutil.which(name, path=str(Path(sys.executable).parent)) or shutil.which(name)
    if found is None:
        pytest.skip(f"SUMO tool {name} not found")
    return found


def _netconvert(tmp_path: Path, nodes: str, edges: str, *extra: str) -> Path:
    (tmp_path / "n.nod.xml").write_text(f"<nodes>{nodes}</nodes>")
    (tmp_path / "e.edg.xml").write_text(f"<edges>{edges}</edges>")
    net = tmp_path / "n.net.xml"
    subprocess.run([_sumo_tool("netconvert"), "-n", str(tmp_path / "n.nod.xml"), "-e", str(tmp_path / "e.edg.xml"),
                    "-o", str(net), "--no-warnings", *extra], check=True, capture_output=True)
    return net


def _grid(tmp_path: Path) -> Path:
    net = tmp_path / "grid.net.xml"
    subprocess.run([_sumo_tool("netgenerate"), "--grid", "--grid.number", "3", "--grid.length", "100",
                    "--default.lanenumber", "2", "--tls.guess", "true", "--sidewalks.guess", "true",
                    "--crossings.guess", "true", "-o", str(net), "--no-warnings"], check=True, capture_output=True)
    return net


NODES = '<node id="a" x="0" y="0"/><node id="b" x="100" y="0"/>'


def test_straight_two_lane_edge(tmp_path: Path) -> None:
    # spreadType="center": the two 3.5 m lanes lie symmetric about y = 0, lane 0 (rightmost) south.
    net = _netconvert(tmp_path, NODES, '<edge id="ab" from="a" to="b" numLanes="2" width="3.5" speed="20" '
                      'spreadType="center" type="highway.motorway"/>')
    lanes = read_network_geometry(net).lanes.set_index("lane_id")
    assert list(lanes.index) == ["ab_0", "ab_1"]
    np.testing.assert_allclose(lanes.width_m, 3.5)
    np.testing.assert_allclose(lanes.loc["ab_0", "shape_y"], -1.75, atol=1e-6)
    np.testing.assert_allclose(lanes.loc["ab_1", "shape_y"], 1.75, atol=1e-6)
    x = lanes.loc["ab_0", "shape_x"]
    assert x[0] < x[-1] and x[-1] - x[0] == pytest.approx(lanes.loc["ab_0", "length_m"], abs=0.05)
    assert (lanes.loc["ab_0", "left_marking"], lanes.loc["ab_0", "right_marking"]) == ("dashed", "solid")
    assert (lanes.loc["ab_1", "left_marking"], lanes.loc["ab_1", "right_marking"]) == ("solid", "dashed")
    assert set(lanes.kind) == {"driving"} and set(lanes.road_type) == {"highway.motorway"}
    assert lanes["index"].dtype == np.int32
    np.testing.assert_allclose(lanes.speed_mps, 20.0)


def test_forbidden_lane_change_is_solid_and_sidewalk_unmarked(tmp_path: Path) -> None:
    edges = ('<edge id="ab" from="a" to="b" numLanes="3" spreadType="center">'
             '<lane index="0" allow="pedestrian" width="2"/><lane index="1" changeLeft="emergency"/></edge>')
    lanes = read_network_geometry(_netconvert(tmp_path, NODES, edges)).lanes.set_index("lane_id")
    assert list(lanes.kind) == ["sidewalk", "driving", "driving"]
    assert (lanes.loc["ab_0", "left_marking"], lanes.loc["ab_0", "right_marking"]) == ("none", "none")
    assert lanes.loc["ab_1", "left_marking"] == "solid" and lanes.loc["ab_2", "right_marking"] == "solid"
    assert lanes.loc["ab_1", "right_marking"] == "solid"  # the carriageway's outer edge, next to the sidewalk


def test_grid_traffic_lights_and_crossings(tmp_path: Path) -> None:
    geo = read_network_geometry(_grid(tmp_path))
    tls = geo.traffic_lights
    assert len(tls) > 0 and geo.network["num_traffic_lights"] == tls.tls_id.nunique() >= 1
    lanes = geo.lanes.set_index("lane_id")
    # Each TLS lists link indices 0..n-1 once, matching the length of its state strings.
    for _, group in tls.groupby("tls_id"):
        assert sorted(group.link_index) == list(range(len(group)))
    vehicle = tls[~tls.pedestrian]
    for row in vehicle.itertuples():
        x, y = lanes.loc[row.from_lane, "shape_x"], lanes.loc[row.from_lane, "shape_y"]
        assert (row.stop_x, row.stop_y) == (x[-1], y[-1])
        assert row.heading_rad == pytest.approx(np.arctan2(y[-1] - y[-2], x[-1] - x[-2]))
        assert lanes.loc[row.from_lane, "kind"] == "driving" and row.via_lane in lanes.index
    assert tls.pedestrian.any() and set(lanes.loc[tls[tls.pedestrian].to_lane, "kind"]) == {"crossing"}
    crossings = geo.lanes[geo.lanes.kind == "crossing"]
    assert len(crossings) > 0 and (crossings.function == "crossing").all()
    assert (geo.lanes.kind == "sidewalk").any() and geo.network["has_pedestrians"]
    assert geo.network["bounds"] == [0.0, 0.0, 200.0, 200.0]
    junctions = geo.junctions.set_index("junction_id")
    assert junctions.loc["B1", "type"] == "traffic_light" and len(junctions.loc["B1", "shape_x"]) >= 4


def test_written_files_deterministic_and_round_trip(tmp_path: Path) -> None:
    net = _grid(tmp_path)
    write_road_geometry(net, tmp_path / "r1")
    write_road_geometry(net, tmp_path / "r2")
    names = sorted(p.name for p in (tmp_path / "r1").iterdir())
    assert names == ["bus_stops.parquet", "junctions.parquet", "lanes.parquet", "network.json",
                     "traffic_lights.parquet"]
    for name in names:
        assert (tmp_path / "r1" / name).read_bytes() == (tmp_path / "r2" / name).read_bytes(), name
    schema = pq.read_schema(tmp_path / "r1" / "lanes.parquet")
    assert str(schema.field("shape_x").type) == "list<element: double>"
    assert str(schema.field("index").type) == "int32"
    loaded, direct = load_road_geometry(tmp_path / "r1"), read_network_geometry(net)
    assert list(loaded.lanes.lane_id) == sorted(direct.lanes.lane_id)
    np.testing.assert_array_equal(loaded.lanes.shape_x.iloc[5], direct.lanes.shape_x.iloc[5])
    assert json.loads((tmp_path / "r1" / "network.json").read_text())["num_lanes"] == len(direct.lanes)


def test_bad_network_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="not found"):
        read_network_geometry(tmp_path / "missing.net.xml")
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<routes/>")
    with pytest.raises(ValueError, match="expected <net>"):
        read_network_geometry(bad)
    bad.write_text("<net><edge")
    with pytest.raises(ValueError, match="not valid XML"):
        read_network_geometry(bad)
