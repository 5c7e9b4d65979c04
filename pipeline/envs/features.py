"""Feature observations: the ego's lane-frame state and its six SUMO-Gym neighbour slots.

Conventions: SUMO gives a vehicle's front-bumper position and its angle in degrees clockwise from north;
centres are front - length/2 x heading (DESIGN.md). The lane frame at the ego: s along the ego's lane
direction, d to its left. Neighbour rows are centre-to-centre offsets in that frame, so "road-aligned"
holds locally (on a curve of radius R the error in d is about ds^2 / 2R).
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

EGO_FIELDS = ("speed_mps", "accel_mps2", "lane_index", "lateral_offset_m", "heading_rel_rad", "route_left_m")
NEIGHBOUR_SLOTS = ("left_leader", "leader", "right_leader", "left_follower", "follower", "right_follower")
NEIGHBOUR_FIELDS = ("present", "ds_m", "dd_m", "dv_mps", "length_m", "width_m")
# getNeighbors mode bits: 1 = left (else right), 2 = leaders (else followers).
_NEIGHBOUR_MODE = {"left_leader": 3, "right_leader": 2, "left_follower": 1, "right_follower": 0}
MAX_LANES = 16
MAX_ROUTE_M = 1.0e5
MAX_LATERAL_M = 20.0
MAX_SIZE_M = 30.0


def observation_space(max_speed_mps: float, accel_min_mps2: float, accel_max_mps2: float,
                      range_m: float) -> spaces.Dict:
    """The Dict space: "ego" (6,) float32 in EGO_FIELDS order, "neighbours" (6, 6) float32 (NEIGHBOUR_SLOTS x
    NEIGHBOUR_FIELDS); an absent neighbour's row is all zeros (``present`` is the mask)."""
    ego_low = np.array([0.0, accel_min_mps2, 0.0, -MAX_LATERAL_M, -math.pi, 0.0], dtype=np.float32)
    ego_high = np.array([max_speed_mps, accel_max_mps2, MAX_LANES - 1, MAX_LATERAL_M, math.pi, MAX_ROUTE_M],
                        dtype=np.float32)
    row_low = np.array([0.0, -range_m, -MAX_LATERAL_M, -2 * max_speed_mps, 0.0, 0.0], dtype=np.float32)
    row_high = np.array([1.0, range_m, MAX_LATERAL_M, 2 * max_speed_mps, MAX_SIZE_M, MAX_SIZE_M], dtype=np.float32)
    n = len(NEIGHBOUR_SLOTS)
    return spaces.Dict({
        "ego": spaces.Box(ego_low, ego_high, dtype=np.float32),
        "neighbours": spaces.Box(np.tile(row_low, (n, 1)), np.tile(row_high, (n, 1)), dtype=np.float32),
    })


def yaw_from_sumo_angle(angle_deg: float) -> float:
    """yaw (rad, CCW from +x) of a SUMO angle (deg, clockwise from north)."""
    return math.radians(90.0 - angle_deg)


def centre_xy(sumo, vid: str) -> tuple[float, float, float]:
    """(x, y, yaw_rad) of a vehicle's box centre."""
    x, y = sumo.vehicle.getPosition(vid)
    yaw = yaw_from_sumo_angle(sumo.vehicle.getAngle(vid))
    half = 0.5 * sumo.vehicle.getLength(vid)
    return x - half * math.cos(yaw), y - half * math.sin(yaw), yaw


def neighbour_ids(sumo, ego: str, range_m: float) -> dict[str, str]:
    """The nearest vehicle of each slot that has one (slot -> id), as SUMO's lane model sees them."""
    found: dict[str, str] = {}
    leader = sumo.vehicle.getLeader(ego, range_m)
    if leader and leader[0]:
        found["leader"] = leader[0]
    follower = sumo.vehicle.getFollower(ego, range_m)
    if follower and follower[0]:
        found["follower"] = follower[0]
    for slot, mode in _NEIGHBOUR_MODE.items():
        near = sumo.vehicle.getNeighbors(ego, mode)
        if near:
            found[slot] = min(near, key=lambda pair: (pair[1], pair[0]))[0]
    return found


def neighbour_rows(sumo, ego: str, ego_xy: tuple[float, float], lane_yaw: float, ego_speed_mps: float,
                   range_m: float, space: spaces.Box) -> np.ndarray:
    """(6, 6) float32 rows in NEIGHBOUR_SLOTS order, clipped to ``space``; neighbours beyond ``range_m`` are absent."""
    rows = np.zeros((len(NEIGHBOUR_SLOTS), len(NEIGHBOUR_FIELDS)), dtype=np.float64)
    c, s = math.cos(lane_yaw), math.sin(lane_yaw)
    for slot, vid in neighbour_ids(sumo, ego, range_m).items():
        x, y, yaw = centre_xy(sumo, vid)
        dx, dy = x - ego_xy[0], y - ego_xy[1]
        ds, dd = dx * c + dy * s, -dx * s + dy * c
        if abs(ds) > range_m:
            continue
        dv = sumo.vehicle.getSpeed(vid) * math.cos(yaw - lane_yaw) - ego_speed_mps
        rows[NEIGHBOUR_SLOTS.index(slot)] = (1.0, ds, dd, dv, sumo.vehicle.getLength(vid), sumo.vehicle.getWidth(vid))
    return np.clip(rows, space.low, space.high).astype(np.float32)
