"""Street furniture beside town roads: traffic signs, bus shelters and bushes (see pipeline/world/props.py).

Each function takes the :class:`~pipeline.world.props.PropPlacer` being built (its road tables, occupancy
rasters, parts and generator) and adds to its parts, marking what it places as taken. Conventions as in
props.py: world frame, metres, yaw CCW from +x; every draw from the placer's generator, in a fixed order.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from pipeline.traffic.busstops import SHELTER_LENGTH_M
from pipeline.world.polygons import cumulative_length, interpolate, offset_polyline
from pipeline.world.primitives import blobs, boxes, prisms
from pipeline.world.roadmesh import lane_points

if TYPE_CHECKING:
    from pipeline.world.props import PropPlacer

log = logging.getLogger(__name__)


def town_sidewalks(placer: PropPlacer) -> list[tuple[str, object]]:
    """(edge id, sidewalk lane row) of every non-highway edge with a sidewalk, in edge order."""
    out = []
    for edge, lanes in placer.edges.items():
        sidewalks = lanes[lanes.kind == "sidewalk"]
        if edge not in placer.highway and len(sidewalks):
            out.append((edge, sidewalks.iloc[0]))
    return out

_SIGN_OUTLINES = {
    "round": np.stack([np.cos(a := np.linspace(0, 2 * np.pi, 16, endpoint=False)), np.sin(a)], 1) * 0.32,
    "triangle": np.array([[0.0, 0.42], [-0.4, -0.27], [0.4, -0.27]]),
    "rectangle": np.array([[-0.3, -0.32], [0.3, -0.32], [0.3, 0.32], [-0.3, 0.32]]),
}


def vertical_plates(centre: np.ndarray, yaw: np.ndarray, outline: np.ndarray, forward_m: float = 0.0,
                    back: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Flat convex plates in vertical planes: centre (N, 3), facing direction yaw (N,) (the side seen from the
    front points along it), outline (K, 2) as (right, up) offsets seen from the front, shifted ``forward_m``
    along the facing direction. Fan-triangulated, counter-clockwise seen from the front (from behind with
    ``back``). Returns (K*N, 3) vertices and ((K-2)*N, 3) triangles."""
    k = len(outline)
    # Seen from the front (looking along -facing), "right" is the facing direction's left (+y local).
    local = np.stack([np.full(k, forward_m), outline[:, 0], outline[:, 1]], 1)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x, y = local[None, :, 0] * c - local[None, :, 1] * s, local[None, :, 0] * s + local[None, :, 1] * c
    verts = (np.stack([x, y, np.broadcast_to(local[None, :, 2], x.shape)], -1) + centre[:, None, :]).reshape(-1, 3)
    fan = np.stack([np.zeros(k - 2, int), np.arange(1, k - 1), np.arange(2, k)], 1)
    fan = fan[:, [0, 2, 1]] if back else fan
    tris = (fan[None] + (np.arange(len(centre)) * k)[:, None, None]).reshape(-1, 3).astype(np.int32)
    return verts, tris


