"""Parked vehicles along the kerb: static actors in the network's parking lanes.

A parking lane (``urban.parking_lane_width_m``; see pipeline/traffic/networks.py) is the rightmost lane of an
edge, of lane type ``parking``, that no class may drive on, between the sidewalk and the moving traffic. Its
vehicles are placed here, not by SUMO: SUMO draws a parked vehicle beside lane 0 (here the sidewalk) or
beside the lane of its parking area, and a parked vehicle in a lane closed to moving traffic changes nothing
in the simulation, so placing them ourselves gives the same traffic and exact, reproducible boxes. They are
written to ``parked.parquet`` (one row per vehicle) and, with ``parked`` true and speed 0, into every frame
of ``trajectories.parquet``, so the renderer draws and labels them like any actor.

Placement (:class:`~pipeline.core.config.scenario.ParkedConfig`): slots run along each parking lane's centre
line from ``end_clearance_m`` after its start, each a vehicle length plus a drawn gap; a slot that would end
within ``end_clearance_m`` of the lane's end is not used, so no vehicle stands on a junction or crossing
(which lie beyond the lane ends). Vehicles of one lane never overlap (slots are disjoint along the line), and a
vehicle lies inside its lane's width (its right side ``kerb_gap_m`` from the kerb edge, its left side inside
the lane), so it never reaches a driving lane. Every draw comes from one generator derived from the seed,
lanes taken in id order. No vehicle parks within BUS_STOP_CLEAR_M before or after a bus stop (its edge's parking
lane, at the stop's place along its sidewalk; pipeline.traffic.busstops): the slots there stay empty, their draws
made all the same, so that every other parked vehicle is the one it would be without the stop.
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.core.classes import ObjectClass
from pipeline.core.config import DemandConfig
from pipeline.traffic.networks import PARKING_LANE_TYPE

log = logging.getLogger(__name__)

PARKED_FILE = "parked.parquet"
# No parking within this of a bus stop, before and after it: Germany's StVO section 12 (3) 4 forbids parking within
# 15 m in front of and behind a bus stop's sign (other countries mark clearways of 20-40 m in all).
BUS_STOP_CLEAR_M = 15.0


class ParkingError(ValueError):
    """Parked vehicles were asked for where the network has no parking lane."""


def parking_lanes(net_file: Path) -> list[tuple[str, float, np.ndarray]]:
    """Parking lanes of normal edges, sorted by id: (lane id, width m, centre line (n, 3) float64)."""
    lanes = []
    for edge in ET.parse(net_file).getroot().iter("edge"):
        if edge.get("function"):
            continue
        for lane in edge.iter("lane"):
            if lane.get("type") == PARKING_LANE_TYPE:
                pts = [tuple(float(c) for c in p.split(",")) for p in lane.get("shape").split()]
                xyz = np.array([(*p, 0.0)[:3] for p in pts], dtype=np.float64)
                lanes.append((lane.get("id"), float(lane.get("width", "3.2")), xyz))
    return sorted(lanes, key=lambda lane: lane[0])


def _at(line: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray]:
    """Point (3,) and unit 2D tangent (2,) at arc length ``s`` (2D) along a polyline (n, 3)."""
    seg = np.diff(line[:, :2], axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.r_[0.0, np.cumsum(seg_len)]
    i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
    t = (s - cum[i]) / seg_len[i] if seg_len[i] > 0 else 0.0
    return line[i] + t * (line[i + 1] - line[i]), seg[i] / max(seg_len[i], 1e-12)


def place_parked(config: DemandConfig, net_file: Path, seed: int, bus_stops: pd.DataFrame | None = None
                 ) -> pd.DataFrame:
    """One row per parked vehicle: actor_id (``park0000``...), cls, lane_id, x_m, y_m, z_m (box centre),
    yaw_rad, length_m, width_m, height_m, color_r/g/b (uint8). Empty when ``config.parked`` is None. ``bus_stops``:
    the network's stops (:data:`pipeline.traffic.busstops.BUS_STOPS_SCHEMA`), kept clear of parked vehicles."""
    columns = ["actor_id", "cls", "lane_id", "x_m", "y_m", "z_m", "yaw_rad", "length_m", "width_m", "height_m",
               "color_r", "color_g", "color_b"]
    parked = config.parked
    if parked is None:
        return pd.DataFrame({c: pd.Series(dtype=str if c in ("actor_id", "cls", "lane_id") else
                                          np.uint8 if c.startswith("color_") else np.float64) for c in columns})
    lanes = parking_lanes(net_file)
    if not lanes:
        raise ParkingError(f"{net_file}: demand.parked is set but the network has no parking lane "
                           "(set network.urban.parking_lane_width_m)")
    rng = np.random.default_rng([seed, 0x9A2C])
    classes = sorted(parked.classes, key=lambda c: c.value)
    shares = np.array([parked.classes[c] for c in classes], dtype=np.float64)
    rows = []
    stops = {} if bus_stops is None else {
        edge: group["pos_m"].to_numpy() / group["lane_length_m"].to_numpy() for edge, group in bus_stops.groupby(
            "edge_id")}  # each stop's place as a share of its edge's length
    for lane_id, lane_w, line in lanes:
        length = float(np.hypot(*np.diff(line[:, :2], axis=0).T).sum())
        clear = stops.get(lane_id.rsplit("_", 1)[0], np.zeros(0)) * length
        s = parked.end_clearance_m
        while True:
            cls: ObjectClass = classes[int(rng.choice(len(classes), p=shares / shares.sum()))]
            spec = config.classes[cls]
            size = [float(np.round(getattr(spec, f).sample(rng, 1)[0], 4)) for f in ("length_m", "width_m", "height_m")]
            color = spec.colors[int(spec.color_index(rng))]
            gap, kerb_gap = float(parked.gap_m.sample(rng, 1)[0]), float(parked.kerb_gap_m.sample(rng, 1)[0])
            taken = bool(rng.random() < parked.occupancy)
            if s + size[0] > length - parked.end_clearance_m:
                break
            if taken and not np.any((s < clear + BUS_STOP_CLEAR_M) & (s + size[0] > clear - BUS_STOP_CLEAR_M)):
                centre, tangent = _at(line, s + size[0] / 2)
                # Right of travel is the kerb; keep the whole body inside the lane.
                offset = max(lane_w / 2 - size[1] / 2 - kerb_gap, 0.0)
                if size[1] > lane_w:
                    raise ParkingError(f"{lane_id}: a parked {cls.value} {size[1]:.2f} m wide does not fit the "
                                       f"{lane_w:.2f} m parking lane")
                xy = centre[:2] + offset * np.array([tangent[1], -tangent[0]])
                rows.append((f"park{len(rows):04d}", cls.value, lane_id, xy[0], xy[1], centre[2] + size[2] / 2,
                             float(np.arctan2(tangent[1], tangent[0])), *size, *color))
            s += size[0] + gap
    table = pd.DataFrame(rows, columns=columns)
    table = table.astype({c: np.uint8 for c in ("color_r", "color_g", "color_b")})
    log.info("parked %d vehicles in %d parking lanes (%.0f m of kerb)", len(table), len(lanes),
             sum(float(np.hypot(*np.diff(line[:, :2], axis=0).T).sum()) for _, _, line in lanes))
    return table


