"""Perception in the loop: what a detector sees in the rendered camera frame, ranged by the LiDAR, tracked.

:class:`Perception` runs a detector (anything with ``predict(list of RGB images) -> list of Detections``, as
:class:`pipeline.detect.onnx.OnnxDetector` and our baseline :class:`pipeline.detect.infer.Detector` have) on the
camera frame, and gives each detection a range and a bearing from the LiDAR points that project into its box: the
median of their positions in the ego frame (x forward, y left, origin at the ego's box centre), NaN where no point
falls in the box. Only points at a depth the box's height allows count (a range gate): a vehicle of its class's
typical height (:data:`TYPICAL_HEIGHT_M`) filling the box's height lies at the depth d = f_y H / h; points nearer than
``range_gate[0]`` d or farther than ``range_gate[1]`` d are another object's, the road's or the air's: in fog the
LiDAR's strongest return on a beam towards a car beyond its fog range is the droplets' echo a few metres ahead
(:mod:`pipeline.sensors.backscatter`), and without the gate such a box was ranged at 4 m. A box that touches the
image's top or bottom edge may show a nearer object cut by the frame, so it keeps the points nearer than its gate.
The gate is wide (0.4-2.5 d by default): it allows for boxes cut by occlusion and classes of other heights; ``None``
turns it off. Returns less than ``ground_clearance_m`` (0.3 m) above the road range no box (ground removal, as a
perception stack segments the ground before it ranges or clusters: a weak box on a road marking would otherwise be
ranged on the road); the road's height in the ego frame is a calibration of the rig (``ground_z_m``; in
:class:`PerceivedFeatures`, half the ego's height below its box centre). The tracker gets each object's centre:
the surfaces the LiDAR sees lie in front of it, so the median is moved half the class's typical length further
along the line of sight (:func:`centre_from_surface`); it tracks them in the world frame from the ego's pose.
:class:`PerceivedFeatures` wraps an environment rendering ``sensors=["camera", "lidar"]``: it adds
the detections to the observation and replaces the ground-truth neighbour slots with those of the
:mod:`pipeline.envs.tracker`'s tracks, so an agent written for features runs on perceived features unchanged (the
slots of a lane the ego cannot drive, which SUMO's ground truth has no lane for, stay empty: parked cars beside the
ego's lane are no right leaders); the ground truth moves to ``info["ground_truth"]``.

Observation entries added: ``detections`` (K, 6) float32 [x1, y1, x2, y2, score, category id] sorted by score,
``detections_mask`` (K,) int8, ``detection_range_m`` and ``detection_bearing_rad`` (K,) float32 (ego frame; 0 where
``detection_ranged`` (K,) int8 is 0: no LiDAR point fell in the box, or no detection). Only detections of the
categories in ``categories`` (default: COCO's car, bus, truck, motorcycle, bicycle) are kept, and only ranged ones
are tracked; :class:`PerceivedFeatures` keeps people too.

People are tracked apart from vehicles (a second :class:`pipeline.envs.tracker.Tracker`, :data:`PERSON_TRACKER`:
born at rest, confirmed after ``person_hits`` frames on end, so a single weak box on a pole does not stop the car),
from the ranged person detections scoring at least ``person_score``. :func:`perceived_path_row` fills the "path" row
(:func:`pipeline.envs.features.path_row`) from their tracks as the ground truth's row is filled from SUMO's people:
the nearest standing in the ego's path (the route's lanes, map knowledge) on the carriageway or a crossing, or
walking into it before the ego gets there. Where a person stands comes from the road geometry's map of sidewalks,
walking areas and crossings (:mod:`pipeline.envs.walkways`; the ground truth asks SUMO which lane a person is on):
people waiting on a corner beside a turning lane do not stop the car. A track's velocity counts only once it is
known: at least :data:`WALKING_MPS` and :data:`WALKING_SIGMAS` standard deviations of it in the filter, that deviation
small and the speed a walk's (a person just seen, one standing whose ranged place jitters, or a track that stepped
between two people standing close together, stands).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from pipeline.envs.features import NEIGHBOUR_SLOTS, PATH_FIELDS, path_row
from pipeline.envs.tracker import (
    Detections,
    EgoPose,
    Track,
    Tracker,
    TrackerParams,
    lane_frame_tracks,
    track_neighbour_rows,
)

ROAD_USER_CATEGORIES = (2, 3, 4, 6, 8)  # COCO: bicycle, car, motorcycle, bus, truck
PERSON_CATEGORY = 1  # COCO: person
# Typical (length, width) by COCO category, for tracks whose size the camera does not measure.
TYPICAL_SIZE_M = {1: (0.5, 0.5), 2: (1.8, 0.6), 3: (4.5, 1.8), 4: (2.1, 0.8), 6: (12.0, 2.55), 8: (8.0, 2.5)}
# Typical height (m) by COCO category, riders included, for the range gate (a box's height -> its depth).
TYPICAL_HEIGHT_M = {1: 1.7, 2: 1.7, 3: 1.5, 4: 1.4, 6: 3.0, 8: 3.0}
PERSON_SCORE = 0.3  # person detections this confident are tracked for the "path" row
PERSON_HITS = 2  # frames on end that confirm a person's track
# The people's tracker: a person walks at a steady pace (white-noise acceleration of 0.1 m^2/s^3 against a vehicle's
# 4) and is born standing, up to ~2 m/s either way (a brisk walk 1.5-2 m/s); associated by position alone (tracker.py).
PERSON_TRACKER = TrackerParams(accel_psd=0.1, birth_speed_std_mps=2.0, confirm_hits=PERSON_HITS, max_misses=3,
                               birth_with_ego=False, iou_gate=None, merge_overlap=None)
# A person's track walks (its velocity counts) at this speed or more and this many standard deviations of it.
# Simulated at 10 m (0.5 m of ranging noise, the tracker's model there; 20 seeds each): a walk at 1.4 m/s towards the
# path from 4 m beside it counts after a median 1.2 s (at most 1.6 s; it enters after 2.0 s), and a person standing
# 1 m beyond the corridor's edge walks into it, falsely, in 0.03 % of 4,000 frames (2 sigma: 0.4 %, after 0.85 s);
# with the limits below too, the same walk counts as early and the person standing never.
WALKING_MPS = 0.5
WALKING_SIGMAS = 3.0
# ... and only once the velocity is known to this standard deviation (a young track's is not), and up to a plausible
# walking speed: in the city by morning (urban seed 5) a track born among people standing 1-2 m apart on a corner
# took a step between two of them for a walk at 4.0 m/s (sigma 0.81 m/s) into the ego's path, and the reference
# driver braked hard for it 11 times in 30 s.
WALKING_SIGMA_MAX_MPS = 0.6
WALKING_MAX_MPS = 3.0
# ... and only where the track's places moved as its velocity says: over its last WALK_WINDOW places (1 s at 0.1 s
# steps) at least WALK_MOVED_SHARE of that speed. In the same city a box on a group of people standing on a corner,
# ranged now on one and now on another, gave a track 2.7 m/s (sigma 0.46 m/s, 9 hits) whose places moved 0.7 m/s.
WALK_WINDOW = 10
WALK_MOVED_SHARE = 0.5
RANGE_GATE = (0.4, 2.5)  # the LiDAR points that range a box lie at this share of the depth its height implies
# LiDAR returns lower than this above the road are the road's (ground removal): they range no box.
GROUND_CLEARANCE_M = 0.3
# A confirmed vehicle track the detector missed for up to this many frames on end is still reported while its
# predicted centre lies in the camera's image (PerceivedFeatures.coast_in_view); out of view it is not (tracker.py).
COAST_IN_VIEW = 2
CAR_MIDDLE_M = 0.75  # the height above the road at which a coasting track's centre is projected into the image


@dataclass(frozen=True)
class PerceivedFrame:
    """One frame's detections with their ranges (K of them, by descending score).

    Attributes:
        boxes_px: (K, 4) float64 x1, y1, x2, y2.
        scores: (K,) float64.
        category_ids: (K,) int64.
        position_m: (K, 2) float64 median (x, y) of the LiDAR points in the box, ego frame; NaN where none.
        points: (K,) int64 how many LiDAR points fell in each box (and its range gate).
    """

    boxes_px: np.ndarray
    scores: np.ndarray
    category_ids: np.ndarray
    position_m: np.ndarray
    points: np.ndarray

    @property
    def range_m(self) -> np.ndarray:
        return np.hypot(self.position_m[:, 0], self.position_m[:, 1])

    @property
    def bearing_rad(self) -> np.ndarray:
        return np.arctan2(self.position_m[:, 1], self.position_m[:, 0])


class Perception:
    """A detector on the camera frame, ranged by the LiDAR (see the module docstring).

    Args:
        detector: an object with ``predict(list of (H, W, 3) uint8 RGB) -> list of Detections`` (boxes, scores,
            category_ids).
        camera: the rig's :class:`pipeline.sensors.camera.Camera` the frames come from.
        lidar_mount: the LiDAR's pose in the ego frame (:attr:`pipeline.sensors.lidar.Lidar.mount`).
        categories: the COCO category ids kept (others are dropped, counted in :attr:`dropped`).
        range_gate: (near, far) shares of the depth a box's height implies between which its LiDAR points count, or
            None to count every point in the box (see the module docstring).
        ground_z_m: the road's height in the ego frame (minus half the ego's height: the frame's origin is its box
            centre), a calibration constant of the rig; points less than ``ground_clearance_m`` above it are the
            road's and range no box. None: no ground removal.
    """

    def __init__(self, detector, camera, lidar_mount, categories=ROAD_USER_CATEGORIES,
                 range_gate: tuple[float, float] | None = RANGE_GATE, ground_z_m: float | None = None,
                 ground_clearance_m: float = GROUND_CLEARANCE_M) -> None:
        from pipeline.core.geometry import Transform

        if range_gate is not None and not 0.0 <= range_gate[0] < range_gate[1]:
            raise ValueError(f"range_gate: expected (near, far) with 0 <= near < far, got {range_gate!r}")
        if not (np.isfinite(ground_clearance_m) and ground_clearance_m >= 0.0):
            raise ValueError(f"ground_clearance_m: expected a finite height >= 0, got {ground_clearance_m!r}")
        self.detector, self.camera = detector, camera
        self.lidar_mount, self.range_gate = lidar_mount, range_gate
        self.ground_z_m, self.ground_clearance_m = ground_z_m, float(ground_clearance_m)
        self.ego_to_camera = camera.camera_to_world(Transform.identity()).inverse()
        self.categories = np.array(sorted(categories), np.int64)
        self.dropped = 0

    def __call__(self, rgb: np.ndarray, lidar_xyz: np.ndarray, lidar_mask: np.ndarray) -> PerceivedFrame:
        """Detect in ``rgb`` and range each box with the (N, 3) LiDAR-frame points where ``lidar_mask``."""
        det = self.detector.predict([rgb])[0]
        boxes = np.asarray(det.boxes, np.float64).reshape(-1, 4)
        scores = np.asarray(det.scores, np.float64).reshape(-1)
        cats = np.asarray(det.category_ids, np.int64).reshape(-1)
        finite = np.isfinite(boxes).all(axis=1) & np.isfinite(scores)
        keep = finite & np.isin(cats, self.categories)
        self.dropped += int((~keep).sum())
        order = np.argsort(-scores[keep], kind="stable")
        boxes, scores, cats = boxes[keep][order], scores[keep][order], cats[keep][order]
        points_ego = self.lidar_mount.apply(np.asarray(lidar_xyz, np.float64)[np.asarray(lidar_mask) > 0])
        if self.ground_z_m is not None:
            points_ego = points_ego[points_ego[:, 2] >= self.ground_z_m + self.ground_clearance_m]
        points_cam = self.ego_to_camera.apply(points_ego)
        uv, in_front = self.camera.project(points_cam)
        position = np.full((len(boxes), 2), np.nan)
        counts = np.zeros(len(boxes), np.int64)
        near, far = self.gates(boxes, cats)
        for k, (x1, y1, x2, y2) in enumerate(boxes):  # one vectorised test per detection (tens of them)
            inside = in_front & (uv[:, 0] >= x1) & (uv[:, 0] < x2) & (uv[:, 1] >= y1) & (uv[:, 1] < y2)
            inside &= (points_cam[:, 2] >= near[k]) & (points_cam[:, 2] <= far[k])
            counts[k] = int(inside.sum())
            if counts[k]:
                position[k] = np.median(points_ego[inside, :2], axis=0)
        return PerceivedFrame(boxes, scores, cats, position, counts)

    def gates(self, boxes: np.ndarray, category_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K,) nearest and farthest camera depth (m) of the LiDAR points that range each of the (K, 4) boxes: the
        range gate around f_y x typical height / box height (0 and inf without a gate; 0 near a box that touches
        the image's top or bottom edge)."""
        k = len(boxes)
        if self.range_gate is None:
            return np.zeros(k), np.full(k, np.inf)
        height = np.array([TYPICAL_HEIGHT_M.get(int(c), 1.5) for c in category_ids], np.float64)
        depth = self.camera.fy * height / np.maximum(boxes[:, 3] - boxes[:, 1], 1.0)
        cut = (boxes[:, 1] <= 0.5) | (boxes[:, 3] >= self.camera.height - 0.5)
        return np.where(cut, 0.0, self.range_gate[0] * depth), self.range_gate[1] * depth


