"""Demand: naturalistic background vehicles with per-vehicle parameters, and pedestrians.

Routes come from SUMO's randomTrips (which validates them with duarouter). Each vehicle then gets
its own vType whose car-following (IDM) and lane-change parameters, size and colour are drawn from the
configured distributions with a numpy Generator derived from the run's seed. We draw per vehicle
ourselves rather than through createVehTypeDistribution because SUMO would then pick a type per
vehicle with its own random draw at insertion; drawing here lets the exact parameters of every vehicle
be recorded (``vehicles.parquet``) and tested against their distributions.
"""

from __future__ import annotations

import dataclasses
import logging
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.core.classes import ObjectClass
from pipeline.core.config import DemandConfig, DriverModel
from pipeline.core.config.scenario import DeparturePattern
from pipeline.traffic.busstops import (
    DWELL_TAG,
    bus_route_stops,
    bus_stop_lanes,
    choose_bus_stops,
    empty_bus_stops,
    waiting_people,
)
from pipeline.traffic.roadgeometry import read_network_geometry
from pipeline.traffic.sumo_tools import run_python_tool

log = logging.getLogger(__name__)

ROUTES_FILE = "demand.rou.xml"

SUMO_VCLASS = {
    ObjectClass.CAR: "passenger",
    ObjectClass.VAN: "delivery",
    ObjectClass.TRUCK: "truck",
    ObjectClass.BUS: "bus",
    ObjectClass.MOTORCYCLE: "motorcycle",
    ObjectClass.BICYCLE: "bicycle",
}
_GUI_SHAPE = {
    ObjectClass.CAR: "passenger",
    ObjectClass.VAN: "delivery",
    ObjectClass.TRUCK: "truck",
    ObjectClass.BUS: "bus",
    ObjectClass.MOTORCYCLE: "motorcycle",
    ObjectClass.BICYCLE: "bicycle",
}
DRIVER_FIELDS = tuple(DriverModel.model_fields)
# SUMO's default pedestrian type (DEFAULT_PEDTYPE): its length is the body depth.
PEDESTRIAN_SIZE_M = {"length_m": 0.215, "width_m": 0.478, "height_m": 1.719}
# The colour of a pedestrian's top, coat or dress (sRGB; the render's ``garment``) and its share. Our estimate of
# what people wear over their clothes in a European city outside summer, not a survey: dark outerwear dominates
# (black 26 %, navy 12 %, dark grey 10 %), then greys, white and cream, beige and camel, blues, browns, olive, reds,
# and a few bright colours. Trousers, skirts, shoes and hair are the body family's (pipeline/world/people.py).
CLOTHES = np.array([[25, 25, 28], [60, 60, 64], [120, 120, 125], [28, 36, 64], [50, 80, 140], [140, 170, 200],
                    [225, 222, 212], [190, 160, 115], [95, 65, 45], [85, 90, 55], [130, 30, 40], [220, 170, 40],
                    [210, 120, 140], [200, 40, 40]], dtype=np.uint8)
