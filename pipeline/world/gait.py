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
"""

from __future__ import annotations

import numpy as np

from pipeline.world.figures import FOREARM_M, SHIN_M, THIGH_M, UPPER_ARM_M, Pose, pose

MODEL_STATURE_M = 1.75  # the figures' stature as modelled (a standing figure's top of the head)
WALK_PHASES = 8  # poses sampled per walk cycle (phase k / WALK_PHASES)
STAND_POSES = 3  # standing: on both feet, weight on the left, weight on the right
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


def walking_pose(phase: float, lean_deg: float = 3.0, arm_swing_deg: float = 15.0) -> Pose:
    """The pose at gait ``phase`` in [0, 1) (0: the left heel strikes), trunk leaning ``lean_deg`` forward."""
    phases = np.array([phase, phase + 0.5]) % 1.0
    ankles_hip = np.array([_ankle(thigh_deg(p), knee_deg(p)) for p in phases])  # (2, 2) x, z from the hip
    roll = np.interp(phases, _ROLL_AT, _ROLL_M)
    hip_z = float(np.max(0.085 + roll - ankles_hip[:, 1]))  # the lower foot on the ground
    sway = 0.018 * np.cos(2.0 * np.pi * phase)  # the pelvis over the stance foot: left near phase 0, right near 0.5
    lean = np.radians(lean_deg)
    pelvis = np.array([0.0, sway, hip_z])
    chest = pelvis + [0.52 * np.sin(lean), 0.0, 0.52 * np.cos(lean)]
    head = pelvis + [0.715 * np.sin(lean) + 0.02, 0.0, 0.715 * np.cos(lean)]
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


def person_pose(index: int, lean_deg: float = 3.0) -> Pose:
    """Pose ``index`` of a person family: 0 .. WALK_PHASES - 1 the walk cycle at phase index / WALK_PHASES, then the
    STAND_POSES standing ones."""
    if index < WALK_PHASES:
        return walking_pose(index / WALK_PHASES, lean_deg)
    return standing_pose(index - WALK_PHASES)


def stride_m(speed_mps: np.ndarray, stature_m: np.ndarray) -> np.ndarray:
    """(N,) float64 stride length (two steps), metres, at walking speed ``speed_mps`` for statures ``stature_m``
    (Alexander 1976; see the module docstring). Zero speed gives zero stride."""
    leg = LEG_LENGTH_RATIO * np.asarray(stature_m, float)
    v = np.maximum(np.asarray(speed_mps, float), 0.0)
    return 2.3 * leg * (v * v / (G_MPS2 * leg)) ** 0.3


def cycle_phase(track_id: np.ndarray, time_s: np.ndarray, rate_hz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cycles completed since each track's first row: the integral of ``rate_hz`` (N,) cycles per second over
    ``time_s`` (trapezoids between a track's rows in time order). Returns (N,) float64 cycles and the (N,) int64 order
    that sorts the rows by (track, time)."""
    track_id, t, rate = np.asarray(track_id), np.asarray(time_s, float), np.asarray(rate_hz, float)
    n = len(track_id)
    order = np.lexsort((t, track_id))
    tid, t, rate = track_id[order], t[order], rate[order]
    first = np.ones(n, bool)
    first[1:] = tid[1:] != tid[:-1]
    step = np.zeros(n)
    step[1:] = 0.5 * (rate[1:] + rate[:-1]) * (t[1:] - t[:-1])
    step[first] = 0.0
    total = np.cumsum(step)
    start = np.maximum.accumulate(np.where(first, np.arange(n), 0))
    cycles = np.empty(n)
    cycles[order] = total - total[start]
    return cycles, order


def gait_poses(track_id: np.ndarray, time_s: np.ndarray, speed_mps: np.ndarray, stature_m: np.ndarray,
               offset: np.ndarray) -> np.ndarray:
    """(N,) int64 each row's pose index (:func:`person_pose`) for N trajectory rows of any number of people.

    A walking person's gait phase is the integral of speed / stride over time since the first row of their track
    (:func:`cycle_phase`), plus their own ``offset`` in [0, 1); a person slower than STANDING_BELOW_MPS stands, the
    weight shifting every WEIGHT_SHIFT_S from one leg to the other. A function of the whole trajectory, so each
    frame's pose is the same however the frames are split among shards.

    Args:
        track_id, time_s, speed_mps, stature_m, offset: (N,) per row (``offset`` and ``stature_m`` constant over
            a track).
    """
    speed, stature, offset = (np.asarray(a, float) for a in (speed_mps, stature_m, offset))
    rate = np.zeros(len(speed))
    walking = speed >= STANDING_BELOW_MPS
    rate[walking] = speed[walking] / stride_m(speed[walking], stature[walking])  # cycles per second
    cycles, _ = cycle_phase(track_id, time_s, rate)
    walk = np.floor(np.mod(cycles + offset, 1.0) * WALK_PHASES).astype(np.int64) % WALK_PHASES
    shift = np.floor(np.asarray(time_s, float) / WEIGHT_SHIFT_S + 3.0 * offset).astype(np.int64)
    return np.where(walking, walk, WALK_PHASES + np.mod(shift, STAND_POSES))


def crank_poses(track_id: np.ndarray, time_s: np.ndarray, speed_mps: np.ndarray, development_m: float, phases: int,
                offset: np.ndarray) -> np.ndarray:
    """(N,) int64 each row's crank pose (0 .. phases - 1) of N rows of bicycles: the crank turns once per
    ``development_m`` ridden (the integral of speed), from each one's own ``offset`` (N,) in [0, 1); stopped, the
    cranks stay where they were."""
    cycles, _ = cycle_phase(track_id, time_s, np.maximum(np.asarray(speed_mps, float), 0.0) / development_m)
    return np.floor(np.mod(cycles + np.asarray(offset, float), 1.0) * phases).astype(np.int64) % phases