def parked_rows(parked: pd.DataFrame, frames: pd.DataFrame, first_track_id: int) -> pd.DataFrame:
    """The parked vehicles as trajectory rows in every frame of ``frames`` (columns frame, time_s), with track
    ids from ``first_track_id`` on, speed 0 and ``parked`` true (other trajectory columns as in
    :func:`pipeline.traffic.simulation.to_trajectories`)."""
    n, f = len(parked), len(frames)
    static = parked.assign(track_id=np.arange(first_track_id, first_track_id + n, dtype=np.int32))
    rep = static.loc[np.tile(np.arange(n), f)].reset_index(drop=True)
    rep.insert(0, "frame", np.repeat(frames["frame"].to_numpy(), n).astype(np.int32))
    rep.insert(1, "time_s", np.repeat(frames["time_s"].to_numpy(), n))
    return rep.assign(is_ego=False, speed_mps=0.0, accel_mps2=0.0, signals=np.int32(0), braking=False, parked=True)


def with_parked(traj: pd.DataFrame, parked: pd.DataFrame, first_track_id: int) -> pd.DataFrame:
    """The trajectories with a ``parked`` column and the parked vehicles' rows in every frame, sorted by
    (frame, track_id); parked track ids follow the moving actors' (from ``first_track_id``)."""
    traj = traj.assign(parked=False)
    if len(parked) == 0:
        return traj
    frames = traj[["frame", "time_s"]].drop_duplicates("frame")
    rows = parked_rows(parked, frames, first_track_id)
    table = pd.concat([traj, rows[traj.columns]], ignore_index=True)
    table = table.sort_values(["frame", "track_id"], kind="stable").reset_index(drop=True)
    return table.astype({"frame": np.int32, "track_id": np.int32, "signals": np.int32,
                         **{c: np.uint8 for c in ("color_r", "color_g", "color_b")}})
