"""Props beside the roads: buildings, trees, street lamps and highway barriers, placed by seeded rules
against an occupancy raster (:mod:`pipeline.world.occupancy`) so none stands on a paved surface.

- Buildings: random footprints and floors along the right side of every non-highway edge, their fronts 3 m
  behind the edge's outermost lane (the sidewalk in town), kept at least 2 m from any paved cell and 1 m from
  each other; their walls, recessed windows, shop fronts and doors come from :mod:`pipeline.world.facades`.
- Trees (:mod:`pipeline.world.trees`): a row in the strip between sidewalk and buildings (deciduous species, crowns
  narrow across the street), and scattered over free ground >= 4 m from pavement (parks, block interiors, highway
  verges; conifers too).
- Street lamps: every ~30 m on the outer side of town sidewalks, every ~50 m beyond highway shoulders;
  7 m / 10 m poles with an arm over the road; their head positions are the night light sources.
- Street furniture (town edges only): traffic signs on 2.2-2.6 m posts 0.35 m from the kerb, facing the
  traffic of their edge (round with a red ring, triangular with a red border, or a plain rectangle): one near
  the start of most edges, more every 35-70 m; a bus shelter (posts, roof, glass back and sides, bench) with
  its stop sign behind the sidewalk of about one edge in five of at least 60 m; bushes in the strip between
  sidewalk and buildings. Shelters are placed before the street trees (trees avoid them), signs and bushes
  after everything else, each only where the occupancy raster is free.
- Barriers: trapezoid concrete barriers 0.6 m outside both outer edges of highway carriageways, cut where
  they would touch a carriageway or junction (ramps, merges); where the two directions of a highway meet
  without a gap (an edge and its reverse), a slimmer median barrier on their shared border, cut 1 m
  before junctions.
"""

from __future__ import annotations

import itertools

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.traffic.roadgeometry import CARRIAGEWAY_KINDS, RoadGeometry
from pipeline.world import facades, furniture, trees
from pipeline.world.facades import FLOOR_M
from pipeline.world.occupancy import Grid
from pipeline.world.polygons import cumulative_length, interpolate, offset_polyline, resample, ribbon
from pipeline.world.primitives import PartBuilder, boxes, prisms, quads
from pipeline.world.roadmesh import lane_points

SETBACK_M = 3.0
_BARRIER_PROFILE = ((0.3, 0.0), (0.12, 0.8), (-0.12, 0.8), (-0.3, 0.0))  # (left offset, height), left to right
_MEDIAN_PROFILE = ((0.2, 0.0), (0.08, 0.8), (-0.08, 0.8), (-0.2, 0.0))
# Species shares (round, oval, spreading, conifer; pipeline.world.trees.SPECIES) of street trees and of the trees
# scattered over parks, block interiors and verges.
STREET_TREES = (0.5, 0.35, 0.15, 0.0)
SCATTERED_TREES = (0.35, 0.2, 0.15, 0.3)
STREET_CROWN_ACROSS_M = 1.7