def centre_from_surface(position_m: np.ndarray, length_m: np.ndarray) -> np.ndarray:
    """(K, 2) estimated object centres from the (K, 2) median of the LiDAR points on the surfaces that face the
    sensor: half the object's (typical) length further along the line of sight, since on a road the vehicles around
    the ego mostly show it their front or back."""
    position_m = np.asarray(position_m, np.float64).reshape(-1, 2)
    norm = np.maximum(np.hypot(position_m[:, 0], position_m[:, 1]), 1e-6)
    return position_m + (0.5 * np.asarray(length_m, np.float64) / norm)[:, None] * position_m


class PerceivedFeatures(gym.Wrapper):
    """Neighbour features from perception instead of ground truth (see the module docstring).

    Args:
        env: a roadsynth env made with ``sensors`` including "camera" and "lidar".
        detector: as :class:`Perception`'s.
        tracker: the tracker's parameters (``dt_s`` is set to the env's step).
        max_detections: K, the rows of the ``detections`` observation.
        range_gate: as :class:`Perception`'s (None: every LiDAR point in a box ranges it).
        ground_clearance_m: LiDAR returns lower than this above the road are the road's and range no box (ground
            removal, as a perception stack segments the ground before it ranges or clusters; without it a weak
            detection on a road marking is ranged on the road and tracked); None or 0: no ground removal.
        person_score, person_hits: person detections scoring at least ``person_score`` are tracked; a track is
            confirmed, and can fill the "path" row, after ``person_hits`` frames on end (module docstring).

    ``observed_slots``: the neighbour slots this perception can fill at all. One front camera sees the leaders of
    the three lanes, never the followers: their slots stay empty whatever is behind, and an agent must not read
    an empty follower slot as an empty lane (:class:`pipeline.envs.driver.ReferenceAgent` does not change lanes
    into a lane it cannot see behind).
    """

    observed_slots = ("left_leader", "leader", "right_leader")

    def __init__(self, env: gym.Env, detector, *, tracker: TrackerParams | None = None,
                 max_detections: int = 32, range_gate: tuple[float, float] | None = RANGE_GATE,
                 ground_clearance_m: float | None = GROUND_CLEARANCE_M, person_score: float = PERSON_SCORE,
                 person_hits: int = PERSON_HITS, coast_in_view: int = COAST_IN_VIEW) -> None:
        super().__init__(env)
        inner = env.unwrapped
        live = getattr(inner, "sensors", None)
        if live is None or not live.cameras or not live.lidars:
            raise ValueError('PerceivedFeatures needs an env made with sensors=["camera", "lidar"]')
        if not isinstance(max_detections, int) or max_detections < 1:
            raise ValueError(f"max_detections: expected an integer >= 1, got {max_detections!r}")
        if not (isinstance(person_score, (int, float)) and 0.0 <= person_score <= 1.0):
            raise ValueError(f"person_score: expected a score in [0, 1], got {person_score!r}")
        if isinstance(person_hits, bool) or not isinstance(person_hits, int) or person_hits < 1:
            raise ValueError(f"person_hits: expected an integer >= 1, got {person_hits!r}")
        if isinstance(coast_in_view, bool) or not isinstance(coast_in_view, int) or coast_in_view < 0:
            raise ValueError(f"coast_in_view: expected an integer >= 0, got {coast_in_view!r}")
        self.coast_in_view = coast_in_view
        self.perception = Perception(detector, live.cameras[0], live.lidars[0].mount,
                                     categories=(PERSON_CATEGORY, *ROAD_USER_CATEGORIES), range_gate=range_gate,
                                     ground_clearance_m=ground_clearance_m or 0.0)
        self.person_score, self.person_hits = float(person_score), person_hits
        self._places = RecentPlaces()
        self.people = Tracker(TrackerParams(**{**PERSON_TRACKER.__dict__, "dt_s": inner.sim.step_length_s,
                                               "confirm_hits": person_hits}))
        self.ground_removal = bool(ground_clearance_m)
        params = tracker if tracker is not None else TrackerParams()
        self.tracker = Tracker(TrackerParams(**{**params.__dict__, "dt_s": inner.sim.step_length_s}))
        self.k = max_detections
        k = max_detections
        self.observation_space = spaces.Dict({
            **env.observation_space.spaces,
            "detections": spaces.Box(-np.inf, np.inf, (k, 6), np.float32),
            "detections_mask": spaces.MultiBinary(k),
            "detection_range_m": spaces.Box(-np.inf, np.inf, (k,), np.float32),
            "detection_bearing_rad": spaces.Box(-np.pi, np.pi, (k,), np.float32),
            "detection_ranged": spaces.MultiBinary(k),
        })

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.tracker.reset()
        self.people.reset()
        self._places.clear()
        # The road lies half the ego's height below its frame's origin (the rig's calibration to the ground).
        self.perception.ground_z_m = -0.5 * self.env.unwrapped.ego_height_m() if self.ground_removal else None
        return self._perceive(obs, info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        obs, info = self._perceive(obs, info)
        return obs, reward, terminated, truncated, info

    def _perceive(self, obs: dict, info: dict) -> tuple[dict, dict]:
        frame = self.perception(obs["camera"], obs["lidar"][:, :3], obs["lidar_mask"])
        ranged = np.isfinite(frame.position_m).all(axis=1)
        person = frame.category_ids == PERSON_CATEGORY
        heading, speed = float(obs["ego"][4]), float(obs["ego"][0])
        inner = self.env.unwrapped
        pose = EgoPose.moving(*inner.ego_pose(), speed)  # the tracks live in the world frame (tracker.py)
        sizes = np.array([TYPICAL_SIZE_M.get(int(c), (4.5, 1.8)) for c in frame.category_ids],
                         np.float64).reshape(-1, 2)
        centres = centre_from_surface(frame.position_m, sizes[:, 0])
        vehicles = ranged & ~person
        tracks = self.tracker.update(Detections(centres[vehicles], frame.boxes_px[vehicles],
                                                frame.category_ids[vehicles], sizes[vehicles],
                                                frame.scores[vehicles]), pose)
        tracks = sorted([*tracks, *self._coasting_in_view(pose)], key=lambda t: t.track_id)
        space = inner.observation_space["neighbours"]
        rows = track_neighbour_rows(lane_frame_tracks(tracks, pose, heading, speed), float(obs["ego"][3]),
                                    inner.lane_width_m(), float(space.high[0, 1]))
        lane = round(float(obs["ego"][2]))
        for side, step in (("left", 1), ("right", -1)):
            if not inner.lane_drivable(lane + step):  # map knowledge: no lane there (parking, kerb, oncoming)
                rows[[NEIGHBOUR_SLOTS.index(f"{side}_{role}") for role in ("leader", "follower")]] = 0.0
        out = dict(obs)
        info = {**info, "ground_truth": {"neighbours": obs["neighbours"], "path": obs["path"]}, "tracks": len(tracks)}
        out["neighbours"] = np.clip(rows, space.low, space.high).astype(np.float32)
        people = ranged & person & (frame.scores >= self.person_score)
        person_tracks = self.people.update(Detections(centres[people], frame.boxes_px[people],
                                                      frame.category_ids[people], sizes[people]), pose)
        info["person_tracks"] = len(person_tracks)
        row = perceived_path_row(person_tracks, inner.path_xy(), 0.5 * inner.ego_width_m(), speed, inner.on_road,
                                 self._places.moved_mps(person_tracks, inner.sim.step_length_s))
        path_space = inner.observation_space["path"]
        out["path"] = np.clip(row, path_space.low, path_space.high).astype(np.float32)
        n = min(len(frame.scores), self.k)
        detections = np.zeros((self.k, 6), np.float32)
        detections[:n] = np.column_stack([frame.boxes_px, frame.scores, frame.category_ids])[:n]
        out["detections"] = detections
        out["detections_mask"] = (np.arange(self.k) < n).astype(np.int8)
        rng, bearing = np.zeros(self.k, np.float32), np.zeros(self.k, np.float32)
        ranged_k = np.zeros(self.k, np.int8)
        ranged_k[:n] = ranged[:n]
        rng[:n] = np.where(ranged[:n], frame.range_m[:n], 0.0)
        bearing[:n] = np.where(ranged[:n], frame.bearing_rad[:n], 0.0)
        out["detection_range_m"], out["detection_bearing_rad"], out["detection_ranged"] = rng, bearing, ranged_k
        return out, info


    def _coasting_in_view(self, pose: EgoPose) -> list[Track]:
        """The confirmed vehicle tracks the tracker does not report that missed at most ``coast_in_view`` frames on
        end and whose predicted centre, at the height of a car's middle, lies in the camera's image."""
        reported = self.tracker.params.report_misses
        coasting = [t for t in self.tracker.tracks if t.confirmed and reported < t.misses <= self.coast_in_view]
        if not coasting:
            return []
        c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        dx = np.array([t.x[0] - pose.x_m for t in coasting])
        dy = np.array([t.x[1] - pose.y_m for t in coasting])
        middle = CAR_MIDDLE_M - 0.5 * self.env.unwrapped.ego_height_m()  # the road lies half the ego's height below
        ego = np.column_stack([c * dx + s * dy, -s * dx + c * dy, np.full(len(coasting), middle)])
        uv, in_front = self.perception.camera.project(self.perception.ego_to_camera.apply(ego))
        camera = self.perception.camera
        with np.errstate(invalid="ignore"):
            inside = (in_front & (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0)
                      & (uv[:, 1] < camera.height))
        return [t for t, keep in zip(coasting, inside, strict=True) if keep]


class RecentPlaces:
    """Each person track's last :data:`WALK_WINDOW` reported places, for :func:`perceived_path_row`'s ``moved_mps``."""

    def __init__(self) -> None:
        self._places: dict[int, list[np.ndarray]] = {}

    def clear(self) -> None:
        self._places.clear()

    def moved_mps(self, tracks: list[Track], dt_s: float) -> np.ndarray:
        """Record this step's reported tracks; (M,) each one's net displacement over its recent places per second (0
        with one place). Tracks no longer reported are forgotten."""
        self._places = {t.track_id: [*self._places.get(t.track_id, []), t.x[:2].copy()][-WALK_WINDOW:]
                        for t in tracks}
        moved = np.zeros(len(tracks))
        for k, t in enumerate(tracks):
            seen = self._places[t.track_id]
            if len(seen) > 1:
                moved[k] = float(np.hypot(*(seen[-1] - seen[0]))) / ((len(seen) - 1) * dt_s)
        return moved


def perceived_path_row(tracks: list[Track], path_xy: np.ndarray, half_width_m: float, ego_speed_mps: float,
                       on_road, moved_mps: np.ndarray | None = None) -> np.ndarray:
    """The perceived "path" row (features.PATH_FIELDS) from the people's confirmed tracks (fixed-frame places and
    velocities, listed by id): :func:`pipeline.envs.features.path_row` with ``on_road(xy) -> (M,) bool`` the map
    test of where each stands, and each track's velocity only where it walks: at least :data:`WALKING_MPS` and
    :data:`WALKING_SIGMAS` standard deviations of its velocity along its most uncertain axis, that deviation at most
    :data:`WALKING_SIGMA_MAX_MPS`, at most :data:`WALKING_MAX_MPS`, and where ``moved_mps`` ((M,): each track's
    net displacement over its recent places per second; None: not checked) is at least :data:`WALK_MOVED_SHARE` of
    that speed (zero otherwise: standing)."""
    if not tracks:
        return np.zeros(len(PATH_FIELDS), np.float32)
    xy = np.array([t.x[:2] for t in tracks], np.float64)
    velocity = np.array([t.x[2:] for t in tracks], np.float64)
    sigma = np.array([math.sqrt(max(float(np.linalg.eigvalsh(t.p[2:, 2:])[-1]), 0.0)) for t in tracks])
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    walking = ((speed >= WALKING_MPS) & (speed >= WALKING_SIGMAS * sigma) & (sigma <= WALKING_SIGMA_MAX_MPS)
               & (speed <= WALKING_MAX_MPS))
    if moved_mps is not None:
        walking &= np.asarray(moved_mps, np.float64) >= WALK_MOVED_SHARE * speed
    velocity[~walking] = 0.0
    return path_row(path_xy, xy, velocity, ego_speed_mps, half_width_m, on_road=on_road(xy))


def detector_from(spec):
    """A detector from ``spec``: an ``.onnx`` file (:class:`pipeline.detect.onnx.OnnxDetector`, any model ``roadsynth
    detect --onnx`` runs), a model folder ``roadsynth train`` wrote (:class:`pipeline.detect.infer.Detector`), or an
    object that has ``predict`` already."""
    if hasattr(spec, "predict"):
        return spec
    from pathlib import Path

    path = Path(spec)
    if path.is_dir():
        from pipeline.detect.infer import Detector

        return Detector.load(path)
    if path.suffix == ".onnx" and path.is_file():
        from pipeline.detect.onnx import OnnxDetector

        return OnnxDetector(path, batch_size=1)
    raise ValueError(f"perception: {spec!r} is neither an ONNX file, a model folder `roadsynth train` wrote, nor a "
                     "detector object with predict()")


def make_env(scenario=None, *, perception=None, max_detections: int = 32, tracker: TrackerParams | None = None,
             range_gate: tuple[float, float] | None = RANGE_GATE, ground_clearance_m: float | None = GROUND_CLEARANCE_M,
             sensors=None, **kwargs) -> gym.Env:
    """The registered envs' entry point: a :class:`pipeline.envs.RoadsynthEnv`, wrapped in
    :class:`PerceivedFeatures` when ``perception`` names a detector (see :func:`detector_from`; the camera and LiDAR
    are then rendered whatever ``sensors`` says)."""
    from pipeline.envs.env import RoadsynthEnv

    if scenario is None:
        raise TypeError("roadsynth/Scenario-v0 needs scenario=NAME (configs/scenarios/) or a YAML PATH")
    if perception is None:
        return RoadsynthEnv(scenario, sensors=sensors, **kwargs)
    detector = detector_from(perception)
    sensors = tuple(dict.fromkeys([*(sensors or ()), "camera", "lidar"]))
    return PerceivedFeatures(RoadsynthEnv(scenario, sensors=sensors, **kwargs), detector, tracker=tracker,
                             max_detections=max_detections, range_gate=range_gate,
                             ground_clearance_m=ground_clearance_m)
