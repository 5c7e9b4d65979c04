"""Feature observations: the ego's lane-frame state, its six SUMO-Gym neighbour slots, the next traffic signal and
the nearest person in its path.

Conventions: SUMO gives a vehicle's front-bumper position and its angle in degrees clockwise from north;
centres are front - length/2 x heading (DESIGN.md). s runs along the road, d to the left. The six slots are
road-aligned through SUMO's lane model (gaps along the lanes, lane indices and lateral offsets). The "nearby"
rows are centre-to-centre offsets in the ego's local lane frame (x along the lane direction at the ego):
exact on straight roads; on a curve of radius R the error in d is about ds^2 / 2R.

The ego's *path* is the centre line of the lanes its route takes from its front bumper on (its lane, then each
junction's internal lane and the next lane, as SUMO's ``vehicle.getNextLinks`` lists them), map knowledge as the
route rule's; the "path" row holds the nearest person who is in it, or walks into it before the ego gets there
(:func:`path_row`): on a pedestrian crossing, or on the road. The lane-based slots hold vehicles only, so without
it a driver on features could not see a person crossing its way (docs/closedloop.md).
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from pipeline.core.classes import ObjectClass
from pipeline.world.polygons import cumulative_length, interpolate

EGO_FIELDS = ("speed_mps", "accel_mps2", "lane_index", "lateral_offset_m", "heading_rel_rad", "route_left_m")
NEIGHBOUR_SLOTS = ("left_leader", "leader", "right_leader", "left_follower", "follower", "right_follower")
NEIGHBOUR_FIELDS = ("present", "ds_m", "dd_m", "dv_mps", "length_m", "width_m")
NEARBY_FIELDS = ("present", "ds_m", "dd_m", "dv_mps", "length_m", "width_m", "heading_rel_rad", "class_index")
SIGNAL_FIELDS = ("present", "distance_m", "state")
PATH_FIELDS = ("present", "distance_m", "lateral_m")
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
# The ego's context subscription of the persons around it (the "path" row). SUMO merges the results of both
# subscriptions into one dict by object id; a person's entry is the one with VAR_VEHICLE (the vehicle it rides in,
# "" on foot), which CONTEXT_VARS does not ask for.
CMD_GET_PERSON_VARIABLE, VAR_VEHICLE, VAR_LANE_ID = 0xAE, 0xC3, 0x51
PERSON_CONTEXT_VARS = (VAR_POSITION, VAR_ANGLE, VAR_SPEED, VAR_VEHICLE, VAR_LANE_ID, VAR_ROAD_ID)
PERSON_RADIUS_M = 0.3  # a person's reach around their position, for the path's width and the distance to them
PATH_HORIZON_S = 3.0  # a person counts who walks into the path within this time, or before the ego gets there
_WALK_STEPS = np.linspace(0.0, 1.0, 7)  # where along that time a walking person's place is tested
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
    ``range_m``), "path" (3,) float32 (PATH_FIELDS: the nearest person in the ego's path within ``range_m``,
    :func:`path_row`) and, if ``nearby_k`` > 0, "nearby" (nearby_k, 8) float32 (the nearest vehicles, nearest first, x
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
        "path": spaces.Box(np.array([0.0, 0.0, -MAX_LATERAL_M], np.float32),
                           np.array([1.0, range_m, MAX_LATERAL_M], np.float32), dtype=np.float32),
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


def path_polyline(start_xy: tuple[float, float], shapes: list[np.ndarray], range_m: float) -> np.ndarray:
    """(N, 2) float64 vertices of the ego's path: ``start_xy`` (its front bumper) and then the lane centre lines
    ``shapes`` in driving order ((K, 2) each; the first cut at the point nearest the start, so it begins where the
    ego is), until ``range_m`` of path; a gap between two shapes (a junction's internal lanes SUMO does not list) is
    crossed in a straight line."""
    start = np.asarray(start_xy, np.float64).reshape(1, 2)
    pieces = [start]
    for k, shape in enumerate(shapes):
        shape = np.asarray(shape, np.float64).reshape(-1, 2)
        if k == 0 and len(shape) >= 2:
            shape = shape[int(project_on_path(shape, start)[3][0]) + 1:]
        pieces.append(shape)
    points = np.concatenate(pieces)
    points = points[np.concatenate([[True], np.hypot(*np.diff(points, axis=0).T) >= 1e-6])]
    arc = cumulative_length(points)
    if len(points) < 2 or arc[-1] < range_m:
        return points
    end, _direction = interpolate(points, np.array([range_m]))
    return np.concatenate([points[arc < range_m], end])


def project_on_path(path_xy: np.ndarray, points_xy: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each of the (M, 2) points on the (N, 2) polyline, N >= 2: (s along it from its start, d its signed distance,
    left positive, whether its nearest point lies within the path (not at its start or end vertex, from behind or
    beyond), the index of the nearest segment), nearest segment first by distance, then by order."""
    path_xy = np.asarray(path_xy, np.float64)
    points_xy = np.asarray(points_xy, np.float64).reshape(-1, 2)
    a, b = path_xy[:-1], path_xy[1:]
    ab = b - a
    seg_len = np.hypot(ab[:, 0], ab[:, 1])
    start_s = np.concatenate([[0.0], np.cumsum(seg_len)[:-1]])
    ap = points_xy[:, None, :] - a[None, :, :]
    t = np.clip((ap * ab[None]).sum(axis=2) / np.maximum(seg_len, 1e-12)[None] ** 2, 0.0, 1.0)
    near = a[None] + t[..., None] * ab[None]
    dist = np.hypot(points_xy[:, None, 0] - near[..., 0], points_xy[:, None, 1] - near[..., 1])
    seg = np.argmin(dist, axis=1)
    rows = np.arange(len(points_xy))
    tt = t[rows, seg]
    cross = ab[seg, 0] * ap[rows, seg, 1] - ab[seg, 1] * ap[rows, seg, 0]
    d = np.copysign(dist[rows, seg], cross)
    s = start_s[seg] + tt * seg_len[seg]
    inside = ~(((seg == 0) & (tt <= 0.0)) | ((seg == len(ab) - 1) & (tt >= 1.0)))
    return s, d, inside, seg


def is_crossing(road: str) -> bool:
    """Whether a SUMO edge or lane id is a pedestrian crossing's (netconvert names them ":JUNCTION_cN", their lanes
    ":JUNCTION_cN_0"; walking areas ":JUNCTION_wN")."""
    if not road.startswith(":"):
        return False
    parts = road.split("_")
    return any(p[:1] == "c" and p[1:].isdigit() for p in parts[-2:]) and len(parts) >= 2


def path_row(path_xy: np.ndarray, people_xy: np.ndarray, people_velocity: np.ndarray, ego_speed_mps: float,
             half_width_m: float, horizon_s: float = PATH_HORIZON_S, radius_m: float = PERSON_RADIUS_M,
             on_road: np.ndarray | None = None) -> np.ndarray:
    """The "path" row (PATH_FIELDS): the nearest of the (M, 2) people (world positions, velocities in m/s) who is in
    the ego's path (:func:`path_polyline`), or walks into it, straight on at their velocity, before the ego gets to
    them at its speed (at least 1 m/s) or within ``horizon_s``, whichever is first: within ``half_width_m`` (half the
    ego's width) + ``radius_m`` of the path's centre line, at some place along it between the front bumper and its
    end. ``on_road`` (M,) bool: whether each stands on the carriageway or a crossing now (None: all do); one who
    does not (on a sidewalk or a junction's walking area, which a turning lane's centre line may pass within a metre
    of) counts only once walking into the path, not for standing where they are. distance_m: along the path from
    the front bumper to the person's reach (their place along it, less ``radius_m``, at least 0) where they first
    enter it; lateral_m: their offset from the centre line then. All zeros when nobody is (a path shorter than 2
    vertices holds nobody)."""
    row = np.zeros(len(PATH_FIELDS), np.float32)
    people_xy = np.asarray(people_xy, np.float64).reshape(-1, 2)
    if len(people_xy) == 0 or len(path_xy) < 2:
        return row
    velocity = np.asarray(people_velocity, np.float64).reshape(-1, 2)
    s_now, d_now, _inside, _seg = project_on_path(path_xy, people_xy)
    until = np.minimum(horizon_s, np.maximum(s_now, 0.0) / max(ego_speed_mps, 1.0))
    # Only those who can reach the corridor in that time are followed along their walk (most people are far off).
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    near = np.flatnonzero(np.abs(d_now) < half_width_m + radius_m + speed * until + 1e-9)
    if len(near) == 0:
        return row
    people_xy, velocity, until, speed = people_xy[near], velocity[near], until[near], speed[near]
    samples = people_xy[:, None, :] + (until[:, None] * _WALK_STEPS[None, :])[..., None] * velocity[:, None, :]
    s, d, inside = (v.reshape(len(near), len(_WALK_STEPS))
                    for v in project_on_path(path_xy, samples.reshape(-1, 2))[:3])
    hit = inside & (np.abs(d) < half_width_m + radius_m) & (s > 0.0)
    if on_road is not None:
        hit[:, 0] &= np.asarray(on_road, bool).reshape(-1)[near]
        hit[:, 1:] &= speed[:, None] > 0.0
    entered = hit.any(axis=1)
    if not entered.any():
        return row
    first = np.argmax(hit, axis=1)  # the first sample in the path, per person
    idx = np.flatnonzero(entered)
    distance = np.maximum(s[idx, first[idx]] - radius_m, 0.0)
    k = int(np.argmin(distance))  # ties: the first listed (callers list people by id)
    row[:] = 1.0, distance[k], d[idx[k], first[idx[k]]]
    return row
