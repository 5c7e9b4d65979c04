"""Traffic-light poles and signal heads, and the table of lamps the renderer lights per frame.

For each incoming edge of a traffic light: a 6 m pole 0.8 m right of the rightmost carriageway lane at
the stop line, a mast arm over the lanes, and one signal head per controlled link above its lane (a
lane with k links gets k heads side by side, in link-index order). Each head is a dark housing with three
lamps (red top, yellow middle, green bottom) facing the incoming traffic. Pedestrian links get no head.

The lamps are quads (two triangles each) of ``parts["traffic_light"]`` with material ``signal_off``;
:meth:`SignalLamps.lit` turns SUMO state strings into which lamps glow, and the renderer gives those
triangles the material ``signal_<colour>``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.core.classes import SemanticClass
from pipeline.traffic.roadgeometry import CARRIAGEWAY_KINDS, RoadGeometry
from pipeline.world.primitives import PartBuilder, boxes, prisms, quads

POLE_HEIGHT_M = 6.0
COLOURS = ("red", "yellow", "green")
# SUMO link state characters (tls state strings) -> lit lamps. 'u' is red+yellow; 'o' blinking yellow
# (shown lit); 'O' off; 's' a green arrow after stopping (shown red).
_LIT = {"red": set("rRus"), "yellow": set("yYuo"), "green": set("gG")}
_HEAD = (0.38, 1.0, 0.3)  # width across the lane, height, depth along travel (m)


@dataclass(frozen=True)
class SignalLamps:
    """One row per lamp; L = 3 x controlled vehicle links, sorted by (tls_id, link_index, colour).

    Attributes:
        tls_id: (L,) object str. link_index: (L,) int32 index into the TLS state string.
        colour: (L,) object str in {red, yellow, green}.
        position: (L, 3) float64 lamp centre, world frame, metres.
        facing_rad: (L,) float64 direction the lamp faces (towards incoming traffic), CCW from +x.
        triangles: (L, 2) int32 [start, stop) triangle range in ``parts["traffic_light"]``.
    """

    tls_id: np.ndarray
    link_index: np.ndarray
    colour: np.ndarray
    position: np.ndarray
    facing_rad: np.ndarray
    triangles: np.ndarray

    def __len__(self) -> int:
        return len(self.tls_id)

    def lit(self, states: dict[str, str]) -> np.ndarray:
        """(L,) bool: which lamps glow for SUMO states ``{tls_id: state string}`` (one char per link_index).

        Raises:
            KeyError: a TLS of the lamps has no state. ValueError: a state string is too short.
        """
        out = np.zeros(len(self), dtype=bool)
        for i, (tls, link, colour) in enumerate(zip(self.tls_id, self.link_index, self.colour, strict=True)):
            state = states[tls]
            if link >= len(state):
                raise ValueError(f"state {state!r} of tls {tls!r} has no link {link}")
            out[i] = state[link] in _LIT[colour]
        return out


def _empty_lamps() -> SignalLamps:
    return SignalLamps(np.array([], object), np.zeros(0, np.int32), np.array([], object), np.zeros((0, 3)),
                       np.zeros(0), np.zeros((0, 2), np.int32))


def build_signals(geo: RoadGeometry, placer) -> tuple[dict[str, PartBuilder], SignalLamps]:
    """Signal poles and heads for all vehicle links of ``geo.traffic_lights``; ``placer`` records their spots."""
    parts = {"traffic_light_pole": PartBuilder(SemanticClass.POLE),
             "traffic_light": PartBuilder(SemanticClass.TRAFFIC_LIGHT)}
    tls = geo.traffic_lights[~geo.traffic_lights.pedestrian]
    if not len(tls):
        return parts, _empty_lamps()
    lanes = geo.lanes.set_index("lane_id")
    links = tls.assign(edge=lanes.edge_id.reindex(tls.from_lane).to_numpy(),
                       lane_index=lanes["index"].reindex(tls.from_lane).to_numpy(),
                       width=lanes.width_m.reindex(tls.from_lane).to_numpy())
    heads_c, heads_yaw, rows = [], [], []
    for (tls_id, edge), group in links.groupby(["tls_id", "edge"], sort=True):
        carriage = lanes[(lanes.edge_id == edge) & lanes.kind.isin(CARRIAGEWAY_KINDS)].sort_values("index")
        right = group.sort_values("lane_index").iloc[0]
        heading = right.heading_rad
        fwd = np.array([np.cos(heading), np.sin(heading)])
        left = np.array([-fwd[1], fwd[0]])
        stop = np.array([right.stop_x, right.stop_y, right.stop_z])
        # Lateral positions (metres left of the rightmost controlled lane's centre) of every lane's centre.
        lane_centre = {r.index: float((np.array([r.shape_x[-1], r.shape_y[-1]]) - stop[:2]) @ left)
                       for r in carriage.itertuples()}
        rightmost = min(lane_centre.values(), default=0.0) - right.width / 2
        leftmost = max(lane_centre.values(), default=0.0) + right.width / 2
        base = stop + np.append(left * (rightmost - 0.8), 0.0)
        parts["traffic_light_pole"].add(*prisms(base[None], np.array([0.1]), np.array([POLE_HEIGHT_M]), 8), "metal")
        span = leftmost - rightmost + 0.8
        arm = base + np.append(left * span / 2, POLE_HEIGHT_M - 0.2)
        parts["traffic_light_pole"].add(*boxes(arm[None], np.array([[span, 0.1, 0.12]]),
                                               np.array([np.arctan2(left[1], left[0])])), "metal")
        placer.take((base[:2] + np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]))[None])
        for lane_index, lane_links in group.sort_values("link_index").groupby("lane_index", sort=True):
            k = len(lane_links)
            lateral = lane_centre.get(lane_index, 0.0) + (np.arange(k) - (k - 1) / 2) * (_HEAD[0] + 0.08)
            for link, lat in zip(lane_links.link_index, lateral, strict=True):
                centre = base + np.append(left * (lat - rightmost + 0.8), POLE_HEIGHT_M - 0.3 - _HEAD[1] / 2)
                heads_c.append(centre)
                heads_yaw.append(heading)
                rows.append((tls_id, int(link)))
    return parts, _heads(parts["traffic_light"], np.array(heads_c), np.array(heads_yaw), rows)


def _heads(part: PartBuilder, centre: np.ndarray, heading: np.ndarray, rows: list[tuple[str, int]]) -> SignalLamps:
    """Lamp quads first (so lamp i owns triangles [2i, 2i+2)), then the housings; rows sorted."""
    order = sorted(range(len(rows)), key=lambda i: rows[i])
    centre, heading, rows = centre[order], heading[order], [rows[i] for i in order]
    n = len(rows)
    fwd = np.stack([np.cos(heading), np.sin(heading), np.zeros(n)], 1)
    left = np.stack([-fwd[:, 1], fwd[:, 0], np.zeros(n)], 1)
    up = np.array([0.0, 0.0, 1.0])
    face = centre - fwd * (_HEAD[2] / 2 + 0.01)
    a = 0.11
    lamp_c = face[:, None, :] + np.array([0.32, 0.0, -0.32])[None, :, None] * up  # (n, 3 colours, 3)
    lamp_c = lamp_c.reshape(-1, 3)
    lf, upv = np.repeat(left, 3, axis=0) * a, up * a
    # CCW seen from the incoming traffic (looking along +fwd): viewer's left is +left.
    corners = np.stack([lamp_c + lf - upv, lamp_c - lf - upv, lamp_c - lf + upv, lamp_c + lf + upv], 1)
    part.add(*quads(corners), "signal_off")
    part.add(*boxes(centre, np.tile([_HEAD[2], _HEAD[0], _HEAD[1]], (n, 1)), heading), "metal")
    start = np.arange(3 * n, dtype=np.int32) * 2
    facing = np.repeat(heading + np.pi, 3)
    return SignalLamps(
        tls_id=np.repeat(np.array([r[0] for r in rows], dtype=object), 3),
        link_index=np.repeat(np.array([r[1] for r in rows], dtype=np.int32), 3),
        colour=np.tile(np.array(COLOURS, dtype=object), n),
        position=lamp_c,
        facing_rad=np.arctan2(np.sin(facing), np.cos(facing)),
        triangles=np.stack([start, start + 2], 1),
    )
