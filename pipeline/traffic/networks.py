"""Road networks built by SUMO's own tools: a highway from plain XML, an urban grid, any OSM extract.

Every builder writes ``<name>.net.xml`` (and its plain-XML inputs, where it has some) into a folder and
returns the network's path. Generated files carry no timestamp, so the same config gives the same bytes.
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.core.config import NetworkConfig, NetworkKind
from pipeline.core.config.scenario import HighwayNetwork, UrbanNetwork
from pipeline.traffic.sumo_tools import SumoToolError, binary, run_tool, strip_timestamp, sumo_home

log = logging.getLogger(__name__)

NET_FILE = "network.net.xml"
_MOTORWAY, _RAMP = "highway.motorway", "highway.motorway_link"
# A parking lane: no class may drive on it (so netconvert connects nothing to it and moving traffic never
# enters it); its lane type marks it for the road geometry and the parked-vehicle placement.
PARKING_LANE_TYPE = "parking"


class NetworkError(ValueError):
    """A network could not be built or read; names the file and what went wrong."""


def build_network(config: NetworkConfig, out_dir: Path) -> Path:
    """Build the configured network into ``out_dir``; return the path of the .net.xml."""
    out_dir.mkdir(parents=True, exist_ok=True)
    builders = {NetworkKind.HIGHWAY: _build_highway, NetworkKind.URBAN: _build_urban, NetworkKind.OSM: _build_osm}
    try:
        net = builders[config.kind](config, out_dir)
    except SumoToolError as exc:  # from our own plain XML, built from the scenario's settings
        kind = config.kind.value
        raise NetworkError(f"network.{kind}: building the {kind} network from these settings failed: {exc}") from None
    strip_timestamp(net)
    return net


# --- highway -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Centreline:
    """The motorway's centre line: straight, a left-hand arc, straight. Stations s in metres."""

    straight_m: float
    radius_m: float
    angle_rad: float

    @property
    def length_m(self) -> float:
        return 2 * self.straight_m + self.radius_m * self.angle_rad

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (N, 2) and headings (N,) at stations ``s`` (N,)."""
        s = np.asarray(s, dtype=np.float64)
        arc_len = self.radius_m * self.angle_rad
        heading = np.where(
            s <= self.straight_m, 0.0, np.minimum((s - self.straight_m) / self.radius_m, self.angle_rad)
        )
        # Arc centre lies to the left (+y) of the end of the first straight.
        arc_x = self.straight_m + self.radius_m * np.sin(heading)
        arc_y = self.radius_m * (1 - np.cos(heading))
        beyond = np.maximum(s - self.straight_m - arc_len, 0.0)
        x = np.where(s <= self.straight_m, s, arc_x + beyond * np.cos(self.angle_rad))
        y = np.where(s <= self.straight_m, 0.0, arc_y + beyond * np.sin(self.angle_rad))
        return np.stack([x, y], axis=1), heading


def _fmt(points: np.ndarray) -> str:
    return " ".join(f"{x:.2f},{y:.2f}" for x, y in points)


def _highway_xml(cfg: HighwayNetwork) -> tuple[ET.Element, ET.Element, ET.Element, ET.Element]:
    """Plain XML (types, nodes, edges, connections) of a divided motorway with ramps both ways."""
    line = _Centreline(cfg.straight_length_m, cfg.curve_radius_m, math.radians(cfg.curve_angle_deg))
    total, n, w = line.length_m, cfg.lanes_per_direction, cfg.lane_width_m
    types, nodes, edges, cons = ET.Element("types"), ET.Element("nodes"), ET.Element("edges"), ET.Element("connections")
    ET.SubElement(types, "type", id=_MOTORWAY, priority="13", numLanes=str(n), speed=f"{cfg.speed_limit_mps:.2f}",
                  width=f"{w:.2f}", oneway="1", disallow="pedestrian bicycle moped", spreadType="right")
    ET.SubElement(types, "type", id=_RAMP, priority="12", numLanes="1", speed=f"{cfg.ramp_speed_mps:.2f}",
                  width=f"{w:.2f}", oneway="1", disallow="pedestrian bicycle moped", spreadType="right")
    # Stations along each carriageway's own direction of travel.
    merge, merge_end = 400.0, 650.0
    diverge_start, diverge = total - 900.0, total - 700.0
    stations = [0.0, merge, merge_end, diverge_start, diverge, total]
    lane_counts = [n, n + 1, n, n + 1, n]
    for direction, sign in (("fwd", 1.0), ("bwd", -1.0)):

        def place(s: np.ndarray, offset_m: float, sign: float = sign) -> np.ndarray:
            # s along this direction; offset to the right of travel, from the median line.
            s_line = s if sign > 0 else total - s
            pts, heading = line.at(s_line)
            left = np.stack([-np.sin(heading), np.cos(heading)], axis=1) * sign
            return pts - left * (cfg.median_width_m / 2 + offset_m)

        node_xy = place(np.array(stations), 0.0)
        ids = [f"{direction}_n{i}" for i in range(len(stations))]
        for i, (node_id, (x, y)) in enumerate(zip(ids, node_xy, strict=True)):
            attrs = {"id": node_id, "x": f"{x:.2f}", "y": f"{y:.2f}"}
            if i == 2:
                attrs["type"] = "zipper"  # the acceleration lane ends in a zipper merge
            ET.SubElement(nodes, "node", attrs)
        for i in range(len(stations) - 1):
            s = np.arange(stations[i], stations[i + 1], 10.0)[1:]
            inner = place(s, 0.0)
            ET.SubElement(edges, "edge", id=f"{direction}_{i}", **{"from": ids[i], "to": ids[i + 1]}, type=_MOTORWAY,
                          numLanes=str(lane_counts[i]), shape=_fmt(np.vstack([node_xy[i], inner, node_xy[i + 1]])))
        ramp_offset = n * w + 35.0
        # Ramps curve in from (out to) well beside the carriageway.
        on_xy = np.vstack([place(np.array([merge - 320.0]), ramp_offset),
                           place(np.array([merge - 160.0]), n * w + 8.0)])
        off_xy = np.vstack([place(np.array([diverge + 160.0]), n * w + 8.0),
                            place(np.array([diverge + 320.0]), ramp_offset)])
        ET.SubElement(nodes, "node", id=f"{direction}_ramp_in", x=f"{on_xy[0, 0]:.2f}", y=f"{on_xy[0, 1]:.2f}")
        ET.SubElement(nodes, "node", id=f"{direction}_ramp_out", x=f"{off_xy[1, 0]:.2f}", y=f"{off_xy[1, 1]:.2f}")
        ET.SubElement(edges, "edge", id=f"{direction}_on", **{"from": f"{direction}_ramp_in", "to": ids[1]},
                      type=_RAMP, shape=_fmt(np.vstack([on_xy, place(np.array([merge]), n * w)])))
        ET.SubElement(edges, "edge", id=f"{direction}_off", **{"from": ids[4], "to": f"{direction}_ramp_out"},
                      type=_RAMP, shape=_fmt(np.vstack([place(np.array([diverge]), n * w), off_xy])))
        # SUMO lane 0 is the rightmost. Widening: everything shifts up one; the extra lane is lane 0.
        for lane in range(n):
            _con(cons, f"{direction}_0", f"{direction}_1", lane, lane + 1)
            _con(cons, f"{direction}_2", f"{direction}_3", lane, lane + 1)
        _con(cons, f"{direction}_on", f"{direction}_1", 0, 0)
        _con(cons, f"{direction}_2", f"{direction}_3", 0, 0)
        for lane in range(1, n + 1):
            _con(cons, f"{direction}_1", f"{direction}_2", lane, lane - 1)
            _con(cons, f"{direction}_3", f"{direction}_4", lane, lane - 1)
        _con(cons, f"{direction}_1", f"{direction}_2", 0, 0)
        _con(cons, f"{direction}_3", f"{direction}_off", 0, 0)
    return types, nodes, edges, cons


def _con(parent: ET.Element, src: str, dst: str, from_lane: int, to_lane: int) -> None:
    ET.SubElement(parent, "connection", **{"from": src, "to": dst, "fromLane": str(from_lane), "toLane": str(to_lane)})


def _write_xml(root: ET.Element, path: Path) -> None:
    ET.indent(root)
    path.write_text(ET.tostring(root, encoding="unicode") + "\n")


def _build_highway(config: NetworkConfig, out_dir: Path) -> Path:
    types, nodes, edges, cons = _highway_xml(config.highway)
    for root, name in ((types, "highway.typ.xml"), (nodes, "highway.nod.xml"), (edges, "highway.edg.xml"),
                       (cons, "highway.con.xml")):
        _write_xml(root, out_dir / name)
    run_tool([binary("netconvert"), "--type-files", "highway.typ.xml", "--node-files", "highway.nod.xml",
              "--edge-files", "highway.edg.xml", "--connection-files", "highway.con.xml",
              "--no-turnarounds", "true", "--output-file", NET_FILE], cwd=out_dir)
    return out_dir / NET_FILE


# --- urban ---------------------------------------------------------------------------------------


def _build_urban(config: NetworkConfig, out_dir: Path) -> Path:
    cfg: UrbanNetwork = config.urban
    grid = [binary("netgenerate"), "--grid", "--grid.x-number", str(cfg.blocks_x + 1),
            "--grid.y-number", str(cfg.blocks_y + 1), "--grid.length", f"{cfg.block_length_m:.2f}",
            "--grid.attach-length", f"{cfg.block_length_m / 2:.2f}",
            "--default.lanenumber", str(cfg.lanes_per_direction), "--default.lanewidth", f"{cfg.lane_width_m:.2f}",
            "--default.speed", f"{cfg.speed_limit_mps:.2f}", "--default-junction-type", "traffic_light"]
    finish = ["--sidewalks.guess", "true", "--default.sidewalk-width", f"{cfg.sidewalk_width_m:.2f}",
              "--crossings.guess", "true", "--walkingareas", "true", "--no-turnarounds", "true",
              "--tls.default-type", "static"]
    if cfg.parking_lane_width_m is None:
        run_tool([*grid, *finish, "--seed", "1", "--output-file", NET_FILE], cwd=out_dir)
        return out_dir / NET_FILE
    # netgenerate has no parking lanes: it writes the grid as plain XML, a kerbside lane that no class may use
    # is added as the rightmost lane of every edge, and netconvert builds the network from that (guessing
    # sidewalks outside it, crossings over it, and connections for the driving lanes only, so right turns
    # start from the right driving lane).
    run_tool([*grid, "--seed", "1", "--plain-output-prefix", "urban", "--output-file", "urban.grid.net.xml"],
             cwd=out_dir)
    (out_dir / "urban.grid.net.xml").unlink()
    for name in ("urban.con.xml", "urban.tll.xml"):  # rebuilt from the new lanes' permissions
        (out_dir / name).unlink()
    edges = ET.parse(out_dir / "urban.edg.xml").getroot()
    for edge in edges.iter("edge"):
        edge.set("numLanes", str(int(edge.get("numLanes", "1")) + 1))
        ET.SubElement(edge, "lane", index="0", disallow="all", type=PARKING_LANE_TYPE,
                      width=f"{cfg.parking_lane_width_m:.2f}")
    _write_xml(edges, out_dir / "urban.edg.xml")
    strip_timestamp(out_dir / "urban.nod.xml")
    run_tool([binary("netconvert"), "--node-files", "urban.nod.xml", "--edge-files", "urban.edg.xml", *finish,
              "--output-file", NET_FILE], cwd=out_dir)
    return out_dir / NET_FILE


# --- OpenStreetMap --------------------------------------------------------------------------------


def _build_osm(config: NetworkConfig, out_dir: Path) -> Path:
    osm = Path(config.osm_file).resolve() if config.osm_file else None
    if osm is None or not osm.is_file():
        raise NetworkError(f"network.osm_file: {config.osm_file} does not exist (expected an OpenStreetMap .osm file)")
    typemap = sumo_home() / "data" / "typemap" / "osmNetconvert.typ.xml"
    local = out_dir / "map.osm.xml"
    local.write_bytes(osm.read_bytes())  # the exact input travels with the run
    try:
        run_tool([binary("netconvert"), "--osm-files", local.name, "--type-files", str(typemap),
                  "--geometry.remove", "true", "--ramps.guess", "true", "--roundabouts.guess", "true",
                  "--junctions.join", "true", "--tls.guess-signals", "true", "--tls.discard-simple", "true",
                  "--tls.join", "true", "--sidewalks.guess", "true", "--crossings.guess", "true",
                  "--remove-edges.isolated", "true", "--keep-edges.components", "1", "--no-turnarounds", "true",
                  "--output.street-names", "true", "--output-file", NET_FILE], cwd=out_dir, inputs={local.name: osm})
    except SumoToolError as exc:
        # The user's file (and line, where netconvert gives one), never our copy in the temporary run folder.
        raise NetworkError(f"{exc.location or osm}: network.osm_file: expected an OpenStreetMap file that netconvert "
                           f"reads; {exc.detail}") from None
    return out_dir / NET_FILE


def network_summary(net_file: Path) -> dict[str, object]:
    """Counts that describe a built network (edges, lanes, traffic lights, crossings, length)."""
    import sumolib

    try:
        net = sumolib.net.readNet(str(net_file), withInternal=True, withPedestrianConnections=True)
    except Exception as exc:  # sumolib raises bare exceptions for broken XML
        raise NetworkError(f"{net_file}: not a readable SUMO network ({exc})") from None
    edges = [e for e in net.getEdges(withInternal=False) if e.getFunction() == ""]
    driving = [lane for e in edges for lane in e.getLanes() if lane.allows("passenger")]
    parking = [float(lane.get("length")) for lane in ET.parse(net_file).getroot().iter("lane")
               if lane.get("type") == PARKING_LANE_TYPE]
    return {
        "edges": len(edges),
        "driving_lanes": len(driving),
        "driving_lane_length_m": round(sum(lane.getLength() for lane in driving), 2),
        "traffic_lights": len(net.getTrafficLights()),
        "crossings": sum(1 for e in net.getEdges(withInternal=True) if e.getFunction() == "crossing"),
        "sidewalk_lanes": sum(1 for e in edges for lane in e.getLanes() if lane.getPermissions() == {"pedestrian"}),
        "parking_lanes": len(parking),
        "parking_lane_length_m": round(sum(parking), 2),
    }