class PropPlacer:
    """Places props for one network; ``parts`` and ``street_lights`` are filled by :meth:`build`.

    Args:
        geometry: the road tables. grid: the raster frame. paved, driving, junctions: (rows, cols) bool
        rasters of all paved ground, of carriageways+junctions, of junctions alone. highway: ids of highway
        edges. rng: the world's generator (draw order is fixed, so the result is deterministic).
    """

    def __init__(self, geometry: RoadGeometry, grid: Grid, paved: np.ndarray, driving: np.ndarray,
                 junctions: np.ndarray, highway: set[str], rng: np.random.Generator) -> None:
        self.geo, self.grid, self.rng, self.highway = geometry, grid, rng, highway
        self.paved, self.driving, self.junctions = paved, driving, junctions
        self.taken = np.zeros(grid.shape, dtype=bool)
        self.parts = {name: PartBuilder(cls) for name, cls in (
            ("building", SemanticClass.BUILDING), ("vegetation", SemanticClass.VEGETATION),
            ("pole", SemanticClass.POLE), ("barrier", SemanticClass.BARRIER))}
        self.street_lights = np.zeros((0, 3))
        normal = geometry.lanes[(geometry.lanes.function == "normal") & (geometry.lanes.shape_x.map(len) >= 2)]
        self.edges = {e: g.sort_values("index") for e, g in normal.groupby("edge_id", sort=True)}

    def free(self, xy: np.ndarray, clearance_m: float = 0.0) -> np.ndarray:
        """(n,) bool: points not on pavement (``clearance_m`` 0 or 2) and not taken by another prop."""
        paved = self.grid.near(self.paved, xy, 2.0, outside=True) if clearance_m >= 2.0 else \
            self.grid.lookup(self.paved, xy, outside=True)
        return ~paved & ~self.grid.lookup(self.taken, xy, outside=True)

    def take(self, corners: np.ndarray) -> None:
        """Mark convex quads (N, 4, >=2) as taken."""
        if len(corners) > 16:
            self.grid.rasterise(np.concatenate([corners[:, [0, 1, 2], :2], corners[:, [0, 2, 3], :2]]), self.taken)
            return
        for quad in corners:
            self.grid.mark_convex(quad, self.taken)

    def build(self) -> PropPlacer:
        self._barriers()
        self._buildings()
        lights = [self._lamps(edge, lanes) for edge, lanes in self.edges.items()]
        self.street_lights = np.concatenate(lights) if lights else np.zeros((0, 3))
        furniture.bus_shelters(self)
        self._street_trees()
        self._scattered_trees()
        furniture.signs(self)
        furniture.bushes(self)
        return self

    # -- buildings ---------------------------------------------------------------------------------
    def _buildings(self) -> None:
        footprints, heights = [], []
        for edge, lanes in self.edges.items():
            if edge in self.highway:
                continue
            outer = lanes.iloc[0]
            line = offset_polyline(lane_points(outer), -(outer.width_m / 2 + SETBACK_M))
            length = cumulative_length(line)[-1]
            s = self.rng.uniform(0.0, 4.0)
            while s < length - 6.0:
                width, depth = self.rng.uniform(8.0, 20.0), self.rng.uniform(8.0, 16.0)
                floors = int(self.rng.integers(2, 9))
                rect = self._footprint(line, s, min(s + width, length), depth)
                if rect is not None:
                    footprints.append(rect)
                    heights.append(floors * FLOOR_M + self.rng.uniform(0.0, 1.0))
                s += width + self.rng.uniform(1.0, 5.0)
        if footprints:
            self._building_meshes(np.array(footprints), np.array(heights))

    def _footprint(self, line: np.ndarray, s0: float, s1: float, depth: float) -> np.ndarray | None:
        """A free rectangle (4, 3) with its front on ``line`` from s0 to s1 and extending right, or None."""
        (p0, p1), _ = interpolate(line, np.array([s0, s1]))
        along = p1[:2] - p0[:2]
        width = np.linalg.norm(along)
        if width < 6.0:
            return None
        along /= width
        out = np.array([along[1], -along[0]])
        for d in (depth, 0.6 * depth):
            u, v = np.meshgrid(np.linspace(0, width, int(width) + 2), np.linspace(0, d, int(d) + 2))
            pts = p0[:2] + u.reshape(-1, 1) * along + v.reshape(-1, 1) * out
            if self.free(pts, clearance_m=2.0).all():
                rect = np.array([p0[:2], p1[:2], p1[:2] + out * d, p0[:2] + out * d])
                grow = np.array([[-1, 1], [1, 1], [1, -1], [-1, -1]]) @ np.stack([along, -out])  # 1 m spacing
                self.take(rect[None] + grow[None])
                return np.concatenate([rect, np.full((4, 1), p0[2])], axis=1)
        return None

    def _building_meshes(self, rects: np.ndarray, heights: np.ndarray) -> None:
        """Walls, recessed windows, doors and shop fronts over footprints (N, 4, 3) of ``heights`` (N,)."""
        facades.layout(rects, heights, self.rng).add_to(self.parts["building"])

    # -- trees ---------------------------------------------------------------------------------------
    def _trees(self, xy: np.ndarray, z: np.ndarray, shares: tuple[float, ...], yaw: np.ndarray | None = None,
               max_across_m: float = np.inf) -> None:
        """Trees at (n, 2) ``xy`` on ground height ``z`` (n,), their species drawn with ``shares`` (one per species
        of :data:`trees.SPECIES`)."""
        n = len(xy)
        if not n:
            return
        species = self.rng.choice(len(trees.SPECIES), n, p=shares)
        grown = trees.grow(np.concatenate([xy, z[:, None]], 1), species, self.rng, yaw, max_across_m)
        self.parts["vegetation"].add(grown.vertices, grown.triangles, grown.material)
        r = 0.5
        self.take(xy[:, None, :] + np.array([[-r, -r], [r, -r], [r, r], [-r, r]])[None])

    def _street_trees(self) -> None:
        spots, zs, yaws = [], [], []
        for edge, lanes in self.edges.items():
            if edge in self.highway:
                continue
            outer = lanes.iloc[0]
            line = offset_polyline(lane_points(outer), -(outer.width_m / 2 + 1.2))
            length = cumulative_length(line)[-1]
            s = np.arange(self.rng.uniform(3.0, 9.0), length - 3.0, self.rng.uniform(10.0, 18.0))
            if len(s):
                pos, direction = interpolate(line, s)
                ok = ~self.grid.near(self.paved, pos, 0.7, outside=True) & self.free(pos)
                spots.append(pos[ok, :2])
                zs.append(pos[ok, 2])
                yaws.append(np.arctan2(direction[ok, 1], direction[ok, 0]))
        if spots:
            # Crowns stay within STREET_CROWN_ACROSS_M across the street: the façades stand SETBACK_M - 1.2 m behind.
            self._trees(np.concatenate(spots), np.concatenate(zs), STREET_TREES, np.concatenate(yaws),
                        STREET_CROWN_ACROSS_M)

    def _scattered_trees(self, area_per_tree_m2: float = 1500.0, max_trees: int = 2000) -> None:
        x0, y0 = self.grid.x0, self.grid.y0
        x1, y1 = x0 + self.grid.shape[1] * self.grid.cell_m, y0 + self.grid.shape[0] * self.grid.cell_m
        n = min(max_trees, int((x1 - x0) * (y1 - y0) / area_per_tree_m2))
        xy = self.rng.uniform((x0, y0), (x1, y1), (n, 2))
        ok = ~self.grid.near(self.paved, xy, 4.0, outside=True) & ~self.grid.near(self.taken, xy, 2.0, outside=True)
        self._trees(xy[ok], np.zeros(int(ok.sum())), SCATTERED_TREES)

    # -- street lamps and barriers -----------------------------------------------------------------
    def _lamps(self, edge: str, lanes) -> np.ndarray:
        """Lamp poles along one edge; returns their head positions (k, 3)."""
        highway = edge in self.highway
        carriage = lanes[lanes.kind.isin(CARRIAGEWAY_KINDS)]
        sidewalks = lanes[lanes.kind == "sidewalk"]
        if highway and len(carriage):  # beyond the shoulder barrier
            ref, spacing, height, arm = carriage.iloc[0], 50.0, 10.0, 2.5
            offset = -(ref.width_m / 2 + 3.0)
        elif not highway and len(sidewalks):  # on the outer side of the sidewalk
            ref, spacing, height, arm = sidewalks.iloc[0], 30.0, 7.0, 1.8
            offset = -(ref.width_m / 2 - 0.3)
        else:
            return np.zeros((0, 3))
        line = offset_polyline(lane_points(ref), offset)
        length = cumulative_length(line)[-1]
        s = np.arange(self.rng.uniform(5.0, spacing / 2), length - 5.0, spacing)
        if not len(s):
            return np.zeros((0, 3))
        pos, direction = interpolate(line, s)
        ok = ~self.grid.lookup(self.driving, pos) & ~self.grid.lookup(self.taken, pos, outside=True)
        pos, direction = pos[ok], direction[ok]
        n = len(pos)
        left = np.stack([-direction[:, 1], direction[:, 0]], 1)
        self.parts["pole"].add(*prisms(pos, np.full(n, 0.09), np.full(n, height), 6), "metal")
        arm_mid = np.concatenate([pos[:, :2] + left * arm / 2, pos[:, 2:] + height - 0.1], 1)
        yaw = np.arctan2(left[:, 1], left[:, 0])
        self.parts["pole"].add(*boxes(arm_mid, np.tile([arm, 0.08, 0.08], (n, 1)), yaw), "metal")
        head = np.concatenate([pos[:, :2] + left * arm, pos[:, 2:] + height - 0.2], 1)
        self.parts["pole"].add(*boxes(head, np.tile([0.6, 0.3, 0.15], (n, 1)), yaw), "lamp")
        self.take(pos[:, None, :2] + np.array([[-0.4, -0.4], [0.4, -0.4], [0.4, 0.4], [-0.4, 0.4]])[None])
        return head - [0.0, 0.0, 0.1]

    def _barriers(self) -> None:
        ends = {(lanes.iloc[0].from_junction, lanes.iloc[0].to_junction) for lanes in self.edges.values()}
        for edge, lanes in self.edges.items():
            carriage = lanes[lanes.kind.isin(CARRIAGEWAY_KINDS)]
            if edge not in self.highway or not len(carriage):
                continue
            for row, side in ((carriage.iloc[-1], 1.0), (carriage.iloc[0], -1.0)):
                line = resample(offset_polyline(lane_points(row), side * (row.width_m / 2 + 0.6)), 1.0)
                self._barrier_runs(line, ~self.grid.near(self.driving, line, 0.35), _BARRIER_PROFILE)
            row = carriage.iloc[-1]
            reverse = (row.to_junction, row.from_junction)
            if reverse in ends and reverse < (row.from_junction, row.to_junction):  # drawn once per pair
                line = resample(offset_polyline(lane_points(row), row.width_m / 2), 1.0)
                on_median = self.grid.lookup(self.driving, offset_polyline(line, 0.5))  # opposite lanes there
                self._barrier_runs(line, on_median & ~self.grid.near(self.junctions, line, 1.0), _MEDIAN_PROFILE)

    def _barrier_runs(self, line: np.ndarray, ok: np.ndarray, profile: tuple) -> None:
        """Barriers along the runs of at least 3 consecutive ``ok`` points of ``line`` (1 m apart)."""
        runs = np.split(np.arange(len(line)), np.flatnonzero(np.diff(ok.astype(int))) + 1)
        for run in runs:
            if ok[run[0]] and len(run) >= 3:
                self._barrier(line[np.unique(np.concatenate([run[::4], run[-1:]]))], profile)

    def _barrier(self, line: np.ndarray, shape: tuple) -> None:
        profile = []
        for lateral, height in shape:
            p = offset_polyline(line, lateral)
            p[:, 2] += height
            profile.append(p)
        for a, b in itertools.pairwise(profile):
            self.parts["barrier"].add(*ribbon(a, b), "barrier")
        ends = np.stack([np.stack(profile, 0)[:, 0], np.stack(profile, 0)[::-1, -1]], 0)  # end caps (2, 4, 3)
        self.parts["barrier"].add(*quads(ends), "barrier")
        self.take(np.stack([profile[0][:-1], profile[0][1:], profile[-1][1:], profile[-1][:-1]], 1))

