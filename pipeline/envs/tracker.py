"""A small multi-object tracker for perceived road users, in the ego's lane frame (issue 42's perception loop).

It turns per-frame detections (a position in the ego's lane frame, from a detector's box and the LiDAR points in
it, with the image box when there is one) into tracks with a velocity, and the tracks into the feature rows an
agent reads (:func:`track_neighbour_rows`, the six slots of :mod:`pipeline.envs.features`).

- **Frame**: tracks live in a fixed frame (a localisation's odometry frame; the world's in the env), so that the
  ego's own turning does not move them. Each frame's detections come in the ego's frame (x forward, y left, origin
  at its box centre) with the ego's pose there (:class:`EgoPose`), which places them in the fixed frame; the
  agent's rows are read back in the ego's lane frame (:func:`lane_frame_tracks`). Tracked in the ego's own frame
  instead, a parked car 20 m ahead of an ego turning at 0.5 rad/s through a junction sweeps sideways at 10 m/s,
  which a constant-velocity model takes for the car's motion (and the lane frame's heading jumps where the ego
  passes from a lane into a junction). Without a pose the detections' frame is taken as fixed.
- **State** per track: x = (x, y, vx, vy), the object's centre and velocity in the fixed frame. Constant-velocity
  Kalman filter: F = [[I, dt I], [0, I]]; process noise from white-noise acceleration of spectral density
  ``accel_psd`` (m^2/s^3), Q = q [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]]; a measurement is the position, H = [I 0],
  with standard deviations growing with the range from the ego (a LiDAR median over a box: ``sigma_m`` +
  ``sigma_per_m`` x range, along and across alike).
- **Association**, each frame: predicted tracks against detections by the Hungarian method
  (:func:`scipy.optimize.linear_sum_assignment`) on a cost that is the smaller of 1 - IoU of the image boxes (where
  both have one) and the squared Mahalanobis distance of the position over the gate (chi-square, 2 degrees of
  freedom, ``gate_probability``); a pair inside neither gate cannot be matched. ``iou_gate`` None: positions only
  (people: a person's box cut to a sliver by an occluder keeps most of its IoU with the last one while the LiDAR
  ranges it on the background 20 m behind, and a match by the box would move the track there).
- **Validation gate**: a detection matched by its box alone, its position outside the position gate, is the same
  object ranged on something else (the LiDAR median of a small box on a far car's lamps, or of a box holding two
  cars); it corrects nothing. A confirmed track takes its box and coasts (a miss: after ``max_misses`` of them the
  next such detection ends it and starts a track where the LiDAR now puts it); a tentative track is dropped and the
  detection starts a track of its own, so that a track confirms on ``confirm_hits`` consistent positions. Corrected
  by such a range instead, a track on a car 38 m ahead on the highway at night moved 9 m in 0.1 s and reported the
  car closing at 100 m/s, and the reference driver braked hard for it (highway seed 1).
- **Confident and weak detections** (``birth_score``, 0 by default: every detection is confident), as ByteTrack
  does (Zhang et al., "ByteTrack: Multi-Object Tracking by Associating Every Detection Box", ECCV 2022): the tracks
  are first associated with the detections scoring at least ``birth_score``, then the tracks left over with the
  weaker ones; only a confident detection left over starts a track. A weak detection can keep a track alive (a car
  that fades into the dark or the fog) but never start one (glare, a far lamp, a shadow).
- **Duplicates** (``merge_overlap``): a detector may box one car twice (the whole car and a part of it, scoring
  too differently for its non-maximum suppression), and both boxes are ranged on the same car. Of two confirmed
  tracks at one place (each inside the other's position gate) whose image boxes overlap by at least
  ``merge_overlap`` of the smaller one, the one with fewer hits is dropped (None: never; people standing in a group
  are at one place and in each other's boxes). Two tracks on one leader took its slot in turns on the highway by
  morning, one of them closing at 6 m/s where the car was drawing away (highway seed 1).
- **Births and deaths**: an unmatched confident detection starts a tentative track (moving as the ego does, or at
  rest with ``birth_with_ego`` False, as for people; with the uncertainty of ``birth_speed_std_mps``); it is
  confirmed after ``confirm_hits`` consecutive hits and dropped at its first miss before that; a confirmed track
  coasts on its prediction through up to ``max_misses`` consecutive misses and is dropped at the next. Only
  confirmed tracks are reported, so a detection that appears once never becomes one, and, as SORT reports them
  (Bewley et al., "Simple Online and Realtime Tracking", ICIP 2016), only while they have missed at most
  ``report_misses`` frames (0: matched in this one): a coasting track can take its object back, but its prediction
  is not reported as a road user. In the city a parked car passed close by coasts out of the camera's view on a
  velocity its last, cut-off boxes gave it, and reported, drifted into the ego's lane as a leader closing at 10-40
  m/s.

Deterministic: track ids count up from 1 in the order tracks are born (detections in input order), and ties in
the assignment resolve as scipy's solver does for a given matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pipeline.envs.checks import check_number
from pipeline.envs.features import NEIGHBOUR_FIELDS, NEIGHBOUR_SLOTS

UNMATCHABLE = 1e6  # cost of a pair outside both gates (the solver needs finite costs)


@dataclass(frozen=True)
class TrackerParams:
    """The tracker's parameters (see the module docstring)."""

    dt_s: float = 0.1
    accel_psd: float = 4.0
    sigma_m: float = 0.3
    sigma_per_m: float = 0.02
    birth_speed_std_mps: float = 15.0
    gate_probability: float = 0.99
    iou_gate: float | None = 0.1
    confirm_hits: int = 3
    max_misses: int = 5
    report_misses: int = 0
    birth_score: float = 0.0
    birth_with_ego: bool = True
    merge_overlap: float | None = 0.7

    def __post_init__(self) -> None:
        for name in ("dt_s", "accel_psd", "sigma_m", "birth_speed_std_mps"):
            check_number("TrackerParams", name, getattr(self, name))
        check_number("TrackerParams", "sigma_per_m", self.sigma_per_m, allow_low=True)
        check_number("TrackerParams", "gate_probability", self.gate_probability, high=1.0, allow_high=False)
        if self.iou_gate is not None:
            check_number("TrackerParams", "iou_gate", self.iou_gate, high=1.0)
        if self.merge_overlap is not None:
            check_number("TrackerParams", "merge_overlap", self.merge_overlap, high=1.0)
        check_number("TrackerParams", "birth_score", self.birth_score, high=1.0, allow_low=True)
        if not isinstance(self.birth_with_ego, bool):
            raise ValueError(f"TrackerParams.birth_with_ego: expected True or False, got {self.birth_with_ego!r}")
        for name, least in (("confirm_hits", 1), ("max_misses", 0), ("report_misses", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < least:
                raise ValueError(f"TrackerParams.{name}: expected an integer >= {least}, got {value!r}")

    @property
    def gate(self) -> float:
        """The squared Mahalanobis distance inside which a position may match (chi-square, 2 dof)."""
        return -2.0 * math.log(1.0 - self.gate_probability)


@dataclass(frozen=True)
class Detections:
    """One frame's detections, K of them.

    Attributes:
        position_m: (K, 2) float64 each object's centre in the ego's frame (x forward, y left, from its box centre;
            :meth:`Tracker.update` places them in the fixed frame by the ego's pose).
        box_px: (K, 4) float64 image boxes x1, y1, x2, y2; NaN rows where a detection has none.
        class_id: (K,) int64 category ids.
        size_m: (K, 2) float64 (length, width) of each object (its class's typical size when not measured).
        score: (K,) float64 the detector's scores, or None (every detection confident; see ``birth_score``).
    """

    position_m: np.ndarray
    box_px: np.ndarray
    class_id: np.ndarray
    size_m: np.ndarray
    score: np.ndarray | None = None

    @classmethod
    def empty(cls) -> Detections:
        return cls(np.zeros((0, 2)), np.zeros((0, 4)), np.zeros(0, np.int64), np.zeros((0, 2)))

    def __post_init__(self) -> None:
        k = len(self.position_m)
        shapes = [("position_m", (k, 2)), ("box_px", (k, 4)), ("class_id", (k,)), ("size_m", (k, 2))]
        for name, shape in shapes + ([("score", (k,))] if self.score is not None else []):
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"Detections.{name}: expected shape {shape}, got {np.shape(getattr(self, name))}")
        if not np.isfinite(self.position_m).all():
            raise ValueError("Detections.position_m: expected finite positions (drop detections without a range)")


@dataclass(frozen=True)
class EgoPose:
    """The ego in the tracker's fixed frame: its box centre (``x_m``, ``y_m``), heading ``yaw_rad`` (CCW from +x)
    and velocity (``vx_mps``, ``vy_mps``). The default is the fixed frame itself, at rest."""

    x_m: float = 0.0
    y_m: float = 0.0
    yaw_rad: float = 0.0
    vx_mps: float = 0.0
    vy_mps: float = 0.0

    @classmethod
    def moving(cls, x_m: float, y_m: float, yaw_rad: float, speed_mps: float) -> EgoPose:
        """A pose whose velocity is ``speed_mps`` along its heading."""
        return cls(x_m, y_m, yaw_rad, speed_mps * math.cos(yaw_rad), speed_mps * math.sin(yaw_rad))

    def to_fixed(self, position_m: np.ndarray) -> np.ndarray:
        """(K, 2) ego-frame positions -> (K, 2) fixed-frame ones."""
        position_m = np.asarray(position_m, np.float64).reshape(-1, 2)
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.column_stack([self.x_m + c * position_m[:, 0] - s * position_m[:, 1],
                                self.y_m + s * position_m[:, 0] + c * position_m[:, 1]])


@dataclass
class Track:
    """One track: Kalman state ``x`` (4,) = (x, y, vx, vy) in the fixed frame and covariance ``p`` (4, 4), the last
    image box, class and size, and its hit and miss counts. :func:`lane_frame_tracks` gives it as (ds, dd, dvs,
    dvd) relative to the ego."""

    track_id: int
    x: np.ndarray
    p: np.ndarray
    box_px: np.ndarray
    class_id: int
    size_m: np.ndarray
    hits: int = 1
    misses: int = 0
    confirmed: bool = False


def box_iou(a: np.ndarray, b: np.ndarray, over: str = "union") -> np.ndarray:
    """(A, B) IoU of (A, 4) and (B, 4) x1, y1, x2, y2 boxes; NaN boxes give 0. ``over`` "smaller": the intersection
    over the smaller box's area instead (1 for a box inside another)."""
    a = np.asarray(a, np.float64)[:, None, :]
    b = np.asarray(b, np.float64)[None, :, :]
    w = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]), 0, None)
    h = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]), 0, None)
    inter = w * h
    area_a = (a[..., 2] - a[..., 0]) * (a[..., 3] - a[..., 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    if over not in ("union", "smaller"):
        raise ValueError(f"box_iou: over: expected 'union' or 'smaller', got {over!r}")
    denominator = area_a + area_b - inter if over == "union" else np.minimum(area_a, area_b)
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where(denominator > 0, inter / denominator, 0.0)
    return np.nan_to_num(iou, nan=0.0)


@dataclass
class Tracker:
    """Tracks road users from frame to frame (see the module docstring). Call :meth:`update` once per frame with
    that frame's :class:`Detections`; it returns the tracks to report (confirmed, and missed at most
    ``report_misses`` times)."""

    params: TrackerParams = field(default_factory=TrackerParams)
    tracks: list[Track] = field(default_factory=list)
    next_id: int = 1

    def reset(self) -> None:
        self.tracks, self.next_id = [], 1

    def _matrices(self) -> tuple[np.ndarray, np.ndarray]:
        dt, q = self.params.dt_s, self.params.accel_psd
        f = np.eye(4)
        f[0, 2] = f[1, 3] = dt
        i2 = np.eye(2)
        qm = q * np.block([[dt ** 3 / 3 * i2, dt ** 2 / 2 * i2], [dt ** 2 / 2 * i2, dt * i2]])
        return f, qm

    def _measurement_cov(self, range_m: float) -> np.ndarray:
        sigma = self.params.sigma_m + self.params.sigma_per_m * range_m
        return np.eye(2) * sigma ** 2

    def predict(self) -> None:
        """Move every track one step ahead."""
        f, q = self._matrices()
        for t in self.tracks:
            t.x = f @ t.x
            t.p = f @ t.p @ f.T + q

    def _costs(self, det: Detections, fixed: np.ndarray, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(T, K) association costs and whether each pair's position lies inside the position gate."""
        costs = np.full((len(self.tracks), len(fixed)), UNMATCHABLE)
        consistent = np.zeros(costs.shape, bool)
        if not len(self.tracks) or not len(fixed):
            return costs, consistent
        iou_gate = self.params.iou_gate
        ious = box_iou(np.array([t.box_px for t in self.tracks]), det.box_px) if iou_gate is not None else None
        gate = self.params.gate
        for i, t in enumerate(self.tracks):
            for j, z in enumerate(fixed):
                s = t.p[:2, :2] + self._measurement_cov(ranges[j])
                r = z - t.x[:2]
                d2 = float(r @ np.linalg.solve(s, r))
                options = []
                if d2 < gate:
                    options.append(d2 / gate)
                    consistent[i, j] = True
                if ious is not None and ious[i, j] >= iou_gate:
                    options.append(1.0 - ious[i, j])
                if options:
                    costs[i, j] = min(options)
        return costs, consistent

    def update(self, det: Detections, pose: EgoPose | None = None) -> list[Track]:
        """Predict, associate (confident detections first, then the weak ones with the tracks left over), correct,
        and manage births and deaths; returns the confirmed tracks missed at most ``report_misses`` times (by id).
        ``pose``: the ego's in the fixed frame at this frame (None: the detections' frame is the fixed one, the ego at
        rest at its origin)."""
        self.predict()
        ranges = np.hypot(det.position_m[:, 0], det.position_m[:, 1])
        fixed = det.position_m if pose is None else pose.to_fixed(det.position_m)
        pose = pose or EgoPose()
        costs, consistent = self._costs(det, fixed, ranges)
        k = len(det.position_m)
        confident = (np.ones(k, bool) if det.score is None
                     else np.asarray(det.score, np.float64) >= self.params.birth_score)
        matched_tracks, matched_dets, dropped = set(), set(), set()
        for dets in (np.flatnonzero(confident), np.flatnonzero(~confident)):
            rows = [i for i in range(len(self.tracks)) if i not in matched_tracks]
            for i, j in self._assign(costs, rows, dets):
                matched_tracks.add(i)
                if consistent[i, j]:
                    self._correct(self.tracks[i], det, j, fixed[j], ranges[j])
                    matched_dets.add(j)
                elif self.tracks[i].confirmed and self.tracks[i].misses < self.params.max_misses:
                    # the same object by its box, its range an outlier: the track coasts
                    self.tracks[i].box_px = det.box_px[j].copy()
                    self.tracks[i].misses += 1
                    matched_dets.add(j)
                else:  # a tentative track confirms on consistent positions only: the detection starts anew
                    dropped.add(i)
        kept = []
        for i, t in enumerate(self.tracks):
            if i in dropped:
                continue
            if i not in matched_tracks:
                t.misses += 1
                if not t.confirmed:
                    continue
            if t.misses > self.params.max_misses:
                continue
            kept.append(t)
        for j in range(k):
            if j not in matched_dets and confident[j]:
                kept.append(self._birth(det, j, fixed[j], ranges[j], pose))
        self.tracks = self._merged(kept)
        return sorted((t for t in self.tracks if t.confirmed and t.misses <= self.params.report_misses),
                      key=lambda t: t.track_id)

    def _merged(self, tracks: list[Track]) -> list[Track]:
        """``tracks`` less the confirmed duplicates (``merge_overlap``): of two confirmed tracks at one place (each
        inside the other's position gate, the two covariances summed) whose image boxes overlap by at least
        ``merge_overlap`` of the smaller one, the one with fewer hits (the younger on a tie) is dropped."""
        if self.params.merge_overlap is None:
            return tracks
        confirmed = [t for t in tracks if t.confirmed]
        if len(confirmed) < 2:
            return tracks
        overlap = box_iou(np.array([t.box_px for t in confirmed]), np.array([t.box_px for t in confirmed]),
                          over="smaller")
        gone: set[int] = set()
        ranked = sorted(range(len(confirmed)), key=lambda i: (-confirmed[i].hits, confirmed[i].track_id))
        for a_rank, a in enumerate(ranked):
            if confirmed[a].track_id in gone:
                continue
            for b in ranked[a_rank + 1:]:
                if confirmed[b].track_id in gone or overlap[a, b] < self.params.merge_overlap:
                    continue
                r = confirmed[b].x[:2] - confirmed[a].x[:2]
                s = confirmed[a].p[:2, :2] + confirmed[b].p[:2, :2]
                if float(r @ np.linalg.solve(s, r)) < self.params.gate:
                    gone.add(confirmed[b].track_id)
        return [t for t in tracks if t.track_id not in gone]

    @staticmethod
    def _assign(costs: np.ndarray, rows: list[int], cols: np.ndarray) -> list[tuple[int, int]]:
        """The minimum-cost pairs (track, detection) of ``costs`` restricted to ``rows`` x ``cols``, less those
        outside both gates (Hungarian method)."""
        from scipy.optimize import linear_sum_assignment

        if not len(rows) or not len(cols):
            return []
        sub = costs[np.ix_(rows, cols)]
        found = linear_sum_assignment(sub)
        return [(rows[a], int(cols[b])) for a, b in zip(*found, strict=True) if sub[a, b] < UNMATCHABLE]

    def _correct(self, t: Track, det: Detections, j: int, z: np.ndarray, range_m: float) -> None:
        h = np.zeros((2, 4))
        h[0, 0] = h[1, 1] = 1.0
        s = h @ t.p @ h.T + self._measurement_cov(range_m)
        k = t.p @ h.T @ np.linalg.inv(s)
        t.x = t.x + k @ (z - h @ t.x)
        t.p = (np.eye(4) - k @ h) @ t.p
        t.box_px, t.class_id, t.size_m = det.box_px[j].copy(), int(det.class_id[j]), det.size_m[j].copy()
        t.hits += 1
        t.misses = 0
        if t.hits >= self.params.confirm_hits:
            t.confirmed = True

    def _birth(self, det: Detections, j: int, z: np.ndarray, range_m: float, pose: EgoPose) -> Track:
        p = np.zeros((4, 4))
        p[:2, :2] = self._measurement_cov(range_m)
        p[2, 2] = p[3, 3] = self.params.birth_speed_std_mps ** 2
        # Until measured, a road user ahead moves as the ego does (in its frame: at rest), the likeliest for traffic;
        # a person (birth_with_ego False) stands.
        v = (pose.vx_mps, pose.vy_mps) if self.params.birth_with_ego else (0.0, 0.0)
        track = Track(self.next_id, np.array([z[0], z[1], *v]), p, det.box_px[j].copy(),
                      int(det.class_id[j]), det.size_m[j].copy(), confirmed=self.params.confirm_hits <= 1)
        self.next_id += 1
        return track


def lane_frame_tracks(tracks: list[Track], pose: EgoPose, heading_rel_rad: float, speed_mps: float
                      ) -> list[Track]:
    """The tracks relative to the ego, in its lane frame: each a copy whose state is (ds along the lane, dd to its
    left, dvs, dvd), for an ego at ``pose`` whose heading is ``heading_rel_rad`` from its lane's (CCW) and whose
    speed is ``speed_mps``. dvs is the object's velocity along the lane less the ego's speed (the ground-truth
    features' dv, :func:`pipeline.envs.features.neighbour_rows`), dvd its velocity across the lane less the ego's."""
    lane = pose.yaw_rad - heading_rel_rad
    c, s = math.cos(lane), math.sin(lane)
    ego_across = -s * pose.vx_mps + c * pose.vy_mps
    out = []
    for t in tracks:
        dx, dy, vx, vy = t.x[0] - pose.x_m, t.x[1] - pose.y_m, t.x[2], t.x[3]
        x = np.array([c * dx + s * dy, -s * dx + c * dy, c * vx + s * vy - speed_mps, -s * vx + c * vy - ego_across])
        out.append(Track(t.track_id, x, t.p, t.box_px, t.class_id, t.size_m, t.hits, t.misses, t.confirmed))
    return out


def track_neighbour_rows(tracks: list[Track], ego_lateral_offset_m: float, lane_width_m: float,
                   range_m: float) -> np.ndarray:
    """(6, 6) float32 rows in NEIGHBOUR_SLOTS x NEIGHBOUR_FIELDS order from tracks in the ego's lane frame
    (:func:`lane_frame_tracks`), as the ground-truth observation
    gives them: each track's lane relative to the ego's is round((ego offset + dd) / lane width) (0 same lane, +1
    left, -1 right), the nearest ahead (ds > 0) and behind of each lane fill the slots; ds, dd and the velocity
    along the lane (dv) come from the track's state, length and width from its detection. Tracks beyond
    ``range_m`` or two lanes away are left out; absent rows are zeros."""
    if not lane_width_m > 0:
        raise ValueError(f"lane_width_m: expected a number > 0, got {lane_width_m!r}")
    rows = np.zeros((len(NEIGHBOUR_SLOTS), len(NEIGHBOUR_FIELDS)), np.float64)
    best: dict[str, tuple[float, Track]] = {}
    for t in tracks:
        ds, dd = float(t.x[0]), float(t.x[1])
        if abs(ds) > range_m:
            continue
        lane = round((ego_lateral_offset_m + dd) / lane_width_m)
        if abs(lane) > 1:
            continue
        side = {1: "left_", 0: "", -1: "right_"}[lane]
        slot = side + ("leader" if ds > 0 else "follower")
        if slot not in best or abs(ds) < best[slot][0]:
            best[slot] = (abs(ds), t)
    for slot, (_, t) in best.items():
        rows[NEIGHBOUR_SLOTS.index(slot)] = (1.0, t.x[0], t.x[1], t.x[2], t.size_m[0], t.size_m[1])
    return rows.astype(np.float32)