def signs(placer: PropPlacer) -> None:
    """Traffic signs on posts at the kerb side of town sidewalks, facing their edge's traffic."""
    spots, yaws, tried = [], [], 0
    for _edge, walk in town_sidewalks(placer):
        line = offset_polyline(lane_points(walk), walk.width_m / 2 - 0.35)  # the kerb side
        length = cumulative_length(line)[-1]
        s = [float(placer.rng.uniform(2.0, 6.0))] if placer.rng.random() < 0.7 else []
        s += list(np.arange(placer.rng.uniform(20.0, 40.0), length - 15.0, placer.rng.uniform(35.0, 70.0)))
        s = np.array([v for v in s if v < length - 2.0])
        if not len(s):
            continue
        pos, direction = interpolate(line, s)
        ok = ~placer.grid.lookup(placer.driving, pos) & ~placer.grid.near(placer.taken, pos, 0.5, outside=True)
        tried += len(ok)
        spots.append(pos[ok])
        yaws.append(np.arctan2(-direction[ok, 1], -direction[ok, 0]))  # facing the oncoming traffic
    if not spots:
        return
    pos, yaw = np.concatenate(spots), np.concatenate(yaws)
    n = len(pos)
    log.info("traffic signs: %d placed, %d of the spots tried were taken or on a carriageway", n, tried - n)
    kind = placer.rng.integers(0, len(_SIGN_OUTLINES), n)
    height = placer.rng.uniform(2.2, 2.6, n)
    placer.parts["pole"].add(*prisms(pos, np.full(n, 0.035), height + 0.3, 6), "metal")
    for k, (name, outline) in enumerate(_SIGN_OUTLINES.items()):
        m = kind == k
        if not m.any():
            continue
        centre = pos[m] + np.stack([np.zeros(m.sum()), np.zeros(m.sum()), height[m]], 1)
        # Mounted 5 cm in front of the post; a metal back, a coloured border, a white face 1 cm further out.
        face = "plate" if name == "rectangle" else "taillight"
        placer.parts["pole"].add(*vertical_plates(centre, yaw[m], outline, 0.05, back=True), "metal")
        placer.parts["pole"].add(*vertical_plates(centre, yaw[m], outline, 0.055), face)
        if name != "rectangle":
            inner = outline * 0.72 + (np.array([0.0, -0.04]) if name == "triangle" else 0.0)
            placer.parts["pole"].add(*vertical_plates(centre, yaw[m], inner, 0.06), "plate")
    placer.take(pos[:, None, :2] + np.array([[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]])[None])


def bus_shelters(placer: PropPlacer) -> None:
    """A bus shelter behind the sidewalk (away from the road) at each of the network's bus stops (the road
    geometry's ``bus_stops``, chosen by the scenario: pipeline.traffic.busstops), centred on the stop; where the
    ground behind the sidewalk is taken (a building, a prop), the stop keeps only its sign, a flag on a pole at the
    kerb (as many real stops are)."""
    length_m, depth_m, height_m = SHELTER_LENGTH_M, 1.5, 2.4
    walks = {lane.lane_id: lane for lanes in placer.edges.values()
             for lane in lanes[lanes.kind == "sidewalk"].itertuples(index=False)}
    placed = blocked = 0
    flags = []
    for stop in placer.geo.bus_stops.itertuples(index=False):
        walk = walks.get(stop.lane_id)
        if walk is None:
            raise ValueError(f"bus stop {stop.stop_id}: {stop.lane_id!r} is not a sidewalk lane of this network "
                             "(bus_stops.parquet and lanes.parquet of different networks?)")
        centre_line = lane_points(walk)
        share = stop.pos_m / max(float(walk.length_m), 1e-9)  # SUMO's length may differ from the shape's
        back_line = offset_polyline(centre_line, -(walk.width_m / 2 + 0.2 + depth_m / 2))
        (centre,), (direction,) = interpolate(back_line, np.array([share * cumulative_length(back_line)[-1]]))
        yaw = float(np.arctan2(direction[1], direction[0]))
        along, left = direction, np.array([-direction[1], direction[0]])
        u, v = np.meshgrid(np.linspace(-length_m / 2, length_m / 2, 9), np.linspace(-depth_m / 2, depth_m / 2, 4))
        pts = centre[:2] + u.reshape(-1, 1) * along + v.reshape(-1, 1) * left
        if not placer.free(pts).all():
            blocked += 1
            kerb_line = offset_polyline(centre_line, walk.width_m / 2 - 0.35)
            (pole,), (kerb_dir,) = interpolate(kerb_line, np.array([share * cumulative_length(kerb_line)[-1]]))
            flags.append((pole, float(np.arctan2(-kerb_dir[1], -kerb_dir[0]))))  # facing the oncoming traffic
            continue
        placed += 1
        z = centre[2]
        corners = np.array([centre[:2] + a * along * (length_m / 2 - 0.1) + b * left * (depth_m / 2 - 0.1)
                            for a in (-1, 1) for b in (-1, 1)])
        placer.parts["building"].add(*prisms(np.c_[corners, np.full(4, z)], np.full(4, 0.04), np.full(4, height_m),
                                           6), "metal")
        yaws = np.full(1, yaw)
        roof = np.r_[centre[:2], z + height_m + 0.04][None]
        placer.parts["building"].add(*boxes(roof, np.array([[length_m + 0.3, depth_m + 0.3, 0.08]]), yaws), "metal")
        back = np.r_[centre[:2] - left * (depth_m / 2 - 0.1), z + 0.3 + 1.0][None]  # the side away from the road
        placer.parts["building"].add(*boxes(back, np.array([[length_m - 0.2, 0.03, 2.0]]), yaws), "glass")
        for a in (-1, 1):
            side = np.r_[centre[:2] + a * along * (length_m / 2 - 0.1), z + 1.3][None]
            placer.parts["building"].add(*boxes(side, np.array([[0.03, depth_m - 0.4, 2.0]]), yaws), "glass")
        bench = np.r_[centre[:2] - left * (depth_m / 2 - 0.4), z + 0.225][None]
        placer.parts["building"].add(*boxes(bench, np.array([[2.0, 0.4, 0.45]]), yaws), "concrete")
        placer.take(np.array([[centre[:2] + a * along * (length_m / 2 + 0.5) + b * left * (depth_m / 2 + 0.3)
                             for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]]))
    if flags:
        pos, yaw = np.array([f[0] for f in flags]), np.array([f[1] for f in flags])
        placer.parts["pole"].add(*prisms(pos, np.full(len(pos), 0.035), np.full(len(pos), 2.9), 6), "metal")
        centre = pos + np.array([0.0, 0.0, 2.55])
        flag = np.array([[-0.25, -0.3], [0.25, -0.3], [0.25, 0.3], [-0.25, 0.3]])
        placer.parts["pole"].add(*vertical_plates(centre, yaw, flag, 0.05, back=True), "metal")
        placer.parts["pole"].add(*vertical_plates(centre, yaw, flag, 0.055), "plate")
        placer.take(pos[:, None, :2] + np.array([[-0.3, -0.3], [0.3, -0.3], [0.3, 0.3], [-0.3, 0.3]])[None])
    if placed or blocked:  # a network without stops (the highway) says nothing
        log.info("bus stops: %d shelters, %d flags only (the ground behind the sidewalk was taken)", placed, blocked)