CLOTHES_SHARES = np.array([0.26, 0.10, 0.07, 0.12, 0.06, 0.04, 0.07, 0.07, 0.05, 0.05, 0.05, 0.02, 0.02, 0.02])
# Standing pedestrians come alone, in twos or in threes with these shares of groups: our estimate for a weekday
# street (most people in city streets walk in groups of 2-3 or alone: Moussaid et al., "The walking behaviour of
# pedestrian social groups and its impact on crowd dynamics", PLoS ONE 5(4): e10047, 2010).
STANDING_GROUPS = (1, 2, 3)
STANDING_GROUP_SHARES = (0.5, 0.35, 0.15)
STANDING_SPACING_M = 0.75  # between the members of a standing group's stops, along the sidewalk (SUMO's places)
# Where a standing group's members stand and face, as people who talk to each other do: in an F-formation (Kendon,
# "Conducting Interaction", 1990), each facing a shared space between them, at the near end of Hall's personal
# distance ("The Hidden Dimension", 1966: 0.45-1.2 m). Two face each other FORMATION_PAIR_M apart, three stand on a
# circle of FORMATION_RADIUS_M facing its centre, the formation turned at random on the sidewalk; they stand
# STANDING_LATERAL_M right of the sidewalk's centre line (negative: towards the kerb; pipeline.traffic.simulation),
# shifted so that every member keeps FORMATION_MARGIN_M from the sidewalk's edges. Without it the members stood in a
# file along the sidewalk all facing one way, which a camera down the street sees as one wall of overlapping people.
FORMATION_PAIR_M = 1.0
FORMATION_RADIUS_M = 0.65
FORMATION_MARGIN_M = 0.3
STANDING_LATERAL_M = -0.9
RUNNERS_TAG = 41  # the random stream that picks the runners among the walkers and draws their speeds
# Which way a person standing alone faces, from the sidewalk's direction towards its right (radians), and its share:
# the street (waiting to cross, for someone, a bus), the shop fronts and walls, and along the sidewalk either way
# (waiting, on the phone), each turned by up to LONE_TURN_RAD either way. Our estimate, no survey; before, everyone
# standing alone faced along the sidewalk (SUMO's angle of a waiting person).
LONE_FACING_RAD = (-0.5 * np.pi, 0.5 * np.pi, 0.0, np.pi)
LONE_FACING_SHARES = (0.4, 0.25, 0.175, 0.175)
LONE_TURN_RAD = np.pi / 6
LONE_FACING_TAG = 42  # their random stream (the rest of the demand draws as before)
FORMATION_PARAM = "roadsynth.stand"  # a person's <param>: "dx dy face" (see _formation)


class DemandError(ValueError):
    """Demand could not be generated (e.g. the network has too few valid routes)."""


@dataclass(frozen=True)
class Demand:
    """Generated demand.

    Attributes:
        vehicles: one row per vehicle: vehicle_id, cls, depart_s, route (space-separated edges),
            route_length_m, length_m, width_m, height_m, color_r/g/b, max_speed_mps and one column per
            DriverModel field.
        persons: one row per person (see :func:`_pedestrians`): walkers, standing people, people waiting at the
            bus stops.
        routes_file: the written SUMO route file.
        bus_stops: the network's bus stops (:data:`pipeline.traffic.busstops.BUS_STOPS_SCHEMA`; none unless
            ``config.bus_stops``), written beside the road geometry by the simulate stage.
    """

    vehicles: pd.DataFrame
    persons: pd.DataFrame
    routes_file: Path
    bus_stops: pd.DataFrame = dataclasses.field(default_factory=empty_bus_stops)

    def actor_table(self) -> pd.DataFrame:
        """Static attributes of every actor, indexed by SUMO id: track_id (1.., stable), cls, size, colour."""
        cols = ["cls", "length_m", "width_m", "height_m", "color_r", "color_g", "color_b"]
        vehicles = self.vehicles.set_index("vehicle_id")[cols]
        persons = self.persons.set_index("person_id")
        persons = persons.assign(cls=ObjectClass.PEDESTRIAN.value, **PEDESTRIAN_SIZE_M)[cols]
        table = pd.concat([vehicles, persons]).astype({c: np.uint8 for c in cols if c.startswith("color_")})
        table.insert(0, "track_id", np.arange(1, len(table) + 1, dtype=np.int32))
        return table


