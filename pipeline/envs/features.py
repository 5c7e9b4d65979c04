"""Feature observations: the ego's lane-frame state and its six SUMO-Gym neighbour slots.

Conventions: SUMO gives a vehicle's front-bumper position and its angle in degrees clockwise from north;
centres are front - length/2 x heading (DESIGN.md). s runs along the road, d to the left. The six slots are
road-aligned through SUMO's lane model (gaps along the lanes, lane indices and lateral offsets). The "nearby"
rows are centre-to-centre offsets in the ego's local lane frame (x along the lane direction at the ego):
exact on straight roads; on a curve of radius R the error in d is about ds^2 / 2R.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from pipeline.core.classes import ObjectClass

EGO_FIELDS = ("speed_mps", "accel_mps2", "lane_index", "lateral_offset_m", "heading_rel_rad", "route_left_m")
NEIGHBOUR_SLOTS = ("left_leader", "leader", "right_leader", "left_follower", "follower", "right_follower")
NEIGHBOUR_FIELDS = ("present", "ds_m", "dd_m", "dv_mps", "length_m", "width_m")
NEARBY_FIELDS = ("present", "ds_m", "dd_m", "dv_mps", "length_m", "width_m", "heading_rel_rad", "class_index")
SIGNAL_FIELDS = ("present", "distance_m", "state")
# A signal's state: what its light for the ego's lane says (SUMO's link state letters).
SIGNAL_GO, SIGNAL_AMBER, SIGNAL_STOP = 0, 1, 2
_SIGNAL_STATE = {**dict.fromkeys("GgOo", SIGNAL_GO), **dict.fromkeys("yYu", SIGNAL_AMBER),
                 **dict.fromkeys("rRs", SIGNAL_STOP)}
# class_index of a nearby vehicle: 1 + its position here (0 only in absent rows).
CLASS_ORDER = tuple(c for c in ObjectClass if c not in (ObjectClass.PEDESTRIAN, ObjectClass.STROLLER))
# traci.constants, spelled out: the ego's context subscription of the vehicles around it.
# The neighbour slots read their vehicles' values from it too (one call a step instead of ~8 per neighbour).
CMD_GET_VEHICLE_VARIABLE, VAR_POSITION, VAR_ANGLE, VAR_SPEED, VAR_LENGTH, VAR_WIDTH = 0xA4, 0x42, 0x43, 0x40, 0x44, 0x4D
VAR_ROAD_ID, VAR_LANE_INDEX, VAR_MINGAP, VAR_LANEPOSITION_LAT = 0x50, 0x52, 0x4C, 0xB8
CONTEXT_VARS = (VAR_POSITION, VAR_ANGLE, VAR_SPEED, VAR_LENGTH, VAR_WIDTH, VAR_ROAD_ID, VAR_LANE_INDEX, VAR_MINGAP,
                VAR_LANEPOSITION_LAT)
# getNeighbors mode bits (traci's getLeftLeaders etc.): 1 = right (else left), 2 = leaders (else followers).
_NEIGHBOUR_MODE = {"left_leader": 2, "right_leader": 3, "left_follower": 0, "right_follower": 1}
MAX_LANES = 16
MAX_ROUTE_M = 1.0e5
MAX_LATERAL_M = 20.0
MAX_SIZE_M = 30.0


def observation_space(max_speed_mps: float, accel_min_mps2: float, accel_max_mps2: float,
                      range_m: float, nearby_k: int) -> spaces.Dict:
    """The Dict space: "ego" (6,) float32 in EGO_FIELDS order, "neighbours" (6, 6) float32 (NEIGHBOUR_SLOTS x
    NEIGHBOUR_FIELDS), "signal" (3,) float32 (SIGNAL_FIELDS: the next traffic signal on the ego's way within
    ``range_m``) and, if ``nearby_k`` > 0, "nearby" (nearby_k, 8) float32 (the nearest vehicles, nearest first, x
    NEARBY_FIELDS); an absent row is all zeros (``present`` is the mask)."""
    ego_low = np.array([0.0, accel_min_mps2, 0.0, -MAX_LATERAL_M, -math.pi, 0.0], dtype=np.float32)
    ego_high = np.array([max_speed_mps, accel_max_mps2, MAX_LANES - 1, MAX_LATERAL_M, math.pi, MAX_ROUTE_M],
                        dtype=np.float32)
    row_low = np.array([0.0, -range_m, -MAX_LATERAL_M, -2 * max_speed_mps, 0.0, 0.0], dtype=np.float32)
    row_high = np.array([1.0, range_m, MAX_LATERAL_M, 2 * max_speed_mps, MAX_SIZE_M, MAX_SIZE_M], dtype=np.float32)
    n = len(NEIGHBOUR_SLOTS)
    boxes = {
        "ego": spaces.Box(ego_low, ego_high, dtype=np.float32),
        "neighbours": spaces.Box(np.tile(row_low, (n, 1)), np.tile(row_high, (n, 1)), dtype=np.float32),
        "signal": spaces.Box(np.zeros(3, np.float32), np.array([1.0, range_m, SIGNAL_STOP], np.float32),
                             dtype=np.float32),
    }
    if nearby_k > 0:
        near_low = np.append(row_low, [-math.pi, 0.0]).astype(np.float32)
        near_high = np.append(row_high, [math.pi, len(CLASS_ORDER)]).astype(np.float32)
        boxes["nearby"] = spaces.Box(np.tile(near_low, (nearby_k, 1)), np.tile(near_high, (nearby_k, 1)),
                                     dtype=np.float32)
    return spaces.Dict(boxes)


def yaw_from_sumo_angle(angle_deg: float) -> float:
    """yaw (rad, CCW from +x) of a SUMO angle (deg, clockwise from north)."""
    return math.radians(90.0 - angle_deg)


def centre_xy(sumo, vid: str) -> tuple[float, float, float]:
    """(x, y, yaw_rad) of a vehicle's box centre."""
    x, y = sumo.vehicle.getPosition(vid)
    yaw = yaw_from_sumo_angle(sumo.vehicle.getAngle(vid))
    half = 0.5 * sumo.vehicle.getLength(vid)
    return x - half * math.cos(yaw), y - half * math.sin(yaw), yaw


