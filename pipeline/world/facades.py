"""Building façades as geometry: windows recessed behind piers and spandrels, so that sun shadows in the reveals,
the glass's mirror reflections, the LiDAR and the ground truth all meet the same surfaces.

A building is a footprint rectangle (4 corners, front first: the side on the street) and a height. Its wall stands
on the footprint: one ring box (the whole footprint) per band of wall between two rows of windows (the plinth below
the first row, a spandrel between floors, the cornice above the last, whose top is the roof), and per face and
zone of floors, vertical piers between the window columns. ``depth`` behind the wall's outer plane lies the glass:
one pane per window, set in a frame (a dark or white quad 2 cm behind the panes, seen around each pane), so every
window is a recess whose reveals catch the light. Styles, drawn per building:

- punched: windows 1.1-1.6 m wide and 1.4-1.8 m tall between piers 0.6-1.8 m wide, 15-25 cm deep reveals;
- ribbon: tall spandrels (1.2-1.7 m) between bands of glass divided by thin mullions;
- curtain: glass from slab edge to slab edge, thin mullions, slab edges in the frame colour, often tinted glass
  (mullions are not boxes: the frame behind the panes shows between them);
- and, on SHOP_SHARE of the buildings, a taller ground floor of shop windows (about 2.6-3 m of glass, wide
  bays) under a fascia board.

Every building has a door on its front. Panes vary: a share of them has a blind or curtain closed (BLIND_CLOSED)
or drawn over its upper part (BLIND_PARTIAL; material ``window_blind``), and a share, drawn per building from
LIT_RATE (shops: SHOP_LIT_RATE), is lit from inside (``window_lit``: glass by day, a warm glow with the lamps at
dusk and night, pipeline.sensors.shading NIGHT_LIT). Wall colours come from WALLS.

Frame of face j: origin at footprint corner j (at the footprint's base height), 'along' from corner j to corner
j + 1, 'across' outwards (the face's normal), z up: the wall's outer plane is across = 0, the glass across = -depth.
Nothing but the cornice (OVERHANG_M), a shop's fascia and a door (a few cm) leaves the footprint. All draws come
from the caller's generator, building by building in a fixed order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.world.materials import material_index
from pipeline.world.primitives import PartBuilder, frame_boxes, frame_quads

FLOOR_M = 3.2
SINK_M = 0.5  # walls reach this far below the footprint's height, so slopes never show a gap
OVERHANG_M = 0.08  # the cornice's projection beyond the footprint
FRAME_GAP_M = 0.02  # the window frame lies this far behind the panes
WALLS = ("building", "building_light", "building_dark", "brick", "brick_dark", "plaster_white", "plaster_ochre",
         "plaster_grey", "plaster_rose")
STYLES = ("punched", "ribbon", "curtain")
STYLE_SHARES = (0.55, 0.25, 0.20)
SHOP_SHARE = 0.4
LIT_RATE = (0.08, 0.45)  # per building, uniform: 0.265 of the windows on average
SHOP_LIT_RATE = 0.6
BLIND_CLOSED, BLIND_PARTIAL = 0.12, 0.15  # shares of the panes with a closed blind, and one drawn part way
# Box sides kept per kind of box (the others are hidden inside the building or under the ground).
_SIDES = {"pier": ("front", "start", "end"), "band": ("bottom", "top", "back", "end", "front", "start"),
          "plinth": ("top", "back", "end", "front", "start"), "door": ("front", "start", "end", "top"),
          "board": ("bottom", "top", "end", "front", "start")}


@dataclass(frozen=True)
class Facades:
    """The façade elements of N buildings, each in the frame of one face (see the module docstring).

    Attributes:
        origin: (4N, 3) float64 frame origins (face j of building b is frame 4b + j); axis: (4N, 2) float64 unit
            'along' directions.
        boxes: kind (a key of _SIDES) -> (frame (K,) int64, lo (K, 3), hi (K, 3) float64 (along, across, z) bounds,
            material (K,) int32).
        frames: the window frames behind the panes, quads: frame (F,), lo, hi (F, 3), material (F,).
        panes: frame (P,) int64, lo, hi (P, 3) (across lo = hi = -depth), glass material (P,) int32, lit (P,) bool,
            blind (P,) float64 share of the pane's height covered from the top (0: none), shop (P,) bool.
        style: (N,) int64 index into STYLES; depth_m: (N,) float64 the glass's depth behind the wall's outer plane.
    """

    origin: np.ndarray
    axis: np.ndarray
    boxes: dict[str, tuple[np.ndarray, ...]]
    frames: tuple[np.ndarray, ...]
    panes: dict[str, np.ndarray]
    style: np.ndarray
    depth_m: np.ndarray

    def add_to(self, part: PartBuilder) -> None:
        """Add the façades' triangles to ``part`` (boxes, frames, then panes split at their blinds)."""
        for kind, (f, lo, hi, mat) in self.boxes.items():
            v, t = frame_boxes(self.origin[f], self.axis[f], lo, hi, _SIDES[kind])
            part.add(v, t, np.repeat(mat, 2 * len(_SIDES[kind])).astype(np.int32))
        f, lo, hi, mat = self.frames
        part.add(*frame_quads(self.origin[f], self.axis[f], lo, hi), np.repeat(mat, 2).astype(np.int32))
        p = self.panes
        split = p["hi"][:, 2] - p["blind"] * (p["hi"][:, 2] - p["lo"][:, 2])
        glass = np.where(p["lit"], material_index("window_lit"), p["material"])
        # A closed blind in a lit room glows through; one drawn part way leaves the pane's lower part lit.
        blind = np.where(p["lit"] & (p["blind"] >= 1.0), material_index("window_lit"), material_index("window_blind"))
        for keep, lo, hi, mat in ((p["blind"] < 1.0, p["lo"], _with_z(p["hi"], split), glass),
                                  (p["blind"] > 0.0, _with_z(p["lo"], split), p["hi"], blind)):
            f = p["frame"][keep]
            part.add(*frame_quads(self.origin[f], self.axis[f], lo[keep], hi[keep]),
                     np.repeat(mat[keep], 2).astype(np.int32))


