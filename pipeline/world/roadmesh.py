"""Road surfaces, sidewalks with kerbs, crossings and lane markings from the road geometry tables.

Heights relative to each lane's/junction's own z (SUMO elevation, 0 on flat networks): carriageways and
junctions at 0; crossings at +5 mm (so they win over the junction they lie in); lane markings, zebra
stripes and stop lines at +2 cm (:data:`MARKING_DZ_M`); sidewalks and walking areas at +15 cm
(:data:`SIDEWALK_DZ_M`) with vertical kerb walls.

Marking geometry: a line between two carriageway lanes of one edge is centred on their border and drawn
once; an outer (carriageway edge) line lies just inside the lane, so the two directions of an undivided
road show a double line at the centre. Highway lines are 15 cm wide with 3 m dashes and 9 m gaps; others
12 cm with 3 m / 6 m.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.core.classes import SemanticClass
from pipeline.traffic.roadgeometry import CARRIAGEWAY_KINDS, RoadGeometry
from pipeline.world.polygons import (
    clean_ring,
    cumulative_length,
    interpolate,
    offset_polyline,
    polyline_normals,
    resample,
    ribbon,
    signed_area,
    triangulate_ring,
    wall,
)
from pipeline.world.primitives import PartBuilder, quads

SIDEWALK_DZ_M = 0.15
MARKING_DZ_M = 0.02
CROSSING_DZ_M = 0.005
HIGHWAY_SPEED_MPS = 22.0  # ~80 km/h: a lane this fast on an edge without sidewalks is treated as highway
_RASTER_STEP_M = 3.0


def lane_points(row: pd.Series) -> np.ndarray:
    """Centre line (n, 3) float64 of a lane row."""
    return np.stack([row.shape_x, row.shape_y, row.shape_z], axis=1)


def highway_edges(lanes: pd.DataFrame) -> set[str]:
    """Edge ids of highway carriageways: motorway/trunk road types, or fast edges without sidewalks.

    (OSM types all start with ``highway.``, so the type prefix alone does not make a highway.)
    """
    normal = lanes[lanes.function == "normal"]
    by_type = normal.road_type.str.contains("motorway|trunk|expressway", regex=True)
    grouped = normal.assign(sidewalk=normal.kind == "sidewalk").groupby("edge_id")
    fast = (grouped.speed_mps.max() >= HIGHWAY_SPEED_MPS) & ~grouped.sidewalk.any()
    return set(normal.edge_id[by_type]) | set(fast.index[fast])


def _strip(points: np.ndarray, half_left: float, half_right: float, dz: float) -> tuple[np.ndarray, np.ndarray]:
    """Surface between offsets +half_left and -half_right of a centre line, raised by dz."""
    normals = polyline_normals(points)  # one set for both sides
    left, right = offset_polyline(points, half_left, normals), offset_polyline(points, -half_right, normals)
    left[:, 2] += dz
    right[:, 2] += dz
    return ribbon(left, right)


def _ring_of(row: pd.Series) -> np.ndarray:
    return clean_ring(np.stack([row.shape_x, row.shape_y, row.shape_z], axis=1))


class RoadSurfaces:
    """Builds the road-level meshes and collects 2D triangles for the occupancy raster.

    Attributes after :meth:`build`: ``parts`` (name -> PartBuilder), ``paved_tris``, ``driving_tris`` and
    ``junction_tris`` (lists of (T, 3, 2) float64 triangles covering all paved ground, the carriageways and
    junctions, and the junctions alone).
    """

    def __init__(self, geometry: RoadGeometry) -> None:
        self.geo = geometry
        self.highway = highway_edges(geometry.lanes)
        self.parts = {
            "road": PartBuilder(SemanticClass.ROAD),
            "sidewalk": PartBuilder(SemanticClass.SIDEWALK),
            "kerb": PartBuilder(SemanticClass.KERB),
            "crossing": PartBuilder(SemanticClass.CROSSING),
            "lane_marking": PartBuilder(SemanticClass.LANE_MARKING),
        }
        self.paved_tris: list[np.ndarray] = []
        self.driving_tris: list[np.ndarray] = []
        self.junction_tris: list[np.ndarray] = []

    def _raster(self, points: np.ndarray, width: float, driving: bool) -> None:
        v, t = _strip(resample(points, _RASTER_STEP_M), width / 2, width / 2, 0.0)
        tri = v[t][:, :, :2]
        self.paved_tris.append(tri)
        if driving:
            self.driving_tris.append(tri)

    def build(self) -> RoadSurfaces:
        for row in self.geo.lanes.itertuples(index=False):
            if len(row.shape_x) < 2 and row.function != "walkingarea":
                continue
            self._lane(row)
        for row in self.geo.junctions.itertuples(index=False):
            ring = _ring_of(row)
            if len(ring) >= 3:
                tris = triangulate_ring(ring)
                self.parts["road"].add(ring, tris, "asphalt")
                self.paved_tris.append(ring[tris][:, :, :2])
                self.driving_tris.append(ring[tris][:, :, :2])
                self.junction_tris.append(ring[tris][:, :, :2])
        self._markings()
        self._stop_lines()
        return self

    def _lane(self, row) -> None:
        kind, width = row.kind, row.width_m
        if kind == "walkingarea":
            ring = _ring_of(row)
            if len(ring) >= 3:
                self._raised_polygon(ring)
            return
        points = lane_points(row)
        if kind == "sidewalk":
            v, t = _strip(points, width / 2, width / 2, SIDEWALK_DZ_M)
            self.parts["sidewalk"].add(v, t, "concrete")
            for side in (1, -1):  # kerb walls on both long sides, facing outward
                edge = offset_polyline(points, side * width / 2)
                edge = edge if side < 0 else edge[::-1]
                self.parts["kerb"].add(*wall(edge, SIDEWALK_DZ_M), "kerb")
            self._raster(points, width, driving=False)
        elif kind == "crossing":
            self.parts["crossing"].add(*_strip(points, width / 2, width / 2, CROSSING_DZ_M), "asphalt")
            self._zebra(points, width)
            self._raster(points, width, driving=False)
        elif kind != "verge":
            self.parts["road"].add(*_strip(points, width / 2, width / 2, 0.0), "asphalt")
            self._raster(points, width, driving=True)

    def _raised_polygon(self, ring: np.ndarray) -> None:
        tris = triangulate_ring(ring)
        top = ring.copy()
        top[:, 2] += SIDEWALK_DZ_M
        self.parts["sidewalk"].add(top, tris, "concrete")
        ccw = ring if signed_area(ring) > 0 else ring[::-1]
        self.parts["kerb"].add(*wall(np.concatenate([ccw, ccw[:1]]), SIDEWALK_DZ_M), "kerb")
        self.paved_tris.append(ring[tris][:, :, :2])

    def _zebra(self, points: np.ndarray, width: float, stripe_m: float = 0.5, gap_m: float = 0.5) -> None:
        """Stripes along the walking direction's normal: each spans the crossing's width, 0.5 m deep."""
        length = cumulative_length(points)[-1]
        count = int((length - gap_m) // (stripe_m + gap_m))
        if count < 1:
            return
        start = (length - count * (stripe_m + gap_m) + gap_m) / 2 + np.arange(count) * (stripe_m + gap_m)
        self._dashes(points, start, start + stripe_m, 0.0, width - 0.4, "crossing")

    def _dashes(self, line: np.ndarray, s0: np.ndarray, s1: np.ndarray, offset: float, line_w: float, part: str,
                samples: int = 4) -> None:
        """Quads strips (``samples`` points each) from arc length s0 to s1 along ``line`` offset sideways."""
        if not len(s0):
            return
        s = s0[:, None] + (s1 - s0)[:, None] * np.linspace(0.0, 1.0, samples)[None, :]
        pos, direction = interpolate(line, s.ravel())
        normal = np.stack([-direction[:, 1], direction[:, 0]], 1)
        centre = pos.copy()
        centre[:, :2] += normal * offset
        centre[:, 2] += MARKING_DZ_M
        left, right = centre.copy(), centre.copy()
        left[:, :2] += normal * line_w / 2
        right[:, :2] -= normal * line_w / 2
        _, t = ribbon(left[:samples], right[:samples])  # the triangle pattern of one strip
        n = len(s0)
        verts = np.concatenate([left.reshape(n, samples, 3), right.reshape(n, samples, 3)], axis=1).reshape(-1, 3)
        tris = (t[None] + (np.arange(n) * 2 * samples)[:, None, None]).reshape(-1, 3)
        self.parts[part].add(verts, tris, "lane_paint")

    def _markings(self) -> None:
        lanes = self.geo.lanes
        normal = lanes[(lanes.function == "normal") & (lanes.shape_x.map(len) >= 2)]
        carriage = set(normal.lane_id[normal.kind.isin(CARRIAGEWAY_KINDS)])
        for row in normal.itertuples(index=False):
            if row.lane_id not in carriage:
                continue
            highway = row.edge_id in self.highway
            line_w, dash, gap = (0.15, 3.0, 9.0) if highway else (0.12, 3.0, 6.0)
            points = lane_points(row)
            for side, mark in ((1, row.left_marking), (-1, row.right_marking)):
                neighbour = f"{row.edge_id}_{row.index + side}"
                shared = neighbour in carriage
                if mark == "none" or (shared and side < 0):
                    continue  # a shared border is drawn once, by the lower-index lane's left side
                offset = side * (row.width_m / 2 if shared else row.width_m / 2 - line_w / 2 - 0.05)
                length = cumulative_length(points)[-1]
                if mark == "solid":
                    line = offset_polyline(points, offset)
                    self.parts["lane_marking"].add(*_strip(line, line_w / 2, line_w / 2, MARKING_DZ_M), "lane_paint")
                else:
                    start = np.arange(gap / 2, length - dash / 2, dash + gap)
                    self._dashes(points, start, np.minimum(start + dash, length), offset, line_w, "lane_marking")

    def _stop_lines(self, depth_m: float = 0.4) -> None:
        tls = self.geo.traffic_lights
        tls = tls[~tls.pedestrian].drop_duplicates("from_lane")
        if not len(tls):
            return
        width = self.geo.lanes.set_index("lane_id").width_m.reindex(tls.from_lane).to_numpy()
        heading = tls.heading_rad.to_numpy()
        fwd = np.stack([np.cos(heading), np.sin(heading), np.zeros_like(heading)], 1)
        left = np.stack([-fwd[:, 1], fwd[:, 0], np.zeros_like(heading)], 1)
        stop = tls[["stop_x", "stop_y", "stop_z"]].to_numpy() + np.array([0.0, 0.0, MARKING_DZ_M])
        half = (width / 2 - 0.1)[:, None]
        back, front = stop - fwd * (depth_m + 0.1), stop - fwd * 0.1
        corners = np.stack([back - left * half, front - left * half, front + left * half, back + left * half], 1)
        self.parts["lane_marking"].add(*quads(corners), "lane_paint")