def neighbour_ids(sumo, ego: str, range_m: float) -> dict[str, tuple[str, float]]:
    """The nearest vehicle of each slot that has one: slot -> (id, SUMO's gap), as SUMO's lane model sees them.

    The gap follows getLeader / getFollower: for leaders from the ego's front + its minGap to the leader's back,
    for followers from the follower's front + its minGap to the ego's back."""
    found: dict[str, tuple[str, float]] = {}
    leader = sumo.vehicle.getLeader(ego, range_m)
    if leader and leader[0]:
        found["leader"] = leader
    follower = sumo.vehicle.getFollower(ego, range_m)
    if follower and follower[0]:
        found["follower"] = follower
    for slot, mode in _NEIGHBOUR_MODE.items():
        near = sumo.vehicle.getNeighbors(ego, mode)
        if near:
            found[slot] = min(near, key=lambda pair: (pair[1], pair[0]))
    return found


def _values(sumo, vid: str, context: dict[str, dict[int, object]]) -> dict[int, object]:
    """CONTEXT_VARS of a vehicle: from the ego's context subscription, or asked for (outside its radius)."""
    if vid in context:
        return context[vid]
    v = sumo.vehicle
    return {VAR_ANGLE: v.getAngle(vid), VAR_SPEED: v.getSpeed(vid), VAR_LENGTH: v.getLength(vid),
            VAR_WIDTH: v.getWidth(vid), VAR_ROAD_ID: v.getRoadID(vid), VAR_LANE_INDEX: v.getLaneIndex(vid),
            VAR_MINGAP: v.getMinGap(vid), VAR_LANEPOSITION_LAT: v.getLateralLanePosition(vid)}


