"""Where a place on the map stands for people: the carriageway or a crossing, or a sidewalk or a walking area.

The ground truth's "path" row (:func:`pipeline.envs.features.path_row`) counts a standing person only on the
carriageway or a crossing: SUMO says which lane a person is on. A perceived person has only a place, estimated from
a camera box ranged by the LiDAR; :class:`Walkways` answers the same question for a place from the road geometry
tables (:mod:`pipeline.traffic.roadgeometry`: map knowledge, as a driving stack's HD map): a place on a carriageway
lane (driving or bike, normal or inside a junction) or a crossing (each its centre line's strip, the lane's width
across) is on the road unless it lies on a sidewalk or in a junction's walking area (its polygon), or within
``margin_m`` (:data:`WALKWAY_MARGIN_M`) of either; anywhere else (a parking lane, beyond the kerb) is not. The
walkways win where they overlap: a turning lane's strip crosses a corner's walking area, and a crossing begins at
the walking area's edge, where SUMO's people wait for the green standing up to 0.7 m inside the crossing's strip
(on the walking area's lane): the kerb's band of a crossing, ``margin_m`` deep, counts as the walkway (a person
walking over it is in the path by their walk: :func:`pipeline.envs.features.path_row`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.traffic.roadgeometry import CARRIAGEWAY_KINDS, RoadGeometry

# A place within this of a sidewalk or a walking area counts as on it: SUMO's people on a walking area stand up to
# 0.70 m outside its polygon (urban seed 1, every person on a walking area at 6 moments: median 0.30 m of those
# outside), and a place ranged from a camera box by the LiDAR is off by about as much.
WALKWAY_MARGIN_M = 0.75


def _strips(lanes: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments (S, 2) starts and ends and (S,) half widths of the lanes' centre lines."""
    starts, ends, half = [], [], []
    for row in lanes.itertuples(index=False):
        points = np.column_stack([row.shape_x, row.shape_y]).astype(np.float64)
        if len(points) < 2:
            continue
        starts.append(points[:-1])
        ends.append(points[1:])
        half.append(np.full(len(points) - 1, 0.5 * float(row.width_m)))
    if not starts:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0)
    return np.concatenate(starts), np.concatenate(ends), np.concatenate(half)


def in_strips(xy: np.ndarray, starts: np.ndarray, ends: np.ndarray, half_width: np.ndarray) -> np.ndarray:
    """(M,) whether each point lies within ``half_width`` of some segment, across it and between its ends (the union
    of the segments' rectangles)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(starts) == 0 or len(xy) == 0:
        return np.zeros(len(xy), bool)
    seg = ends - starts
    length2 = np.einsum("ij,ij->i", seg, seg)
    rel = xy[:, None, :] - starts[None, :, :]
    along = np.einsum("mij,ij->mi", rel, seg)
    across = rel[..., 0] * seg[None, :, 1] - rel[..., 1] * seg[None, :, 0]
    inside = (along >= 0.0) & (along <= length2) & (across * across <= (half_width * half_width * length2)[None])
    return (inside & (length2 > 0.0)[None]).any(axis=1)


def near_segments(xy: np.ndarray, starts: np.ndarray, ends: np.ndarray, radius: float) -> np.ndarray:
    """(M,) whether each point lies within ``radius`` of some segment (its ends included: capsules)."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(starts) == 0 or len(xy) == 0:
        return np.zeros(len(xy), bool)
    seg = ends - starts
    length2 = np.maximum(np.einsum("ij,ij->i", seg, seg), 1e-18)
    rel = xy[:, None, :] - starts[None, :, :]
    t = np.clip(np.einsum("mij,ij->mi", rel, seg) / length2, 0.0, 1.0)
    off = rel - t[..., None] * seg[None]
    return (np.einsum("mij,mij->mi", off, off) <= radius * radius).any(axis=1)


def in_rings(xy: np.ndarray, starts: np.ndarray, ends: np.ndarray, ring_of_edge: np.ndarray, rings: int) -> np.ndarray:
    """(M,) whether each point lies inside some ring (even-odd rule per ring), the rings given by their edges."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(starts) == 0 or len(xy) == 0:
        return np.zeros(len(xy), bool)
    x, y = xy[:, 0:1], xy[:, 1:2]
    y0, y1 = starts[None, :, 1], ends[None, :, 1]
    straddles = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_cut = starts[None, :, 0] + (y - y0) * (ends[None, :, 0] - starts[None, :, 0]) / (y1 - y0)
    crossings = straddles & (x < x_cut)
    counts = np.zeros((len(xy), rings), np.int64)
    for m in range(len(xy)):
        counts[m] = np.bincount(ring_of_edge[crossings[m]], minlength=rings)
    return (counts % 2 == 1).any(axis=1)


class Walkways:
    """The pedestrian areas of a network (module docstring): :meth:`on_road` of a place."""

    def __init__(self, lanes: pd.DataFrame, margin_m: float = WALKWAY_MARGIN_M) -> None:
        self.margin_m = float(margin_m)
        self._roads = _strips(lanes[lanes["kind"].isin((*CARRIAGEWAY_KINDS, "crossing"))])  # lanes and crossings
        self._sidewalks = _strips(lanes[lanes["kind"] == "sidewalk"])
        starts, ends, owner = [], [], []
        areas = lanes[lanes["kind"] == "walkingarea"]
        for k, row in enumerate(areas.itertuples(index=False)):
            ring = np.column_stack([row.shape_x, row.shape_y]).astype(np.float64)
            if len(ring) < 3:
                continue
            starts.append(ring)
            ends.append(np.roll(ring, -1, axis=0))
            owner.append(np.full(len(ring), k))
        self._rings = len(areas)
        self._ring_edges = ((np.concatenate(starts), np.concatenate(ends), np.concatenate(owner)) if starts
                            else (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64)))

    @classmethod
    def from_geometry(cls, geometry: RoadGeometry) -> Walkways:
        return cls(geometry.lanes)

    def on_road(self, xy: np.ndarray) -> np.ndarray:
        """(M,) bool for (M, 2) world places: on a carriageway lane or a crossing, and neither on nor within
        ``margin_m`` of a sidewalk or a walking area."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        road = in_strips(xy, *self._roads)
        if road.any():
            near, (starts, ends, owner) = xy[road], self._ring_edges
            side_start, side_end, side_half = self._sidewalks
            road[road] = ~(in_strips(near, side_start, side_end, side_half + self.margin_m)
                           | in_rings(near, starts, ends, owner, self._rings)
                           | near_segments(near, starts, ends, self.margin_m))
        return road