def _random_routes(net_file: Path, count: int, seed: int, min_distance_m: float, work: Path, *, prefix: str,
                   extra: list[str], fringe_factor: str = "max") -> list[tuple[str, list[str]]]:
    """``count`` or more validated routes from randomTrips, as (trip id, edge list). ``fringe_factor`` weighs
    origins and destinations on the network's fringe (randomTrips' --fringe-factor; "max": only there)."""
    trips, routes = work / f"{prefix}.trips.xml", work / f"{prefix}.rou.xml"
    # Ask for twice as many as needed: validation drops trips without a route.
    period = 1.0 / (2 * count)
    run_python_tool("randomTrips.py", ["-n", str(net_file), "-o", trips.name, "-r", routes.name, "--seed", str(seed),
                                       "-b", "0", "-e", "1", "-p", f"{period:.9f}", "--prefix", prefix,
                                       "--min-distance", f"{min_distance_m:.1f}", "--fringe-factor", fringe_factor,
                                       "--validate", *extra], cwd=work)
    root = ET.parse(routes).getroot()
    out = []
    for veh in root.iter("vehicle"):
        route = veh.find("route")
        if route is not None:
            out.append((veh.get("id"), route.get("edges").split()))
    for person in root.iter("person"):
        walk = person.find("walk")
        if walk is not None and walk.get("edges"):
            out.append((person.get("id"), walk.get("edges").split()))
    return out