def _with_z(points: np.ndarray, z: np.ndarray) -> np.ndarray:
    out = points.copy()
    out[:, 2] = z
    return out


def _columns(length: float, width: float, gap: float, end: float, fit: bool) -> tuple[np.ndarray, np.ndarray]:
    """Window columns [s0, s1) along a face of ``length``: openings of ``width`` (``fit``: stretched to fill the
    face) ``gap`` apart, at least ``end`` from each corner; none where the face is too short."""
    room = length - 2.0 * end
    n = max(1, round((room + gap) / (width + gap))) if fit else int((room + gap) // (width + gap))
    w = (room - (n - 1) * gap) / n if fit else width
    if n < 1 or w < 0.5:
        return np.zeros(0), np.zeros(0)
    s0 = (length - n * w - (n - 1) * gap) / 2.0 + np.arange(n) * (w + gap)
    return s0, s0 + w


class _Collector:
    """Façade elements as rows of arrays, gathered zone by zone."""

    def __init__(self) -> None:
        self.boxes: dict[str, list[np.ndarray]] = {k: [] for k in _SIDES}
        self.frames: list[np.ndarray] = []
        self.panes: list[np.ndarray] = []
        self.style: list[int] = []
        self.depth: list[float] = []

    def box(self, kind: str, frame: int, lo, hi, material: str | int | np.ndarray) -> None:
        """Boxes in one frame: ``lo``, ``hi`` (K, 3) or (3,) bounds, ``material`` a name or (K,) indices."""
        mat = material_index(material) if isinstance(material, str) else material
        lo, hi = np.atleast_2d(np.asarray(lo, np.float64)), np.atleast_2d(np.asarray(hi, np.float64))
        k = max(len(lo), len(hi))
        self.boxes[kind].append(np.column_stack([np.full(k, frame), np.broadcast_to(lo, (k, 3)),
                                                 np.broadcast_to(hi, (k, 3)), np.broadcast_to(mat, (k,))]))

    @staticmethod
    def _stack(rows: list[np.ndarray], width: int) -> np.ndarray:
        return np.concatenate(rows) if rows else np.zeros((0, width))

    def build(self, rects: np.ndarray) -> Facades:
        along = np.roll(rects, -1, axis=1)[..., :2] - rects[..., :2]  # face j: corner j -> j + 1
        axis = (along / np.linalg.norm(along, axis=2, keepdims=True)).reshape(-1, 2)
        boxes = {}
        for kind, rows in self.boxes.items():
            a = self._stack(rows, 8)
            boxes[kind] = (a[:, 0].astype(np.int64), a[:, 1:4], a[:, 4:7], a[:, 7].astype(np.int32))
        fr = self._stack(self.frames, 8)
        pa = self._stack(self.panes, 11)
        panes = {"frame": pa[:, 0].astype(np.int64), "lo": pa[:, 1:4], "hi": pa[:, 4:7],
                 "material": pa[:, 7].astype(np.int32), "lit": pa[:, 8] > 0, "blind": pa[:, 9], "shop": pa[:, 10] > 0}
        return Facades(rects.reshape(-1, 3), axis, boxes,
                       (fr[:, 0].astype(np.int64), fr[:, 1:4], fr[:, 4:7], fr[:, 7].astype(np.int32)), panes,
                       np.array(self.style, np.int64), np.array(self.depth, np.float64))


def layout(rects: np.ndarray, heights: np.ndarray, rng: np.random.Generator) -> Facades:
    """Façades of N buildings: footprints ``rects`` (N, 4, 3) (clockwise seen from above, corner 0 -> 1 the front;
    each corner's z the footprint's base height, taken from corner 0), ``heights`` (N,) metres of wall above it (a
    building with a shop floor grows by its extra height)."""
    rects = np.asarray(rects, np.float64).copy()
    rects[:, :, 2] = rects[:, :1, 2]
    a, b = rects[:, 1, :2] - rects[:, 0, :2], rects[:, 3, :2] - rects[:, 0, :2]
    if np.any(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0] >= 0):
        raise ValueError("footprints must run clockwise seen from above (each face's outside on its left)")
    out = _Collector()
    for b in range(len(rects)):
        lengths = np.linalg.norm(np.roll(rects[b], -1, axis=0)[:, :2] - rects[b, :, :2], axis=1)
        _building(out, 4 * b, lengths, float(heights[b]), rng)
    return out.build(rects)


