"""Bus stops of a network, and the people who wait at them.

A bus stop belongs to the network, not to a run: :func:`choose_bus_stops` picks them from the network's sidewalk
lanes with a random stream of its own (BUS_STOPS_TAG, no run seed), so every seed of a scenario, and the driving
environment, has the same stops, as a city does. The simulate stage writes them to ``<sim>/roads/bus_stops.parquet``
beside the road geometry (:data:`BUS_STOPS_SCHEMA`); the demand puts people waiting at them
(:func:`waiting_people`, SUMO stops on the sidewalk like the other standing people); the render builds a shelter
behind the sidewalk at each (pipeline.world.furniture.bus_shelters). Conventions: SUMO's, positions in metres along
the sidewalk lane from its start; a person's place across the sidewalk is its offset right of the lane's centre
line (away from the road: a sidewalk is its edge's rightmost lane), the way it faces the angle from the lane's
direction towards its right (as pipeline.traffic.demand's standing people).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa

from pipeline.core.config.scenario import BusStopConfig, DemandConfig

BUS_STOPS_SCHEMA = pa.schema([
    ("stop_id", pa.string()), ("edge_id", pa.string()), ("lane_id", pa.string()),
    ("pos_m", pa.float64()), ("lane_length_m", pa.float64()), ("lane_width_m", pa.float64()),
])
BUS_STOPS_TAG = 43  # the stops' random stream (no run seed: the network's stops)
WAITING_TAG = 44  # the waiting people's random stream, with the run's seed (everyone else draws as before)
DWELL_TAG = 45  # the buses' dwell times at the stops, with the run's seed
MIN_STOP_FROM_START_M = 15.0  # a bus departing on a stop's edge stops there only this far into it
STOP_SPREAD_M = 10.0  # a stop lies within this of its sidewalk's middle
SHELTER_LENGTH_M = 4.0  # along the sidewalk (pipeline.world.furniture.bus_shelters)
# Where people wait: at places WAITING_SLOT_M apart along the stop's SHELTER_LENGTH_M + 1 m (a person's shoulders
# and personal space; Fruin's queue spacing is 0.5-0.9 m), jittered by up to WAITING_JITTER_M, most between the
# sidewalk's centre line and the shelter, some at the kerb looking out for the bus (WAITING_AT_KERB).
WAITING_SLOT_M = 0.8
WAITING_JITTER_M = 0.15
WAITING_AT_KERB = 0.3
WAITING_MARGIN_M = 0.35  # from the sidewalk's edges
# Which way a waiting person faces, from the sidewalk's direction towards its right (radians), and its share: the
# road, up the road where the bus comes from (against the lane's direction, turned towards the road), and along the
# sidewalk either way (on the phone, talking). Our estimate, no survey.
WAITING_FACING_RAD = (-0.5 * np.pi, -0.8 * np.pi, 0.0, np.pi)
WAITING_FACING_SHARES = (0.45, 0.35, 0.1, 0.1)
WAITING_TURN_RAD = np.pi / 12


def empty_bus_stops() -> pd.DataFrame:
    """A bus-stop table with no rows (a network without stops)."""
    return BUS_STOPS_SCHEMA.empty_table().to_pandas()


def choose_bus_stops(lanes: pd.DataFrame, config: BusStopConfig | None) -> pd.DataFrame:
    """The network's bus stops (:data:`BUS_STOPS_SCHEMA`, one row per stop in edge order): each edge's first
    sidewalk lane (its rightmost) at least ``config.min_sidewalk_m`` long holds one with probability
    ``config.share``, within STOP_SPREAD_M of its middle. ``lanes``: the road geometry's lane table
    (pipeline.traffic.roadgeometry). ``config`` None: no stops."""
    if config is None or config.share <= 0.0:
        return empty_bus_stops()
    walks = lanes[(lanes["kind"] == "sidewalk") & (lanes["function"] == "normal")]
    walks = walks.sort_values(["edge_id", "index"]).drop_duplicates("edge_id")  # an edge's first sidewalk
    walks = walks[walks["length_m"] >= config.min_sidewalk_m]
    rng = np.random.default_rng(BUS_STOPS_TAG)
    take = rng.random(len(walks)) < config.share
    shift = rng.uniform(-STOP_SPREAD_M, STOP_SPREAD_M, len(walks))
    walks, shift = walks[take], shift[take]
    pos = np.round(walks["length_m"].to_numpy() / 2.0 + shift, 2)
    return pd.DataFrame({"stop_id": [f"bus{i:03d}" for i in range(len(walks))], "edge_id": walks["edge_id"].to_numpy(),
                         "lane_id": walks["lane_id"].to_numpy(), "pos_m": pos,
                         "lane_length_m": walks["length_m"].to_numpy(), "lane_width_m": walks["width_m"].to_numpy()})


def bus_stop_lanes(lanes: pd.DataFrame, stops: pd.DataFrame) -> pd.DataFrame:
    """Where a bus stands at each stop: the rightmost lane of the stop's edge that buses may drive (kind
    "driving", the lowest index) and the stop's place on it (its share of the sidewalk's length, on that lane's
    length): one row per stop with edge_id, lane_id, pos_m. A stop whose edge has no such lane is left out."""
    driving = lanes[(lanes["kind"] == "driving") & (lanes["function"] == "normal")]
    driving = driving.sort_values(["edge_id", "index"]).drop_duplicates("edge_id").set_index("edge_id")
    rows = []
    for stop in stops.itertuples(index=False):
        if stop.edge_id in driving.index:
            lane = driving.loc[stop.edge_id]
            rows.append((stop.edge_id, lane["lane_id"], round(stop.pos_m / stop.lane_length_m * lane["length_m"], 2)))
    return pd.DataFrame(rows, columns=["edge_id", "lane_id", "pos_m"])


def bus_route_stops(route: str, stop_lanes: pd.DataFrame) -> list[tuple[str, float]]:
    """The stops (lane id, position) of a bus whose route is ``route`` (space-separated edge ids), in route order:
    each stop on one of its edges (:func:`bus_stop_lanes`), but one less than MIN_STOP_FROM_START_M into the bus's
    first edge (it departs at the edge's start)."""
    at = {edge: i for i, edge in enumerate(stop_lanes["edge_id"])}
    out = []
    for k, edge in enumerate(route.split()):
        i = at.get(edge)
        if i is not None and (k > 0 or stop_lanes["pos_m"].iat[i] >= MIN_STOP_FROM_START_M):
            out.append((str(stop_lanes["lane_id"].iat[i]), float(stop_lanes["pos_m"].iat[i])))
    return out


def waiting_people(stops: pd.DataFrame, config: DemandConfig, first_index: int, seed: int,
                   garments: np.ndarray, garment_shares: np.ndarray) -> pd.DataFrame:
    """The people waiting at ``stops`` when the run starts (``config.bus_stops`` says how many and how long): at
    each stop a number drawn from a Poisson distribution of mean ``waiting_mean`` (at most the stop's places), each
    at a place of its own along the stop (WAITING_SLOT_M apart), most between the sidewalk's centre and the shelter,
    a share WAITING_AT_KERB at the kerb, facing the road, up the road or along the sidewalk (WAITING_FACING_RAD).
    They depart at 0, stand ``waiting_s`` seconds, then walk on along their stop's edge at a pedestrian's speed.
    Columns as the demand's standing people: person_id (``ped{first_index:04d}`` on), depart_s, route, speed_mps,
    stop_lane, stop_pos_m, stop_s, stand_dx_m, stand_dy_m, stand_face_rad, and color_r/g/b, a row of ``garments``
    drawn with ``garment_shares``; every draw from a stream of their own (``seed``, WAITING_TAG)."""
    columns = ["person_id", "depart_s", "route", "speed_mps", "stop_lane", "stop_pos_m", "stop_s", "stand_dx_m",
               "stand_dy_m", "stand_face_rad", "color_r", "color_g", "color_b"]
    spec = config.bus_stops
    if spec is None or not len(stops):
        return pd.DataFrame({c: [] for c in columns})
    rng = np.random.default_rng([seed, WAITING_TAG])
    slots = np.arange(0.0, SHELTER_LENGTH_M + 1.0 + 1e-9, WAITING_SLOT_M)
    slots = slots - slots.mean()
    rows = []
    for stop in stops.itertuples(index=False):
        count = min(int(rng.poisson(spec.waiting_mean)), len(slots))
        places = np.sort(rng.choice(slots, count, replace=False)) + rng.uniform(-WAITING_JITTER_M, WAITING_JITTER_M,
                                                                                 count)
        pos = np.clip(stop.pos_m + places, 0.5, stop.lane_length_m - 0.5)
        half = max(stop.lane_width_m / 2 - WAITING_MARGIN_M, 0.0)
        kerb = rng.random(count) < WAITING_AT_KERB
        across = np.where(kerb, -half, rng.uniform(0.0, half, count))
        facing = np.asarray(WAITING_FACING_RAD)[rng.choice(len(WAITING_FACING_RAD), count, p=WAITING_FACING_SHARES)]
        facing = facing + rng.uniform(-WAITING_TURN_RAD, WAITING_TURN_RAD, count)
        wait = spec.waiting_s.sample(rng, count)
        speed = config.pedestrian_speed_mps.sample(rng, count)
        colour = garments[rng.choice(len(garments), count, p=garment_shares)]
        for j in range(count):
            rows.append({"person_id": f"ped{first_index + len(rows):04d}", "depart_s": 0.0, "route": stop.edge_id,
                         "speed_mps": float(speed[j]), "stop_lane": stop.lane_id,
                         "stop_pos_m": round(float(pos[j]), 2), "stop_s": round(float(wait[j]), 1),
                         "stand_dx_m": 0.0, "stand_dy_m": round(float(across[j]), 3),
                         "stand_face_rad": round(float(facing[j]), 4), "color_r": int(colour[j, 0]),
                         "color_g": int(colour[j, 1]), "color_b": int(colour[j, 2])})
    return pd.DataFrame(rows, columns=columns)