def sample_driver(model: DriverModel, rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """Draw every DriverModel parameter for ``n`` vehicles (one independent stream per field)."""
    return {name: getattr(model, name).sample(rng, n) for name in DRIVER_FIELDS}


def sample_vehicles(config: DemandConfig, rng: np.random.Generator) -> pd.DataFrame:
    """Class, size, colour and driver parameters for every vehicle (routes and departures excluded)."""
    n = config.vehicles
    classes = sorted(config.classes, key=lambda c: c.value)
    shares = np.array([config.classes[c].share for c in classes])
    cls_index = rng.choice(len(classes), size=n, p=shares / shares.sum())
    frame = pd.DataFrame({"cls": [classes[i].value for i in cls_index]})
    columns: dict[str, np.ndarray] = {}
    for name in ("length_m", "width_m", "height_m", "max_speed_mps", "color_r", "color_g", "color_b",
                 *DRIVER_FIELDS):
        columns[name] = np.zeros(n)
    for k, cls in enumerate(classes):
        mask = cls_index == k
        count = int(mask.sum())
        spec = config.classes[cls]
        for name in ("length_m", "width_m", "height_m"):
            columns[name][mask] = getattr(spec, name).sample(rng, count)
        colors = np.asarray(spec.colors)[spec.color_index(rng, count)]
        columns["color_r"][mask], columns["color_g"][mask], columns["color_b"][mask] = colors.T
        columns["max_speed_mps"][mask] = spec.max_speed_mps
        for name, values in sample_driver(spec.driver or config.driver, rng, count).items():
            columns[name][mask] = values
    for name, values in columns.items():
        frame[name] = values.astype(np.uint8) if name.startswith("color_") else values
    return frame


def _depart_times(config: DemandConfig, rng: np.random.Generator) -> np.ndarray:
    n, window = config.vehicles, config.depart_window_s
    if config.departure is DeparturePattern.UNIFORM:
        return np.arange(n) * (window / n)
    return np.sort(rng.uniform(0.0, window, size=n))


def build_demand(config: DemandConfig, net_file: Path, out_dir: Path, work_dir: Path, seed: int) -> Demand:
    """Sample the vehicles, route them, and write ``out_dir/demand.rou.xml``."""
    rng = np.random.default_rng([seed, 0xDE3A4D])
    work_dir.mkdir(parents=True, exist_ok=True)
    vclasses = {SUMO_VCLASS[c] for c in config.classes}
    vclass = "passenger" if "passenger" in vclasses else sorted(vclasses)[0]
    net_file = net_file.resolve()
    routes = _random_routes(net_file, config.vehicles, seed, config.min_route_length_m, work_dir, prefix="veh",
                            extra=["--vehicle-class", vclass])
    if len(routes) < config.vehicles:
        raise DemandError(f"{net_file}: only {len(routes)} valid routes of at least {config.min_route_length_m} m "
                          f"for {config.vehicles} vehicles; lower demand.vehicles or min_route_length_m")
    vehicles = sample_vehicles(config, rng)
    # SUMO reads the parameters at the precision written to the route file; record exactly those.
    rounded = ["length_m", "width_m", "height_m", *DRIVER_FIELDS]
    vehicles[rounded] = vehicles[rounded].round(4)
    vehicles.insert(0, "vehicle_id", [f"veh{i:04d}" for i in range(config.vehicles)])
    vehicles.insert(2, "depart_s", np.round(_depart_times(config, rng), 2))
    vehicles.insert(3, "route", [" ".join(edges) for _, edges in routes[: config.vehicles]])
    persons = _pedestrians(config, net_file, work_dir, seed, rng)
    lanes = read_network_geometry(net_file).lanes if config.bus_stops is not None else None
    stops = empty_bus_stops() if lanes is None else choose_bus_stops(lanes, config.bus_stops)
    bus_stops = {}
    if len(stops):
        waiting = waiting_people(stops, config, len(persons), seed, CLOTHES, CLOTHES_SHARES)
        persons = pd.concat([persons, waiting.astype(persons.dtypes.to_dict())], ignore_index=True)
        bus_stops = _bus_stops_on_routes(vehicles, stops, lanes, config, seed)
    path = out_dir / ROUTES_FILE
    _write_routes(vehicles, persons, path, config.depart_pos.value, bus_stops)
    return Demand(vehicles, persons, path, stops)


def _bus_stops_on_routes(vehicles: pd.DataFrame, stops: pd.DataFrame, lanes: pd.DataFrame, config: DemandConfig,
                         seed: int) -> dict[str, list[tuple[str, float, float]]]:
    """vehicle id -> the stops (lane id, position, dwell seconds) each bus makes on its route
    (:func:`pipeline.traffic.busstops.bus_route_stops`; ``lanes`` the network's lane table), dwell times from
    ``config.bus_stops.dwell_s`` on a random stream of their own (DWELL_TAG), so that every other draw of the demand
    is as it was; none where ``dwell_s`` is None."""
    dwell = config.bus_stops.dwell_s if config.bus_stops is not None else None
    if dwell is None:
        return {}
    lanes = bus_stop_lanes(lanes, stops)
    rng = np.random.default_rng([seed, DWELL_TAG])
    out = {}
    for row in vehicles[vehicles["cls"] == ObjectClass.BUS.value].itertuples(index=False):
        on_route = bus_route_stops(row.route, lanes)
        if on_route:
            times = np.round(dwell.sample(rng, len(on_route)), 1)
            out[row.vehicle_id] = [(lane, pos, float(t)) for (lane, pos), t in zip(on_route, times, strict=True)]
    return out


def network_bus_stops(net_file: Path, config: DemandConfig) -> pd.DataFrame:
    """The bus stops ``config.bus_stops`` asks for on the network of ``net_file``
    (:func:`pipeline.traffic.busstops.choose_bus_stops`; none without it)."""
    if config.bus_stops is None:
        return empty_bus_stops()
    return choose_bus_stops(read_network_geometry(net_file).lanes, config.bus_stops)


def _pedestrians(config: DemandConfig, net_file: Path, work: Path, seed: int,
                 rng: np.random.Generator) -> pd.DataFrame:
    """One row per person: person_id, depart_s, route, speed_mps, color_r/g/b, and for those who stand first (after
    the ``pedestrians`` walkers, ``standing_pedestrians`` more) the sidewalk lane, the position on it and how long
    they stand (stop_lane, stop_pos_m, stop_s; "" and NaN for walkers)."""
    columns = {"person_id": str, "depart_s": float, "route": str, "speed_mps": float, "color_r": np.uint8,
               "color_g": np.uint8, "color_b": np.uint8, "stop_lane": str, "stop_pos_m": float, "stop_s": float,
               "stand_dx_m": float, "stand_dy_m": float, "stand_face_rad": float}
    total = config.pedestrians + config.standing_pedestrians
    if total == 0:
        return pd.DataFrame({c: pd.Series(dtype=t) for c, t in columns.items()})
    # Walks start and end anywhere (not on the fringe like vehicles'): people come out of the buildings, and
    # a walker covers only ~100 m during the warm-up, so fringe origins would leave the inner streets empty.
    walks = _random_routes(net_file, total, seed + 1, 50.0, work, prefix="ped",
                           extra=["--pedestrians", "--max-distance", "1500"], fringe_factor="1")
    if len(walks) < total:
        raise DemandError(f"{net_file}: only {len(walks)} valid walks for {total} pedestrians "
                          "(does the network have sidewalks?)")
    n = config.pedestrians
    clothes = CLOTHES[rng.choice(len(CLOTHES), size=total, p=CLOTHES_SHARES)]
    walkers = pd.DataFrame({
        "person_id": [f"ped{i:04d}" for i in range(n)],
        "depart_s": np.round(np.sort(rng.uniform(0.0, config.depart_window_s, size=n)), 2),
        "route": [" ".join(edges) for _, edges in walks[:n]],
        "speed_mps": config.pedestrian_speed_mps.sample(rng, n),
        "stop_lane": "", "stop_pos_m": np.nan, "stop_s": np.nan, "stand_dx_m": np.nan, "stand_dy_m": np.nan,
        "stand_face_rad": np.nan,
    })
    walkers["speed_mps"] = _with_runners(config, walkers["speed_mps"].to_numpy(), seed)
    standing = _standing(config, _sidewalks(net_file), walks[n:total], rng, np.random.default_rng([seed, 40]),
                         np.random.default_rng([seed, LONE_FACING_TAG]))
    persons = pd.concat([walkers, standing], ignore_index=True)
    persons["color_r"], persons["color_g"], persons["color_b"] = clothes.T
    return persons[list(columns)].astype({c: t for c, t in columns.items() if t is not str})


def _with_runners(config: DemandConfig, speed_mps: np.ndarray, seed: int) -> np.ndarray:
    """The walkers' speeds with a share ``config.runners`` of them (each one independently) running at
    ``config.runner_speed_mps`` instead, drawn from a random stream of their own (RUNNERS_TAG), so that everyone
    else's draws stay as they were."""
    speed_mps = np.array(speed_mps, np.float64)
    if config.runners > 0.0:
        rng = np.random.default_rng([seed, RUNNERS_TAG])
        runs = np.flatnonzero(rng.random(len(speed_mps)) < config.runners)
        speed_mps[runs] = config.runner_speed_mps.sample(rng, len(runs))
    return speed_mps


def _sidewalks(net_file: Path) -> dict[str, tuple[str, float, float]]:
    """Edge id -> (its sidewalk lane's id, that lane's length and width in metres) for the network's edges with a
    sidewalk (a lane without a width has SUMO's default, 3.2 m)."""
    out = {}
    for edge in ET.parse(net_file).getroot().iter("edge"):
        if edge.get("function") not in (None, "normal"):
            continue
        for lane in edge.iter("lane"):
            if lane.get("allow") == "pedestrian":
                out[edge.get("id")] = (lane.get("id"), float(lane.get("length")), float(lane.get("width", "3.2")))
                break
    return out


def _standing(config: DemandConfig, sidewalks: dict[str, tuple[str, float, float]],
              walks: list[tuple[str, list[str]]], rng: np.random.Generator,
              formation_rng: np.random.Generator | None = None,
              facing_rng: np.random.Generator | None = None) -> pd.DataFrame:
    """The standing pedestrians, in groups (STANDING_GROUPS): each group's stops lie STANDING_SPACING_M apart at a
    random place on the sidewalk of its first walk's first edge, from a common departure for a common time, then it
    walks that route together at the slowest member's speed. The members of a group of two or three stand in a
    formation (:func:`_formation`, drawn from ``formation_rng``; a stream of its own, so the rest of the demand is
    the same with or without it): stand_dx_m, stand_dy_m, stand_face_rad. One standing alone stands STANDING_LATERAL_M
    right of the centre line facing a way drawn from ``facing_rng`` (:func:`_lone_facing`)."""
    rows = []
    k = 0
    formation_rng = formation_rng or np.random.default_rng(0)
    facing_rng = facing_rng or np.random.default_rng(1)
    while k < config.standing_pedestrians:
        size = min(int(rng.choice(STANDING_GROUPS, p=STANDING_GROUP_SHARES)), config.standing_pedestrians - k)
        _, edges = walks[k]
        lane, length_m, width_m = sidewalks.get(edges[0], ("", 0.0, 0.0))
        span = STANDING_SPACING_M * (size - 1)
        if length_m < span + 6.0:  # no room for the group on this sidewalk: they walk instead
            lane, pos = "", np.full(size, np.nan)
        else:
            pos = rng.uniform(3.0, length_m - 3.0 - span) + STANDING_SPACING_M * np.arange(size)
        depart = round(float(rng.uniform(0.0, config.depart_window_s)), 2)
        stand = float(config.standing_s.sample(rng, 1)[0]) if lane else np.nan
        speed = float(config.pedestrian_speed_mps.sample(rng, size).min())
        places = np.full((size, 3), np.nan)
        if lane:
            places = _formation(size, pos, width_m, formation_rng) if size > 1 else \
                np.array([[0.0, STANDING_LATERAL_M, _lone_facing(facing_rng)]])
        for j in range(size):
            rows.append({"person_id": f"ped{config.pedestrians + k + j:04d}", "depart_s": depart,
                         "route": " ".join(edges), "speed_mps": speed, "stop_lane": lane,
                         "stop_pos_m": round(float(pos[j]), 2), "stop_s": round(stand, 1),
                         "stand_dx_m": round(float(places[j, 0]), 3), "stand_dy_m": round(float(places[j, 1]), 3),
                         "stand_face_rad": round(float(places[j, 2]), 4)})
        k += size
    return pd.DataFrame(rows, columns=["person_id", "depart_s", "route", "speed_mps", "stop_lane", "stop_pos_m",
                                       "stop_s", "stand_dx_m", "stand_dy_m", "stand_face_rad"])


def _lone_facing(rng: np.random.Generator) -> float:
    """The way a person standing alone faces (radians from the sidewalk's direction towards its right): one of
    LONE_FACING_RAD with LONE_FACING_SHARES, turned uniformly by up to LONE_TURN_RAD either way."""
    base = LONE_FACING_RAD[int(rng.choice(len(LONE_FACING_RAD), p=LONE_FACING_SHARES))]
    return float(base + rng.uniform(-LONE_TURN_RAD, LONE_TURN_RAD))


def _formation(size: int, stops_m: np.ndarray, width_m: float, rng: np.random.Generator) -> np.ndarray:
    """(size, 3): where each member of a standing group stands and faces, in its sidewalk's frame (a along the lane,
    l to its right): dx, the member's place along the lane less its own stop ``stops_m[j]`` (SUMO's), dy, its offset
    right of the lane's centre line, and face, the angle of the way it faces from the lane's direction towards its
    right (radians). Two face each other FORMATION_PAIR_M apart, three stand on a circle of FORMATION_RADIUS_M facing
    its centre; the formation is turned by a uniform angle, centred on the stops' mean along the lane and
    STANDING_LATERAL_M across it, shifted across to keep FORMATION_MARGIN_M inside a sidewalk ``width_m`` wide."""
    turn = float(rng.uniform(0.0, 2.0 * np.pi))
    radius = 0.5 * FORMATION_PAIR_M if size == 2 else FORMATION_RADIUS_M
    angle = turn + 2.0 * np.pi * np.arange(size) / size
    u, v = radius * np.cos(angle), radius * np.sin(angle)
    room = max(0.5 * width_m - FORMATION_MARGIN_M, float(np.max(np.abs(v))))
    centre_l = float(np.clip(STANDING_LATERAL_M, -room - v.min(), room - v.max()))
    dx = float(np.mean(stops_m)) + u - np.asarray(stops_m, np.float64)
    return np.column_stack([dx, centre_l + v, np.arctan2(-v, -u)])


def _g(x: float) -> str:
    return f"{x:.4f}".rstrip("0").rstrip(".")


def _vtype(row) -> dict[str, str]:
    cls = ObjectClass(row.cls)
    attrs = {
        "id": f"t_{row.vehicle_id}", "vClass": SUMO_VCLASS[cls], "guiShape": _GUI_SHAPE[cls],
        "length": _g(row.length_m), "width": _g(row.width_m), "height": _g(row.height_m),
        "color": f"{row.color_r},{row.color_g},{row.color_b}", "maxSpeed": _g(row.max_speed_mps),
        "carFollowModel": "IDM", "accel": _g(row.accel_mps2), "decel": _g(row.decel_mps2),
        "emergencyDecel": _g(max(9.0, row.decel_mps2)), "tau": _g(row.tau_s), "minGap": _g(row.min_gap_m),
        "delta": _g(row.delta), "speedFactor": _g(row.speed_factor), "speedDev": "0",
        "laneChangeModel": "LC2013", "lcCooperative": _g(row.lc_cooperative), "lcAssertive": _g(row.lc_assertive),
    }
    return attrs


def _write_routes(vehicles: pd.DataFrame, persons: pd.DataFrame, path: Path, depart_pos: str,
                  bus_stops: dict[str, list[tuple[str, float, float]]] | None = None) -> None:
    """The SUMO route file: a vType per vehicle, then vehicles and persons by departure; ``bus_stops``: vehicle id
    -> the stops (lane id, position, dwell seconds) the bus makes on its route, in route order."""
    bus_stops = bus_stops or {}
    root = ET.Element("routes")
    root.append(ET.Comment(" roadsynth: one vType per background vehicle, parameters sampled per vehicle "))
    for row in vehicles.itertuples(index=False):
        vtype = ET.SubElement(root, "vType", _vtype(row))
        if row.imperfection > 0:
            # SUMO's driver-state device adds perception errors; awareness 1 is a perfect driver.
            ET.SubElement(vtype, "param", key="has.driverstate.device", value="true")
            ET.SubElement(vtype, "param", key="device.driverstate.initialAwareness", value=_g(1.0 - row.imperfection))
    entries = [(row.depart_s, 0, row.vehicle_id, row) for row in vehicles.itertuples(index=False)]
    entries += [(row.depart_s, 1, row.person_id, row) for row in persons.itertuples(index=False)]
    for depart, kind, ident, row in sorted(entries, key=lambda e: (e[0], e[1], e[2])):
        if kind == 0:
            veh = ET.SubElement(root, "vehicle", id=ident, type=f"t_{ident}", depart=f"{depart:.2f}",
                                departLane="best", departSpeed="max", departPos=depart_pos)
            ET.SubElement(veh, "route", edges=row.route)
            for lane, pos, dwell in bus_stops.get(ident, ()):
                ET.SubElement(veh, "stop", lane=lane, endPos=_g(pos), duration=_g(dwell), friendlyPos="true")
        elif row.stop_lane:  # stands at stop_pos_m on its first edge's sidewalk, then walks
            person = ET.SubElement(root, "person", id=ident, depart=f"{depart:.2f}", departPos=_g(row.stop_pos_m))
            ET.SubElement(person, "stop", lane=row.stop_lane, endPos=_g(row.stop_pos_m), duration=_g(row.stop_s))
            ET.SubElement(person, "walk", edges=row.route, speed=_g(row.speed_mps))
            if np.isfinite(row.stand_face_rad):  # where it stands and faces: its formation's place, or alone
                ET.SubElement(person, "param", key=FORMATION_PARAM, value=f"{_g(row.stand_dx_m)} {_g(row.stand_dy_m)} "
                                                                         f"{_g(row.stand_face_rad)}")
        else:
            person = ET.SubElement(root, "person", id=ident, depart=f"{depart:.2f}")
            ET.SubElement(person, "walk", edges=row.route, speed=_g(row.speed_mps))
    ET.indent(root)
    path.write_text('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n")
