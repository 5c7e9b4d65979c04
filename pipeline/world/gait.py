"""The human walk cycle: joint angles as functions of the gait phase, poses sampled at a few phases, and the phase of
each person in each frame from the distance they walked.

Frame and conventions as :mod:`pipeline.world.figures` (metres, x forward, y left, z up, ground at z = 0, a
stature of :data:`MODEL_STATURE_M`); the pelvis is at x = y = 0 in every pose, so a pose's offset from the
trajectory point is its own (:attr:`pipeline.world.actors.ActorMeshes.model_low`).

Phase 0 is the left heel's strike; the right leg runs half a cycle behind. The sagittal joint angles follow the
shape of the normative curves of level walking at a natural cadence (Winter, "The Biomechanics and Motor Control of
Human Gait", 2nd ed., 1991; Perry & Burnfield, "Gait Analysis", 2nd ed., 2010, ch. 4-6): the thigh swings from about
20 deg forward at heel strike to about 12 deg back at 50 % of the cycle; the knee flexes about 15 deg in loading
(15 %), straightens by 40 %, and flexes to about 60 deg in early swing (72 %); toe-off at 60 %; the arms swing
opposite to the legs, about 15 deg each way, the elbow bending as the arm comes forward. The pelvis height follows
from the stance leg on the ground, so the torso bobs twice per cycle (4-5 cm at 1.3 m/s, as measured).

The stride (two steps) follows Alexander's dynamic-similarity relation, stride / leg length = 2.3 (v^2 / (g leg
length))^0.3 (R. McN. Alexander, "Estimates of speeds of dinosaurs", Nature 261, 129-130, 1976), with the leg
length (hip height) 0.53 of the stature; at 1.34 m/s a 1.75 m person strides 1.36 m, about 0.98 Hz.

People change between walking and running at about 2.0 m/s (the preferred transition speed of adults: Hreljac,
"Preferred and energetically optimal gait transition speeds in human locomotion", Med. Sci. Sports Exerc. 25(10),
1993); SUMO's walkers' speeds scatter by about 0.2 m/s from step to step, so a walker starts running above
RUN_ABOVE_MPS and a runner walks again below WALK_BELOW_MPS (a hysteresis around that speed, so that a fast walker
does not flicker). The running cycle is ours, shaped after the curves of running in Novacheck, "The biomechanics of
running", Gait & Posture 7, 77-95 (1998): a foot is on the ground for the first 39 % of its cycle (toe-off), so each
step ends in a float in which neither foot touches the ground (the pelvis ~3 cm above the line from take-off to
landing); the thigh swings from about 17 deg back at toe-off to about 42 deg forward late in the swing; the knee flexes
about 40 deg at mid-stance (the body at its lowest) and 105 deg in the swing (the heel comes up behind); the trunk
leans 5 deg more than walking and the arms swing 30 deg each way with the elbows bent 85-93 deg. Alexander's relation
gives the running stride too (2.1 m at 2.9 m/s for a 1.75 m person: 167 steps a minute). The running poses are
sampled half a sample off the walk's phases, so that two of the eight show the float.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from pipeline.core.classes import Person
from pipeline.world.figures import FOREARM_M, SHIN_M, THIGH_M, UPPER_ARM_M, Outfit, Pose, bend, pose

MODEL_STATURE_M = 1.75  # the figures' stature as modelled (a standing figure's top of the head)
WALK_PHASES = 8  # poses sampled per walk cycle (phase k / WALK_PHASES)
STAND_POSES = 3  # standing: on both feet, weight on the left, weight on the right
RUN_PHASES = 8  # poses sampled per running cycle (phase (k + 0.5) / RUN_PHASES), after the standing ones
UMBRELLA_POSES = 11  # the walking and standing poses again with an umbrella held up, after the running ones
RUN_ABOVE_MPS = 2.3  # a walker faster than this starts running (see the module docstring)
WALK_BELOW_MPS = 1.9  # a runner slower than this walks again
UMBRELLA_FIRST = WALK_PHASES + STAND_POSES + RUN_PHASES  # the first umbrella pose's index
LEG_LENGTH_RATIO = 0.53  # hip height / stature (adults; Winter 1991, Fig. 3.1 segment proportions)
STANDING_BELOW_MPS = 0.25  # slower than this a person stands (SUMO's waiting pedestrians have speed 0)
WEIGHT_SHIFT_S = 6.0  # a standing person changes the leg that carries the weight about this often
G_MPS2 = 9.81

_CYCLE = np.array([0.0, 0.15, 0.4, 0.6, 0.72, 0.85, 0.97, 1.0])
_KNEE_DEG = np.array([5.0, 17.0, 4.0, 38.0, 60.0, 30.0, 3.0, 5.0])  # knee flexion over the cycle
_FOOT_AT = np.array([0.0, 0.08, 0.42, 0.55, 0.62, 0.75, 0.88, 0.96, 1.0])
_FOOT_DEG = np.array([14.0, 0.0, 0.0, -22.0, -40.0, -18.0, 0.0, 12.0, 14.0])  # shoe pitch, toe up +
_ROLL_AT = np.array([0.0, 0.42, 0.5, 0.6, 1.0])
_ROLL_M = np.array([0.0, 0.0, 0.025, 0.06, 0.0])  # the ankle rises as the foot rolls onto the toes before toe-off
# Running (Novacheck 1998): toe-off at 39 % of the cycle; knee flexion landmarks; the shoe's pitch and the ankle's rise.
_RUN_TOE_OFF = 0.39
_RUN_CYCLE = np.array([0.0, 0.17, 0.39, 0.68, 0.93, 1.0])
_RUN_KNEE_DEG = np.array([20.0, 40.0, 18.0, 105.0, 12.0, 20.0])
_RUN_FOOT_AT = np.array([0.0, 0.06, 0.3, 0.39, 0.5, 0.75, 0.93, 1.0])
_RUN_FOOT_DEG = np.array([8.0, 0.0, 0.0, -30.0, -45.0, -10.0, 10.0, 8.0])
_RUN_ROLL_AT = np.array([0.0, 0.25, 0.39, 1.0])
_RUN_ROLL_M = np.array([0.0, 0.0, 0.06, 0.06])
_FLOAT_RISE_M = 0.03  # the pelvis above the line from take-off to landing at the middle of the float


def thigh_deg(phase) -> np.ndarray:
    """The thigh's angle forward of vertical (deg) at gait phase(s) ``phase`` (0 = this leg's heel strike)."""
    return 4.0 + 16.0 * np.cos(2.0 * np.pi * (np.asarray(phase, float) + 0.05))


def knee_deg(phase) -> np.ndarray:
    """Knee flexion (deg) over the cycle (periodic linear interpolation of the normative curve's landmarks)."""
    return np.interp(np.mod(phase, 1.0), _CYCLE, _KNEE_DEG)


def _ankle(thigh: float, knee: float) -> np.ndarray:
    """(x, z) of the ankle from the hip joint for the thigh ``thigh`` deg forward and the knee bent ``knee`` deg."""
    t, s = np.radians(thigh), np.radians(thigh - knee)
    return np.array([THIGH_M * np.sin(t) + SHIN_M * np.sin(s), -THIGH_M * np.cos(t) - SHIN_M * np.cos(s)])


def _arm(shoulder: np.ndarray, swing_deg: float, elbow_deg: float, side: float) -> tuple[np.ndarray, np.ndarray]:
    """Wrist and hand direction of an arm swung ``swing_deg`` forward of hanging with the elbow bent ``elbow_deg``;
    the arm hangs a little out from the body (``side`` +1 left, -1 right)."""
    a, f = np.radians(swing_deg), np.radians(swing_deg + elbow_deg)
    upper = np.array([np.sin(a), 0.09 * side, -np.cos(a)])
    fore = np.array([np.sin(f), 0.02 * side, -np.cos(f)])
    upper, fore = upper / np.linalg.norm(upper), fore / np.linalg.norm(fore)
    return shoulder + UPPER_ARM_M * upper + FOREARM_M * fore, fore


def _trunk(hip_z: float, sway: float, lean_deg: float, head_forward: float) -> tuple[np.ndarray, ...]:
    """Pelvis, chest (the shoulders' midpoint) and head centre of a trunk leaning ``lean_deg`` forward, the pelvis
    ``sway`` to the left at ``hip_z``, the head ``head_forward`` ahead of the trunk's line."""
    lean = np.radians(lean_deg)
    pelvis = np.array([0.0, sway, hip_z])
    chest = pelvis + [0.52 * np.sin(lean), 0.0, 0.52 * np.cos(lean)]
    head = pelvis + [0.715 * np.sin(lean) + head_forward, 0.0, 0.715 * np.cos(lean)]
    return pelvis, chest, head


def walking_pose(phase: float, lean_deg: float = 3.0, arm_swing_deg: float = 15.0) -> Pose:
    """The pose at gait ``phase`` in [0, 1) (0: the left heel strikes), trunk leaning ``lean_deg`` forward."""
    phases = np.array([phase, phase + 0.5]) % 1.0
    ankles_hip = np.array([_ankle(thigh_deg(p), knee_deg(p)) for p in phases])  # (2, 2) x, z from the hip
    roll = np.interp(phases, _ROLL_AT, _ROLL_M)
    hip_z = float(np.max(0.085 + roll - ankles_hip[:, 1]))  # the lower foot on the ground
    sway = 0.018 * np.cos(2.0 * np.pi * phase)  # the pelvis over the stance foot: left near phase 0, right near 0.5
    pelvis, chest, head = _trunk(hip_z, sway, lean_deg, 0.02)
    side = np.array([1.0, -1.0])
    ankles = np.column_stack([ankles_hip[:, 0], sway + 0.085 * side, hip_z + ankles_hip[:, 1]])
    pitch = np.radians(np.interp(phases, _FOOT_AT, _FOOT_DEG))
    feet = np.column_stack([np.cos(pitch), 0.06 * side, np.sin(pitch)])
    # Each arm swings with the opposite leg: forward as the other leg's thigh comes forward.
    swing = -arm_swing_deg * np.cos(2.0 * np.pi * (phases + 0.05)) + 2.0
    shoulders = chest + 0.185 * side[:, None] * [0.0, 1.0, 0.0] - [0.0, 0.0, 0.02]
    arms = [_arm(shoulders[i], swing[i], 18.0 + 0.9 * max(swing[i], 0.0), side[i]) for i in range(2)]
    knee_dir = np.array([1.0, 0.0, 0.0])
    return pose(pelvis, chest, head, ankles, feet, [a[0] for a in arms], [a[1] for a in arms], knee_dir=knee_dir,
                elbow_dir=[(-1.0, 0.2, 0.0), (-1.0, -0.2, 0.0)])


def run_thigh_deg(phase) -> np.ndarray:
    """The thigh's angle forward of vertical (deg) running, at phase(s) ``phase`` (0 = this foot's strike): about
    30 deg at the strike, 17 deg back at toe-off, 42 deg forward at 85 % of the cycle (Novacheck 1998's hip curve)."""
    return 12.0 + 30.0 * np.cos(2.0 * np.pi * (np.asarray(phase, float) - 0.85))


def run_knee_deg(phase) -> np.ndarray:
    """Knee flexion (deg) over the running cycle (periodic linear interpolation of the landmarks)."""
    return np.interp(np.mod(phase, 1.0), _RUN_CYCLE, _RUN_KNEE_DEG)


def run_clearance_m(phase: float) -> float:
    """How high the lower foot's sole is above the ground (m) at running ``phase`` in [0, 1): 0 while a foot is on
    the ground, more during the float (after one foot's toe-off, before the other's strike)."""
    phases = np.array([phase, phase + 0.5]) % 1.0
    if (phases < _RUN_TOE_OFF).any():
        return 0.0
    return _run_hip(phase) - max(_stance_hip(p) for p in phases)


def _stance_hip(phase: float) -> float:
    """The hip height at which a foot at ``phase`` (any) would just touch the ground."""
    ankle = _ankle(float(run_thigh_deg(phase)), float(run_knee_deg(phase)))
    return float(0.085 + np.interp(phase, _RUN_ROLL_AT, _RUN_ROLL_M) - ankle[1])


def _run_hip(phase: float) -> float:
    """The hip joints' height (m) at running ``phase`` (0: the left foot strikes): over the stance foot on the
    ground; in the float on a line from take-off to landing raised by _FLOAT_RISE_M x 4 u (1 - u)."""
    phases = np.array([phase, phase + 0.5]) % 1.0
    stance = phases < _RUN_TOE_OFF
    if stance.any():
        return _stance_hip(float(phases[stance][0]))
    gone = float(phases[np.argmin(phases)])  # the foot that left the ground last: its phase is in (TOE_OFF, 0.5)
    u = (gone - _RUN_TOE_OFF) / (0.5 - _RUN_TOE_OFF)
    take_off, landing = _stance_hip(_RUN_TOE_OFF), _stance_hip(0.0)
    return take_off + u * (landing - take_off) + 4.0 * _FLOAT_RISE_M * u * (1.0 - u)


def running_pose(phase: float, lean_deg: float = 8.0, arm_swing_deg: float = 30.0) -> Pose:
    """The running pose at ``phase`` in [0, 1) (0: the left foot strikes), trunk leaning ``lean_deg`` forward, the
    feet at their height above the ground (both off it in the float; :func:`run_clearance_m`)."""
    phases = np.array([phase, phase + 0.5]) % 1.0
    ankles_hip = np.array([_ankle(float(run_thigh_deg(p)), float(run_knee_deg(p))) for p in phases])
    hip_z = _run_hip(phase)
    sway = 0.012 * np.cos(2.0 * np.pi * phase)
    pelvis, chest, head = _trunk(hip_z, sway, lean_deg, 0.03)
    side = np.array([1.0, -1.0])
    ankles = np.column_stack([ankles_hip[:, 0], sway + 0.08 * side, hip_z + ankles_hip[:, 1]])
    pitch = np.radians(np.interp(phases, _RUN_FOOT_AT, _RUN_FOOT_DEG))
    feet = np.column_stack([np.cos(pitch), 0.06 * side, np.sin(pitch)])
    # Each arm swings with the opposite leg: forward as the other thigh comes forward (its peak at 0.85 + 0.5).
    swing = arm_swing_deg * np.cos(2.0 * np.pi * (phases - 0.35)) - 5.0
    shoulders = chest + 0.185 * side[:, None] * [0.0, 1.0, 0.0] - [0.0, 0.0, 0.02]
    arms = [_arm(shoulders[i], swing[i], 85.0 + 0.3 * max(swing[i], 0.0), side[i]) for i in range(2)]
    return pose(pelvis, chest, head, ankles, feet, [a[0] for a in arms], [a[1] for a in arms],
                knee_dir=(1.0, 0.0, 0.0), elbow_dir=[(-1.0, 0.3, 0.0), (-1.0, -0.3, 0.0)])


def standing_pose(weight: int = 0, lean_deg: float = 0.0) -> Pose:
    """Standing: ``weight`` 0 on both feet, 1 on the left leg (the right knee relaxed, that foot a little forward and
    out, the pelvis over the left foot), 2 the mirror image."""
    lean = np.radians(lean_deg)
    shift = {0: 0.0, 1: 0.035, 2: -0.035}[weight]
    relaxed = {0: None, 1: 1, 2: 0}[weight]
    ankles = np.array([[0.0, 0.11, 0.085], [0.0, -0.11, 0.085]])
    hip_z = 0.92
    if relaxed is not None:
        ankles[relaxed] += [0.06, 0.03 * (1 if relaxed == 0 else -1), 0.0]
        hip_z = 0.915
    pelvis = np.array([0.0, shift, hip_z])
    chest = pelvis + [0.52 * np.sin(lean), -0.4 * shift, 0.52]
    head = pelvis + [0.015 + 0.715 * np.sin(lean), -0.5 * shift, 0.715]
    return pose(pelvis, chest, head, ankles, [(1.0, 0.18, 0.0), (1.0, -0.18, 0.0)],
                wrists=[chest + [0.03, 0.225, -0.58], chest + [0.03, -0.225, -0.58]],
                hands=[(0.15, 0.02, -1.0), (0.15, -0.02, -1.0)], knee_dir=(1.0, 0.0, 0.0),
                elbow_dir=(-1.0, 0.3, 0.0))


def umbrella_pose(p: Pose) -> Pose:
    """``p`` with the left arm holding an umbrella's shaft up: the fist in front of the left chest, a little below the
    shoulders, the hand pointing up, the elbow down and out (the arm no longer swings)."""
    chest = p.chest
    wrist = chest + [0.24, 0.06, -0.2]
    elbow = bend(p.shoulders[0], wrist, UPPER_ARM_M, FOREARM_M, (-0.3, 0.6, -1.0))
    return replace(p, wrists=np.array([wrist, p.wrists[1]]), elbows=np.array([elbow, p.elbows[1]]),
                   hands=np.array([[0.0, 0.0, 1.0], p.hands[1]]))


def pose_count(umbrella: bool) -> int:
    """How many poses a person family has (:func:`person_pose`'s layout): walking, standing and running, and with
    ``umbrella`` the umbrella poses after them."""
    return WALK_PHASES + STAND_POSES + RUN_PHASES + (UMBRELLA_POSES if umbrella else 0)


@dataclass(frozen=True)
class PosedFamily:
    """What every person family shares (:class:`pipeline.world.people.PersonFamily`,
    :class:`pipeline.world.wheelchairs.WheelchairFamily`): a name, a group of statures, an outfit, and poses in
    :func:`person_pose`'s layout (the umbrella poses where a subclass's ``umbrella`` is set)."""

    name: str
    group: str
    outfit: Outfit

    @property
    def poses(self) -> int:
        """Walking, standing and running; and the umbrella poses, for a family with an umbrella."""
        return pose_count(getattr(self, "umbrella", None) is not None)

    @property
    def __name__(self) -> str:
        return self.name

    @property
    def person(self) -> Person:
        """Who the family's people are in the labels (``person``): its stature group's age, men and women adults."""
        return Person.ADULT if self.group in ("man", "woman") else Person(self.group)

    def check_pose(self, pose: int) -> None:
        """Raise a ValueError naming the family where ``pose`` is not one of its poses."""
        if not 0 <= pose < self.poses:
            raise ValueError(f"{self.name}: pose {pose} outside 0 .. {self.poses - 1}")


def run_phase(index: int) -> float:
    """The running phase of person pose ``index`` (>= WALK_PHASES + STAND_POSES)."""
    return (index - WALK_PHASES - STAND_POSES + 0.5) / RUN_PHASES


def person_pose(index: int, lean_deg: float = 3.0) -> Pose:
    """Pose ``index`` of a person family: 0 .. WALK_PHASES - 1 the walk cycle at phase index / WALK_PHASES, then the
    STAND_POSES standing ones, then the RUN_PHASES running ones (:func:`run_phase`; the trunk leans 5 deg more than
    walking), then the UMBRELLA_POSES: the walking and standing ones again with an umbrella held up
    (:func:`umbrella_pose`)."""
    if index >= UMBRELLA_FIRST:
        return umbrella_pose(person_pose(index - UMBRELLA_FIRST, lean_deg))
    if index < WALK_PHASES:
        return walking_pose(index / WALK_PHASES, lean_deg)
    if index < WALK_PHASES + STAND_POSES:
        return standing_pose(index - WALK_PHASES)
    return running_pose(run_phase(index), lean_deg + 5.0)


def stride_m(speed_mps: np.ndarray, stature_m: np.ndarray) -> np.ndarray:
    """(N,) float64 stride length (two steps), metres, at walking speed ``speed_mps`` for statures ``stature_m``
    (Alexander 1976; see the module docstring). Zero speed gives zero stride."""
    leg = LEG_LENGTH_RATIO * np.asarray(stature_m, float)
    v = np.maximum(np.asarray(speed_mps, float), 0.0)
    return 2.3 * leg * (v * v / (G_MPS2 * leg)) ** 0.3


def cycle_phase(track_id: np.ndarray, time_s: np.ndarray, rate_hz: np.ndarray,
                runs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cycles completed since each track's first row: the integral of ``rate_hz`` (N,) cycles per second over
    ``time_s`` (trapezoids between a track's rows in time order). Returns (N,) float64 cycles and the (N,) int64 order
    that sorts the rows by (track, time). ``runs``: :func:`_track_runs` of the same rows, if already known."""
    t, rate = np.asarray(time_s, float), np.asarray(rate_hz, float)
    order, first, start = runs if runs is not None else _track_runs(track_id, t)
    t, rate = t[order], rate[order]
    n = len(t)
    step = np.zeros(n)
    step[1:] = 0.5 * (rate[1:] + rate[:-1]) * (t[1:] - t[:-1])
    step[first] = 0.0
    total = np.cumsum(step)
    cycles = np.empty(n)
    cycles[order] = total - total[start]
    return cycles, order


def _track_runs(track_id: np.ndarray, time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (N,) order that sorts N rows by (track, time), and in that order (N,) bool: the track's first row, and
    (N,) int64: the position of the track's first row."""
    track_id = np.asarray(track_id)
    n = len(track_id)
    order = np.lexsort((time_s, track_id))
    tid = track_id[order]
    first = np.ones(n, bool)
    first[1:] = tid[1:] != tid[:-1]
    return order, first, np.maximum.accumulate(np.where(first, np.arange(n), 0))


def running_rows(track_id: np.ndarray, time_s: np.ndarray, speed_mps: np.ndarray,
                 runs: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(N,) bool: the rows in which the person runs. Along each track in time order a person starts running on a row
    faster than RUN_ABOVE_MPS and walks again on one slower than WALK_BELOW_MPS (in between the gait stays as it
    was; a track starts walking). ``runs``: :func:`_track_runs` of the same rows, if already known."""
    order, _, start = runs if runs is not None else _track_runs(track_id, np.asarray(time_s, float))
    v = np.asarray(speed_mps, float)[order]
    n = len(v)
    decided = (v > RUN_ABOVE_MPS) | (v < WALK_BELOW_MPS)
    last = np.maximum.accumulate(np.where(decided, np.arange(n), -1))  # the latest row that decided the gait
    out = np.zeros(n, bool)
    out[order] = (last >= start) & (v[np.maximum(last, 0)] > RUN_ABOVE_MPS)
    return out


def gait_poses(track_id: np.ndarray, time_s: np.ndarray, speed_mps: np.ndarray, stature_m: np.ndarray,
               offset: np.ndarray, umbrella: np.ndarray | None = None) -> np.ndarray:
    """(N,) int64 each row's pose index (:func:`person_pose`) for N trajectory rows of any number of people.

    A walking person's gait phase is the integral of speed / stride over time since the first row of their track
    (:func:`cycle_phase`), plus their own ``offset`` in [0, 1); a person slower than STANDING_BELOW_MPS stands, the
    weight shifting every WEIGHT_SHIFT_S from one leg to the other; where :func:`running_rows` says so a person runs
    (the running poses, at the same phase: the cycle goes on through a change of gait). A person with ``umbrella``
    walks and stands under it (the umbrella poses; a runner runs without). A function of the whole trajectory, so
    each frame's pose is the same however the frames are split among shards.

    Args:
        track_id, time_s, speed_mps, stature_m, offset: (N,) per row (``offset`` and ``stature_m`` constant over
            a track); umbrella: (N,) bool per row (constant over a track), None for nobody.
    """
    speed, stature, offset = (np.asarray(a, float) for a in (speed_mps, stature_m, offset))
    rate = np.zeros(len(speed))
    walking = speed >= STANDING_BELOW_MPS
    rate[walking] = speed[walking] / stride_m(speed[walking], stature[walking])  # cycles per second
    runs = _track_runs(track_id, np.asarray(time_s, float))
    cycles, _ = cycle_phase(track_id, time_s, rate, runs)
    phase = np.mod(cycles + offset, 1.0)
    walk = np.floor(phase * WALK_PHASES).astype(np.int64) % WALK_PHASES
    run = WALK_PHASES + STAND_POSES + np.floor(phase * RUN_PHASES).astype(np.int64) % RUN_PHASES
    shift = np.floor(np.asarray(time_s, float) / WEIGHT_SHIFT_S + 3.0 * offset).astype(np.int64)
    running = running_rows(track_id, time_s, speed, runs)
    out = np.where(running, run, np.where(walking, walk, WALK_PHASES + np.mod(shift, STAND_POSES)))
    if umbrella is not None:
        out = np.where(np.asarray(umbrella, bool) & ~running, UMBRELLA_FIRST + out, out)
    return out


def crank_poses(track_id: np.ndarray, time_s: np.ndarray, speed_mps: np.ndarray, development_m: float, phases: int,
                offset: np.ndarray) -> np.ndarray:
    """(N,) int64 each row's crank pose (0 .. phases - 1) of N rows of bicycles: the crank turns once per
    ``development_m`` ridden (the integral of speed), from each one's own ``offset`` (N,) in [0, 1); stopped, the
    cranks stay where they were."""
    cycles, _ = cycle_phase(track_id, time_s, np.maximum(np.asarray(speed_mps, float), 0.0) / development_m)
    return np.floor(np.mod(cycles + np.asarray(offset, float), 1.0) * phases).astype(np.int64) % phases