def _building(out: _Collector, frame0: int, lengths: np.ndarray, height: float, rng: np.random.Generator) -> None:
    """One building's elements (frames frame0 .. frame0 + 3, face lengths (4,))."""
    style = STYLES[rng.choice(len(STYLES), p=STYLE_SHARES)]
    wall = material_index(WALLS[rng.integers(len(WALLS))])
    frame = material_index("frame_dark" if rng.random() < 0.6 else "frame_white")
    glass = material_index("building_glass")
    # Columns: opening width, the pier or mullion between openings, the least corner pier, whether openings stretch
    # to fill the face. Mullions are no boxes: the frame behind the panes shows between them (``inset`` each side).
    if style == "punched":
        depth, width, win_h, gap, sill = (rng.uniform(0.15, 0.25), rng.uniform(1.1, 1.6), rng.uniform(1.4, 1.8),
                                          rng.uniform(0.6, 1.8), rng.uniform(0.8, 1.0))
        end, fit, piers, inset = max(gap, 0.7), False, True, 0.06
    elif style == "ribbon":
        depth, width, win_h, gap, sill = (rng.uniform(0.2, 0.3), rng.uniform(1.2, 1.8), rng.uniform(1.5, 2.0),
                                          rng.uniform(0.04, 0.08), rng.uniform(0.8, 1.0))
        end, fit, piers, inset = rng.uniform(0.5, 1.0), True, False, 0.02
    else:
        depth, width, gap = rng.uniform(0.1, 0.15), rng.uniform(1.3, 1.8), rng.uniform(0.03, 0.06)
        sill, win_h = 0.25, FLOOR_M - 0.5
        end, fit, piers, inset = depth + 0.15, True, False, 0.015
        if rng.random() < 0.6:
            glass = material_index("glass_tinted")
    out.style.append(STYLES.index(style))
    out.depth.append(depth)
    floors = max(1, int(height // FLOOR_M))
    shop = floors >= 2 and lengths[0] >= 8.0 and rng.random() < SHOP_SHARE
    ground = rng.uniform(4.0, 4.5) if shop else FLOOR_M
    z0 = np.arange(floors) * FLOOR_M + sill + (ground - FLOOR_M) * (np.arange(floors) >= 1)
    z1 = z0 + win_h
    if shop:
        z0[0], z1[0] = 0.4, ground - 1.0
    top = height + ground - FLOOR_M
    # Wall bands as ring boxes over the whole footprint (frame0: the front face's frame, the building behind it).
    w, d = lengths[0], lengths[1]
    lows, highs = np.r_[-SINK_M, z1], np.r_[z0, top]
    grow = np.where(np.arange(floors + 1) == floors, OVERHANG_M, 0.0)  # the cornice projects
    band_mat = np.full(floors + 1, wall)
    if style == "curtain":
        band_mat[1:-1] = frame  # slab edges between the floors' glass
    lo = np.column_stack([-grow, -d - grow, lows])
    hi = np.column_stack([w + grow, grow, highs])
    out.box("plinth", frame0, lo[:1], hi[:1], band_mat[:1])
    out.box("band", frame0, lo[1:], hi[1:], band_mat[1:])
    lit_rate = rng.uniform(*LIT_RATE)
    # Zones of floors per face: (face, rows, z range of the piers, column layout, interior piers, pane inset).
    zones = []
    for j in range(4):
        if shop:
            layout = (rng.uniform(2.5, 4.5), rng.uniform(0.3, 0.6), max(0.5, depth + 0.2), True)
            zones.append((j, [0], (-SINK_M, z1[0]), layout, True, 0.05))
        rows = list(range(1, floors) if shop else range(floors))
        zones.append((j, rows, (z1[0] if shop else -SINK_M, top), (width, gap, end, fit), piers, inset))
    for j, rows, (pz0, pz1), (cw, cg, ce, cfit), interior, pane_inset in zones:
        frame_j = frame0 + j
        s0, s1 = _columns(lengths[j], cw, cg, ce, cfit)
        lo_s, hi_s = (np.r_[0.0, s1], np.r_[s0, lengths[j]]) if interior or not len(s0) else \
            (np.r_[0.0, s1[-1]], np.r_[s0[0], lengths[j]])
        k = len(lo_s)
        out.box("pier", frame_j, np.column_stack([lo_s, np.full(k, -depth - 0.05), np.full(k, pz0)]),
                np.column_stack([hi_s, np.zeros(k), np.full(k, pz1)]), wall)
        if not len(s0) or not rows:
            continue
        _panes(out, frame_j, s0, s1, z0, z1, np.array(rows), depth, pane_inset, frame, glass,
               SHOP_LIT_RATE if shop and rows == [0] else lit_rate, shop and rows == [0], rng)
        if j == 0 and 0 in rows:  # the door, in a column of the front's ground floor
            c = int(rng.integers(len(s0)))
            door_w = min(s1[c] - s0[c] - 0.1, rng.uniform(1.0, 1.6))
            door_h = min(z1[0] - 0.1, rng.uniform(2.2, 2.5))
            mid = 0.5 * (s0[c] + s1[c])
            out.box("door", frame_j, (mid - door_w / 2, -depth - 0.03, -SINK_M), (mid + door_w / 2, 0.03, door_h),
                    "door")
    if shop:  # the fascia board over the shop windows
        z = z1[0] + 0.15
        out.box("board", frame0, (0.3, -0.05, z), (lengths[0] - 0.3, 0.06, z + rng.uniform(0.5, 0.8)), frame)


def _panes(out: _Collector, frame_j: int, s0: np.ndarray, s1: np.ndarray, z0: np.ndarray, z1: np.ndarray,
           rows: np.ndarray, depth: float, inset: float, frame: int, glass: int, lit_rate: float, shop: bool,
           rng: np.random.Generator) -> None:
    """The panes of columns [s0, s1) x window rows ``rows`` (of z0, z1) of one face zone, and their frames (one quad
    per row behind them): each pane lit with ``lit_rate``; blinds: none in shops, else a closed one (BLIND_CLOSED of
    the panes) or one drawn part way (BLIND_PARTIAL)."""
    m = len(rows)
    q = -depth - FRAME_GAP_M
    out.frames.append(np.column_stack([np.full(m, frame_j), np.full(m, s0[0] - 0.05), np.full(m, q), z0[rows] - 0.05,
                                       np.full(m, s1[-1] + 0.05), np.full(m, q), z1[rows] + 0.05, np.full(m, frame)]))
    col, row = np.meshgrid(np.arange(len(s0)), rows, indexing="ij")
    col, row = col.ravel(), row.ravel()
    n = len(col)
    lit = rng.random(n) < lit_rate
    u, part = rng.random(n), rng.uniform(0.15, 0.85, n)
    blind = 0.0 if shop else np.where(u < BLIND_CLOSED, 1.0, np.where(u < BLIND_CLOSED + BLIND_PARTIAL, part, 0.0))
    out.panes.append(np.column_stack([np.full(n, frame_j), s0[col] + inset, np.full(n, -depth), z0[row] + inset,
                                      s1[col] - inset, np.full(n, -depth), z1[row] - inset, np.full(n, glass), lit,
                                      np.broadcast_to(blind, (n,)), np.full(n, shop)]))
