"""SUMO network (.net.xml) to the road geometry tables the renderer builds its static world from.

The simulate stage calls :func:`write_road_geometry` on the generated network and writes ``<sim>/roads/``:

- ``lanes.parquet``: one row per lane (normal, internal, crossing and walking-area lanes), see
  :data:`LANES_SCHEMA`. Shapes are centre lines in the world frame (SUMO network coordinates, metres).
- ``junctions.parquet``: one row per junction with its polygon, see :data:`JUNCTIONS_SCHEMA`.
- ``traffic_lights.parquet``: one row per controlled link (tls_id, link_index), see :data:`TLS_SCHEMA`.
- ``bus_stops.parquet``: the network's bus stops, see :mod:`pipeline.traffic.busstops` (no rows without).
- ``network.json``: bounds (``convBoundary``), counts and flags.

Lane ``kind`` comes from the lane's permissions (allow/disallow) and the edge function: ``crossing`` and
``walkingarea`` by function; otherwise ``driving`` if any road motor vehicle class may use it, ``bike`` if
bicycles may, ``rail`` if only rail classes may, ``sidewalk`` if only pedestrians may, ``parking`` for a lane
of lane type ``parking`` (the urban network's kerbside parking lanes: no class may drive on them; drawn as
asphalt without markings of its own), and ``verge`` if nothing else may (e.g. OSM green verges,
``disallow="all"``).

Marking rule (``left_marking``/``right_marking`` in {solid, dashed, none}), on normal edges only; a
*carriageway* lane is one of kind driving or bike:

- a border between two carriageway lanes of the same edge is ``dashed`` when both lanes have the same kind
  and SUMO allows changing across it in both directions (``changeLeft`` of the right lane and
  ``changeRight`` of the left lane absent, ``all``, or listing the lane's class: passenger for driving,
  bicycle for bike lanes); otherwise ``solid`` (a real one-way-permitted line contains a solid line);
- the outer borders of a carriageway (no carriageway lane beyond it in the same edge: kerb, sidewalk,
  median, the opposite direction) are ``solid``;
- lanes that are not carriageway lanes and all internal, crossing and walking-area lanes: ``none``.

Traffic-light rows: vehicle links stop at the end of the incoming lane's shape, heading along its last
segment. Pedestrian links (walking area to crossing, ``pedestrian`` true) stop at the crossing end nearer
the walking area, heading across the crossing. ``linkIndex2`` (a crossing's reverse signal) is not listed.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.core.tables import read_parquet
from pipeline.traffic.busstops import BUS_STOPS_SCHEMA

log = logging.getLogger(__name__)

DEFAULT_LANE_WIDTH_M = 3.2  # SUMO_const_laneWidth: used when a lane has no width attribute.
_F64_LIST = pa.list_(pa.float64())

LANES_SCHEMA = pa.schema([
    ("lane_id", pa.string()), ("edge_id", pa.string()), ("function", pa.string()), ("kind", pa.string()),
    ("index", pa.int32()), ("width_m", pa.float64()), ("speed_mps", pa.float64()), ("length_m", pa.float64()),
    ("shape_x", _F64_LIST), ("shape_y", _F64_LIST), ("shape_z", _F64_LIST),
    ("left_marking", pa.string()), ("right_marking", pa.string()), ("road_type", pa.string()),
    ("from_junction", pa.string()), ("to_junction", pa.string()),
])
JUNCTIONS_SCHEMA = pa.schema([
    ("junction_id", pa.string()), ("type", pa.string()),
    ("x", pa.float64()), ("y", pa.float64()), ("z", pa.float64()),
    ("shape_x", _F64_LIST), ("shape_y", _F64_LIST), ("shape_z", _F64_LIST),
])
TLS_SCHEMA = pa.schema([
    ("tls_id", pa.string()), ("link_index", pa.int32()),
    ("from_lane", pa.string()), ("to_lane", pa.string()), ("via_lane", pa.string()),
    ("stop_x", pa.float64()), ("stop_y", pa.float64()), ("stop_z", pa.float64()),
    ("heading_rad", pa.float64()), ("pedestrian", pa.bool_()),
])

_RAIL = {"tram", "rail_urban", "rail", "rail_electric", "rail_fast", "subway", "cable_car"}
_ROAD_MOTOR = {
    "private", "emergency", "authority", "army", "vip", "passenger", "hov", "taxi", "bus", "coach", "delivery",
    "truck", "trailer", "motorcycle", "moped", "evehicle", "custom1", "custom2", "container",
}
_ALL_CLASSES = _RAIL | _ROAD_MOTOR | {"ignoring", "pedestrian", "bicycle", "ship", "wheelchair", "scooter",
                                     "aircraft", "drone"}
CARRIAGEWAY_KINDS = ("driving", "bike")


@dataclass(frozen=True)
class RoadGeometry:
    """The road geometry tables (rows sorted, columns as in the module's schemas).

    Attributes:
        lanes: one row per lane (:data:`LANES_SCHEMA`); shape columns hold (n,) float64 arrays.
        junctions: one row per junction (:data:`JUNCTIONS_SCHEMA`).
        traffic_lights: one row per controlled link (:data:`TLS_SCHEMA`).
        network: bounds [xmin, ymin, xmax, ymax], has_pedestrians, counts (written as network.json).
        bus_stops: one row per bus stop (:data:`pipeline.traffic.busstops.BUS_STOPS_SCHEMA`); none where the
            scenario has none (and as the network file is read: the scenario chooses them).
    """

    lanes: pd.DataFrame
    junctions: pd.DataFrame
    traffic_lights: pd.DataFrame
    network: dict
    bus_stops: pd.DataFrame = dataclasses.field(default_factory=lambda: BUS_STOPS_SCHEMA.empty_table().to_pandas())


def parse_shape(text: str | None) -> np.ndarray:
    """SUMO shape string ``"x,y[,z] x,y[,z] ..."`` to an (n, 3) float64 array (z = 0 where absent)."""
    if not text:
        return np.zeros((0, 3))
    points = [p.split(",") for p in text.split()]
    out = np.zeros((len(points), 3))
    for i, p in enumerate(points):
        out[i, : len(p)] = [float(v) for v in p[:3]]
    return out


def _permissions(lane: ET.Element) -> set[str]:
    allow, disallow = lane.get("allow"), lane.get("disallow")
    if allow is not None:
        names = set(allow.split())
        return set(_ALL_CLASSES) if "all" in names else names
    names = set((disallow or "").split())
    return set() if "all" in names else _ALL_CLASSES - names


def _lane_kind(function: str, permissions: set[str], lane_type: str | None = None) -> str:
    if function in ("crossing", "walkingarea"):
        return function
    if lane_type == "parking":
        return "parking"
    if permissions & _ROAD_MOTOR:
        return "driving"
    if "bicycle" in permissions:
        return "bike"
    if permissions & _RAIL:
        return "rail"
    if permissions & {"pedestrian", "wheelchair"}:
        return "sidewalk"
    return "verge"


def _may_change(lane: ET.Element, attr: str, kind: str) -> bool:
    value = lane.get(attr)
    if value is None:
        return True
    names = set(value.split())
    return "all" in names or ("passenger" if kind == "driving" else "bicycle") in names


def _edge_markings(lanes: list[ET.Element], kinds: list[str]) -> list[tuple[str, str]]:
    """(left, right) marking per lane of one normal edge, lanes ordered by index (0 = rightmost)."""
    n = len(lanes)
    border = ["solid"] * (n + 1)  # border[i] lies between lane i-1 and lane i; 0 and n are outer.
    for i in range(1, n):
        a, b = kinds[i - 1], kinds[i]
        if a in CARRIAGEWAY_KINDS and b in CARRIAGEWAY_KINDS:
            same = a == b and _may_change(lanes[i - 1], "changeLeft", a) and _may_change(lanes[i], "changeRight", b)
            border[i] = "dashed" if same else "solid"
    return [(border[i + 1], border[i]) if kinds[i] in CARRIAGEWAY_KINDS else ("none", "none") for i in range(n)]


def _lane_rows(root: ET.Element) -> list[dict]:
    rows = []
    for edge in root.iter("edge"):
        function = edge.get("function", "normal")
        if function == "connector":
            continue
        lanes = sorted(edge.iter("lane"), key=lambda e: int(e.get("index", "0")))
        kinds = [_lane_kind(function, _permissions(lane), lane.get("type")) for lane in lanes]
        marks = _edge_markings(lanes, kinds) if function == "normal" else [("none", "none")] * len(lanes)
        for lane, kind, (left, right) in zip(lanes, kinds, marks, strict=True):
            shape = parse_shape(lane.get("shape"))
            rows.append({
                "lane_id": lane.get("id"), "edge_id": edge.get("id"), "function": function, "kind": kind,
                "index": int(lane.get("index", "0")),
                "width_m": float(lane.get("width", DEFAULT_LANE_WIDTH_M)),
                "speed_mps": float(lane.get("speed", "0")), "length_m": float(lane.get("length", "0")),
                "shape_x": shape[:, 0], "shape_y": shape[:, 1], "shape_z": shape[:, 2],
                "left_marking": left, "right_marking": right, "road_type": edge.get("type", ""),
                "from_junction": edge.get("from", ""), "to_junction": edge.get("to", ""),
            })
    return sorted(rows, key=lambda r: r["lane_id"])


def _junction_rows(root: ET.Element) -> list[dict]:
    rows = []
    for j in root.iter("junction"):
        shape = parse_shape(j.get("shape"))
        rows.append({
            "junction_id": j.get("id"), "type": j.get("type", ""),
            "x": float(j.get("x", "0")), "y": float(j.get("y", "0")), "z": float(j.get("z", "0")),
            "shape_x": shape[:, 0], "shape_y": shape[:, 1], "shape_z": shape[:, 2],
        })
    return sorted(rows, key=lambda r: r["junction_id"])


def _stop(from_shape: np.ndarray, to_shape: np.ndarray, pedestrian: bool) -> tuple[np.ndarray, float]:
    """Stop point (3,) and heading (rad) of one link, per the module docstring's rule."""
    if pedestrian and len(to_shape) >= 2:
        centre = from_shape[:, :2].mean(axis=0) if len(from_shape) else to_shape[0, :2]
        near_start = np.linalg.norm(to_shape[0, :2] - centre) <= np.linalg.norm(to_shape[-1, :2] - centre)
        path = to_shape if near_start else to_shape[::-1]
        start, direction = path[0], path[1] - path[0]
    else:
        start, direction = from_shape[-1], from_shape[-1] - from_shape[-2]
    return start, float(np.arctan2(direction[1], direction[0]))


def _tls_rows(root: ET.Element, shapes: dict[str, np.ndarray], functions: dict[str, str]) -> list[dict]:
    rows = []
    for c in root.iter("connection"):
        tls = c.get("tl")
        if tls is None:
            continue
        from_lane = f"{c.get('from')}_{c.get('fromLane')}"
        to_lane = f"{c.get('to')}_{c.get('toLane')}"
        if from_lane not in shapes or to_lane not in shapes:
            raise ValueError(f"connection {from_lane} -> {to_lane} of tls {tls!r} names a lane the network lacks")
        pedestrian = functions.get(c.get("from", "")) == "walkingarea"
        stop, heading = _stop(shapes[from_lane], shapes[to_lane], pedestrian)
        rows.append({
            "tls_id": tls, "link_index": int(c.get("linkIndex", "-1")),
            "from_lane": from_lane, "to_lane": to_lane, "via_lane": c.get("via", ""),
            "stop_x": stop[0], "stop_y": stop[1], "stop_z": stop[2], "heading_rad": heading,
            "pedestrian": pedestrian,
        })
    return sorted(rows, key=lambda r: (r["tls_id"], r["link_index"], r["from_lane"], r["to_lane"]))


def _frame(rows: list[dict], schema: pa.Schema) -> pd.DataFrame:
    frame = pd.DataFrame(rows, columns=schema.names)
    for field in schema:
        if field.type == pa.int32():
            frame[field.name] = frame[field.name].astype(np.int32)
    return frame


def read_network_geometry(net_path: Path) -> RoadGeometry:
    """Parse a SUMO .net.xml into :class:`RoadGeometry` (pure; rows sorted by id).

    Raises:
        FileNotFoundError: the network does not exist.
        ValueError: the file is not a SUMO network or is inconsistent (names the file and what is wrong).
    """
    net_path = Path(net_path)
    if not net_path.is_file():
        raise FileNotFoundError(f"SUMO network not found: {net_path}")
    try:
        root = ET.parse(net_path).getroot()
    except ET.ParseError as err:
        raise ValueError(f"{net_path}: not valid XML ({err})") from err
    if root.tag != "net":
        raise ValueError(f"{net_path}: root element is <{root.tag}>, expected <net> (a SUMO .net.xml)")
    location = root.find("location")
    if location is None or location.get("convBoundary") is None:
        raise ValueError(f"{net_path}: <location convBoundary=...> missing")
    bounds = [float(v) for v in location.get("convBoundary").split(",")]

    lanes = _frame(_lane_rows(root), LANES_SCHEMA)
    shapes = {lid: np.stack([x, y, z], axis=1) for lid, x, y, z in
              zip(lanes.lane_id, lanes.shape_x, lanes.shape_y, lanes.shape_z, strict=True)}
    functions = dict(zip(lanes.edge_id, lanes.function, strict=True))
    try:
        tls = _frame(_tls_rows(root, shapes, functions), TLS_SCHEMA)
    except ValueError as err:
        raise ValueError(f"{net_path}: {err}") from err
    junctions = _frame(_junction_rows(root), JUNCTIONS_SCHEMA)
    kinds = lanes.kind.value_counts()
    network = {
        "bounds": bounds,
        "net_offset": [float(v) for v in location.get("netOffset", "0,0").split(",")],
        "has_pedestrians": bool(kinds.reindex(["sidewalk", "crossing", "walkingarea"]).fillna(0).sum() > 0),
        "num_lanes": len(lanes),
        "num_junctions": len(junctions),
        "num_traffic_lights": int(tls.tls_id.nunique()),
        "num_tls_links": len(tls),
        "lane_kinds": {k: int(v) for k, v in sorted(kinds.items())},
        "sumo_net_version": root.get("version", ""),
    }
    log.info("%s: %d lanes, %d junctions, %d tls links", net_path.name, len(lanes), len(junctions), len(tls))
    return RoadGeometry(lanes, junctions, tls, network)


def _write_parquet(frame: pd.DataFrame, schema: pa.Schema, path: Path) -> None:
    table = pa.Table.from_pandas(frame, schema=schema, preserve_index=False).replace_schema_metadata(None)
    pq.write_table(table, path, compression="zstd", use_dictionary=False, write_statistics=False,
                   write_page_checksum=True)  # read back checked (read_parquet): a flipped byte fails, naming the file


def write_road_geometry(net_path: Path, out_dir: Path, bus_stops: pd.DataFrame | None = None) -> None:
    """Parse ``net_path`` and write lanes/junctions/traffic_lights/bus_stops parquet and network.json into
    ``out_dir``; ``bus_stops``: the scenario's stops on this network (:mod:`pipeline.traffic.busstops`; None: none).

    Output is deterministic: the same network and stops give byte-identical files.
    """
    geometry = read_network_geometry(net_path)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    _write_parquet(geometry.lanes, LANES_SCHEMA, out_dir / "lanes.parquet")
    _write_parquet(geometry.junctions, JUNCTIONS_SCHEMA, out_dir / "junctions.parquet")
    _write_parquet(geometry.traffic_lights, TLS_SCHEMA, out_dir / "traffic_lights.parquet")
    _write_parquet(geometry.bus_stops if bus_stops is None else bus_stops, BUS_STOPS_SCHEMA,
                   out_dir / "bus_stops.parquet")
    (out_dir / "network.json").write_text(json.dumps(geometry.network, indent=2, sort_keys=True) + "\n")


def load_road_geometry(roads_dir: Path) -> RoadGeometry:
    """Read the tables written by :func:`write_road_geometry` (shape cells as (n,) float64 arrays)."""
    roads_dir = Path(roads_dir)
    missing = [n for n in ("lanes.parquet", "junctions.parquet", "traffic_lights.parquet", "bus_stops.parquet",
                           "network.json") if not (roads_dir / n).is_file()]
    if missing:
        older = " (a simulation made before bus stops lacks it: simulate again)" \
            if missing == ["bus_stops.parquet"] else ""
        raise FileNotFoundError(f"{roads_dir}: road geometry incomplete, missing {', '.join(missing)}{older}")
    tables = [read_parquet(roads_dir / f"{n}.parquet") for n in ("lanes", "junctions", "traffic_lights", "bus_stops")]
    for frame in tables:
        # Python strings, not pandas' Arrow-backed ones: the world build selects and reads these tables lane by lane,
        # and Arrow strings made that measurably slower (docs/performance.md).
        for col in frame.columns:
            if pd.api.types.is_string_dtype(frame[col].dtype) and frame[col].dtype != object:
                frame[col] = frame[col].astype(object)
        for col in ("shape_x", "shape_y", "shape_z"):
            if col in frame:
                frame[col] = [np.asarray(v, dtype=np.float64) for v in frame[col]]
    lanes, junctions, lights, stops = tables
    return RoadGeometry(lanes, junctions, lights, json.loads((roads_dir / "network.json").read_text()), stops)