def bushes(placer: PropPlacer) -> None:
    """Low bushes in the strip between town sidewalks and the buildings, where it is free."""
    spots, zs = [], []
    for _edge, walk in town_sidewalks(placer):
        line = offset_polyline(lane_points(walk), -(walk.width_m / 2 + placer.rng.uniform(1.4, 2.2)))
        length = cumulative_length(line)[-1]
        s = np.arange(placer.rng.uniform(2.0, 6.0), length - 2.0, placer.rng.uniform(4.0, 9.0))
        s = s[placer.rng.random(len(s)) < 0.45]
        if len(s):
            pos, _ = interpolate(line, s)
            ok = (~placer.grid.near(placer.paved, pos, 1.3, outside=True)
                  & ~placer.grid.near(placer.taken, pos, 0.8, outside=True))
            spots.append(pos[ok, :2])
            zs.append(pos[ok, 2])
    if not spots:
        return
    xy, z = np.concatenate(spots), np.concatenate(zs)
    n = len(xy)
    log.info("bushes: %d placed", n)
    # At most 1.1 m across from the centre: they stay off the sidewalk (>= 1.3 m away, checked above).
    r = placer.rng.uniform(0.45, 0.8, n)
    radii = np.stack([r * placer.rng.uniform(1.0, 1.4, n), r, r * placer.rng.uniform(0.6, 0.9, n)], 1)
    centre = np.stack([xy[:, 0], xy[:, 1], z + radii[:, 2] * 0.8], 1)
    placer.parts["vegetation"].add(*blobs(centre, radii, placer.rng.uniform(0, np.pi, n)), "foliage")
    placer.take(xy[:, None, :] + np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])[None])