def neighbour_rows(sumo, ego: str, ego_speed_mps: float, lane_yaw: float, range_m: float,
                   context: dict[str, dict[int, object]], space: spaces.Box) -> np.ndarray:
    """(6, 6) float32 rows in NEIGHBOUR_SLOTS order, clipped to ``space``; neighbours beyond ``range_m`` are absent.
    ``context``: the ego's context subscription results (CONTEXT_VARS, the ego included).

    Road-aligned: ds (centre to centre) from SUMO's gap along the lanes plus the minGap and half of both lengths;
    dd from lane indices (on the ego's edge; else the slot's side) x lane width plus both lateral offsets.
    """
    rows = np.zeros((len(NEIGHBOUR_SLOTS), len(NEIGHBOUR_FIELDS)), dtype=np.float64)
    me = _values(sumo, ego, context)
    width = sumo.lane.getWidth(sumo.vehicle.getLaneID(ego))
    for slot, (vid, gap) in neighbour_ids(sumo, ego, range_m).items():
        it = _values(sumo, vid, context)
        length = it[VAR_LENGTH]
        if slot.endswith("leader"):
            ds = gap + me[VAR_MINGAP] + 0.5 * (me[VAR_LENGTH] + length)
        else:
            ds = -(gap + it[VAR_MINGAP] + 0.5 * (me[VAR_LENGTH] + length))
        if abs(ds) > range_m:
            continue
        side = 1 if slot.startswith("left") else -1 if slot.startswith("right") else 0
        lanes = it[VAR_LANE_INDEX] - me[VAR_LANE_INDEX] if it[VAR_ROAD_ID] == me[VAR_ROAD_ID] else side
        dd = lanes * width + it[VAR_LANEPOSITION_LAT] - me[VAR_LANEPOSITION_LAT]
        dv = it[VAR_SPEED] * math.cos(yaw_from_sumo_angle(it[VAR_ANGLE]) - lane_yaw) - ego_speed_mps
        rows[NEIGHBOUR_SLOTS.index(slot)] = (1.0, ds, dd, dv, length, it[VAR_WIDTH])
    return np.clip(rows, space.low, space.high).astype(np.float32)


def nearby_rows(results: dict[str, dict[int, object]], ego: str, ego_xy: tuple[float, float], lane_yaw: float,
                ego_speed_mps: float, classes: dict[str, int], space: spaces.Box) -> np.ndarray:
    """(K, 8) float32 rows (NEARBY_FIELDS) of the K nearest vehicles (by centre distance, ties by id) among the
    ego's context-subscription ``results``, in the ego's lane frame, clipped to ``space``; the rest absent.
    ``classes``: vehicle id -> class_index."""
    k = space.shape[0]
    rows = np.zeros(space.shape, dtype=np.float64)
    ids = sorted(v for v in results if v != ego)
    if ids:
        values = np.array([(*results[v][VAR_POSITION], results[v][VAR_ANGLE], results[v][VAR_SPEED],
                            results[v][VAR_LENGTH], results[v][VAR_WIDTH]) for v in ids])
        yaw = np.radians(90.0 - values[:, 2])
        x = values[:, 0] - 0.5 * values[:, 4] * np.cos(yaw)
        y = values[:, 1] - 0.5 * values[:, 4] * np.sin(yaw)
        dx, dy = x - ego_xy[0], y - ego_xy[1]
        c, s = math.cos(lane_yaw), math.sin(lane_yaw)
        order = np.argsort(np.hypot(dx, dy), kind="stable")[:k]
        rel = (yaw[order] - lane_yaw + math.pi) % (2 * math.pi) - math.pi
        rows[: len(order)] = np.column_stack([
            np.ones(len(order)), dx[order] * c + dy[order] * s, -dx[order] * s + dy[order] * c,
            values[order, 3] * np.cos(yaw[order] - lane_yaw) - ego_speed_mps, values[order, 4], values[order, 5],
            rel, [classes.get(ids[i], 0) for i in order]])
    return np.clip(rows, space.low, space.high).astype(np.float32)


def signal_row(next_signals: list[tuple], range_m: float) -> np.ndarray:
    """The "signal" row (SIGNAL_FIELDS) from SUMO's ``vehicle.getNextTLS`` of the ego (its route's coming signals,
    nearest first: (tls id, link index, distance from the front bumper to the stop line, link state letter)): the
    nearest within ``range_m``, its distance and its state for the ego's lane (SIGNAL_GO: green, also a minor green
    or a signal switched off; SIGNAL_AMBER: yellow or red-yellow; SIGNAL_STOP: red, or a stop-then-go arrow); all
    zeros when none lies within range."""
    row = np.zeros(len(SIGNAL_FIELDS), np.float32)
    for _tls, _link, distance, state in next_signals:
        if 0.0 <= distance <= range_m:
            if state not in _SIGNAL_STATE:
                raise ValueError(f"traffic signal {_tls!r}: link state {state!r} is not one of SUMO's letters "
                                 f"({''.join(sorted(_SIGNAL_STATE))})")
            row[:] = 1.0, distance, _SIGNAL_STATE[state]
            break
    return row
