"""Networks built by SUMO's own tools: highway, urban grid, OpenStreetMap."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
import sumolib

from pipeline.core.config import NetworkConfig
from pipeline.traffic.networks import NetworkError, build_network, network_summary
from pipeline.traffic.sumo_tools import SumoToolError, binary, run_tool
from tests.conftest import DATA


def _net(path: Path) -> sumolib.net.Net:
    return sumolib.net.readNet(str(path), withInternal=True, withPedestrianConnections=True)


@pytest.fixture(scope="module")
def highway(tmp_path_factory) -> Path:
    return build_network(NetworkConfig(kind="highway"), tmp_path_factory.mktemp("hw"))


def test_highway_is_a_divided_motorway_with_ramps_and_a_curve(highway):
    net = _net(highway)
    for direction in ("fwd", "bwd"):
        main = [net.getEdge(f"{direction}_{i}") for i in range(5)]
        assert min(e.getLaneNumber() for e in main) >= 3
        assert sum(e.getLength() for e in main) > 3000
        assert net.getEdge(f"{direction}_on").getToNode() == main[1].getFromNode()
        assert net.getEdge(f"{direction}_off").getFromNode() == main[4].getFromNode()
        # The heading changes along the carriageway: there is a curve.
        shape = main[2].getShape()
        start = math.atan2(shape[1][1] - shape[0][1], shape[1][0] - shape[0][0])
        end = math.atan2(shape[-1][1] - shape[-2][1], shape[-1][0] - shape[-2][0])
        assert abs(math.remainder(end - start, math.tau)) > math.radians(30)
        # The on-ramp feeds the acceleration lane; the off-ramp leaves from the rightmost lane.
        assert net.getEdge(f"{direction}_on").getLane(0).getOutgoing()[0].getToLane().getID() == f"{direction}_1_0"
    # Divided: no edge connects the two carriageways.
    fwd_nodes = {n.getID() for n in net.getNodes() if n.getID().startswith("fwd")}
    for edge in net.getEdges():
        assert (edge.getFromNode().getID() in fwd_nodes) == (edge.getToNode().getID() in fwd_nodes)


def test_urban_grid_has_lights_sidewalks_and_crossings(tmp_path):
    net_file = build_network(NetworkConfig(kind="urban"), tmp_path)
    summary = network_summary(net_file)
    assert summary["traffic_lights"] >= 16  # every inner junction of a 5x5 grid of junctions
    assert summary["crossings"] > 0 and summary["sidewalk_lanes"] > 0
    net = _net(net_file)
    roads = [e for e in net.getEdges(withInternal=False) if e.allows("passenger")]
    assert all(sum(lane.allows("passenger") for lane in e.getLanes()) == 2 for e in roads)
    xs = sorted({round(n.getCoord()[0]) for n in net.getNodes() if n.getType() == "traffic_light"})
    assert len(xs) >= 5  # at least 4 blocks across


def test_osm_extract(tmp_path):
    net_file = build_network(NetworkConfig(kind="osm", osm_file=DATA / "tiny.osm"), tmp_path)
    summary = network_summary(net_file)
    assert summary["edges"] >= 4 and summary["traffic_lights"] == 1
    names = {e.getName() for e in _net(net_file).getEdges(withInternal=False)}
    assert {"Hauptstrasse", "Nebenweg"} <= names


def test_networks_are_byte_identical_when_rebuilt(highway, tmp_path):
    again = build_network(NetworkConfig(kind="highway"), tmp_path)
    assert again.read_bytes() == highway.read_bytes()
    assert b"generated on" not in again.read_bytes()


def test_missing_osm_file_names_the_field(tmp_path):
    with pytest.raises(NetworkError, match=r"network\.osm_file: .*nope\.osm does not exist"):
        build_network(NetworkConfig(kind="osm", osm_file=tmp_path / "nope.osm"), tmp_path / "out")


def test_broken_osm_file_reports_netconvert_error(tmp_path):
    broken = tmp_path / "broken.osm"
    broken.write_text("<osm><node id='1' lat='48.1' lon='11.5'><way></osm>")
    with pytest.raises(NetworkError, match=rf"^{re.escape(str(broken))}, line \d+, column \d+: network\.osm_file: "
                                           r"expected an OpenStreetMap file that netconvert reads; netconvert failed"):
        build_network(NetworkConfig(kind="osm", osm_file=broken), tmp_path / "out")


def test_a_truncated_osm_file_is_named_with_its_line_not_our_copy(tmp_path):
    text = (DATA / "tiny.osm").read_text()
    truncated = tmp_path / "my extract.osm"  # a space: the path is replaced whole
    truncated.write_text(text[:600])
    out = tmp_path / ".simulate.tmp-123"  # as the stage's temporary sibling
    with pytest.raises(NetworkError) as caught:
        build_network(NetworkConfig(kind="osm", osm_file=truncated), out)
    message = str(caught.value)
    where = re.match(rf"{re.escape(str(truncated))}, line (\d+), column (\d+): network\.osm_file: ", message)
    assert where is not None, message
    assert int(where[1]) in (text[:600].count("\n") + 1, text[:600].count("\n") + 2)  # where the input stops
    assert "unexpected end of input" in message.splitlines()[0]
    assert f"In file '{truncated}'" in message
    assert "map.osm.xml" not in message and str(out) not in message


def test_an_osm_error_without_a_line_still_names_the_users_file(tmp_path):
    bad = tmp_path / "bad.osm"
    bad.write_text('<?xml version="1.0"?>\n<osm version="0.6">\n<node id="1" lat="x" lon="11.5"/>\n</osm>\n')
    with pytest.raises(NetworkError, match=rf"^{re.escape(str(bad))}: network\.osm_file: .*netconvert failed "
                                           r"\(exit 1\): Attribute 'lat' in definition of node '1'") as caught:
        build_network(NetworkConfig(kind="osm", osm_file=bad), tmp_path / "out")
    assert "map.osm.xml" not in str(caught.value) and str(tmp_path / "out") not in str(caught.value)


def test_sumo_tool_errors_name_the_users_paths_for_our_copies(tmp_path):
    user = tmp_path / "users" / "roads.nod.xml"
    user.parent.mkdir()
    user.write_text('<nodes>\n  <node id="a" x="0" y="0"/>\n  <node id="b" x="1" y="0"><bad>\n</nodes>\n')
    work = tmp_path / "work"
    work.mkdir()
    (work / "copy.nod.xml").write_bytes(user.read_bytes())
    with pytest.raises(SumoToolError) as caught:
        run_tool([binary("netconvert"), "--node-files", "copy.nod.xml", "-o", "n.net.xml"], cwd=work,
                 inputs={"copy.nod.xml": user})
    assert "copy.nod.xml" not in str(caught.value) and f"In file '{user}'" in str(caught.value)
    assert re.fullmatch(rf"{re.escape(str(user))}, line \d+, column \d+", caught.value.location)
    assert caught.value.detail.startswith("netconvert failed (exit 1): expected end of tag 'bad'\n")
    assert str(caught.value) == f"{caught.value.location}: {caught.value.detail}"


def test_broken_network_file_is_reported(tmp_path):
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net><edge id='x'>")
    with pytest.raises(NetworkError, match="bad.net.xml: not a readable SUMO network"):
        network_summary(bad)
