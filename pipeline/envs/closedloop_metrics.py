"""Closed-loop driving metrics from an episode's per-step log, and their comparison over seeds.

An :class:`EpisodeLog` holds, per step, the ego's speed and acceleration, the ground-truth leader (present, gap
bumper to bumper, closing speed) whatever the agent saw, whether the agent's own observation had a leader, and the
range of the ground-truth leader when it was first tracked. The metrics (:func:`episode_metrics`):

- ``collisions_per_100km``: collisions (0 or 1: a collision ends the episode) per 100 km driven;
- ``min_ttc_s``: the smallest time to collision with the ground-truth leader, gap / closing speed over the steps
  where the ego closes in (``inf`` when it never does), and ``share_ttc_below_1_5s``, the share of steps with a TTC
  under 1.5 s (the usual threshold of a critical encounter: Vogel 2003, "A comparison of headway and time to
  collision as safety indicators", Accident Analysis & Prevention 35);
- ``hard_brakes``: events of deceleration beyond 4 m/s^2 (``HARD_BRAKE_MPS2``; one event per run of steps);
- ``first_tracked_range_m``: the median over leaders of the ground-truth gap at which the agent's observation
  first held each new leader (perceived runs; with ground truth, the range it appears in the observation). The
  observation holds the leader when its leader slot is filled and the slot's near face (ds less half its length)
  and lateral offset lie within the tracker's own association gate of the true leader's (:func:`holds_leader`): a
  false track in the slot, or one ranged on something else at about the leader's distance, is not the leader;
- ``steady_tracked_range_m``: the same for the start of the first stretch of at least STEADY_S in which the
  observation holds the leader at every step: a single lucky hold far off (a track born from three hits, then lost)
  counts in the first tracked range, not here;
- ``leader_held_<lo>_<hi>m``: by the ground-truth leader's gap (bins of ``LEADER_RANGE_BINS_M``), the share of the
  steps with the leader in that bin on which the observation held it: the lead vehicle's recall by range, from every
  step rather than from the one step each leader is first seen (which depends on how each leader came to lead, and
  on the ego's own driving: braking for a false track lets the leader draw away);
- ``mean_speed_mps`` and ``progress_m``;
- the perception's own errors on the three leader slots (the front camera's view; :meth:`EpisodeLog.add_slots`):
  ``slot_missed_share`` (slots the ground truth fills and the observation leaves empty, over those it fills),
  ``slot_false_share`` (filled in the observation, empty in the ground truth, over those filled in the
  observation), and over slots filled in both the median absolute errors ``slot_ds_error_m`` and
  ``slot_dv_error_mps`` (0 and 0 for a ground-truth run, whose observation is the ground truth);
- the same for the "path" row, the nearest person in the ego's path (:meth:`EpisodeLog.add_path`):
  ``person_missed_share`` (steps on which the ground truth has a person in the path and the observation has none,
  over the steps the ground truth has one: the perceived row holds people about to walk into the path only once
  their track's velocity is known, the ground truth's on SUMO's velocity at once), ``person_false_share`` (steps
  the observation has a person in the path and the ground truth none, over the steps it has one) and
  ``person_steps_share`` (the share of steps the ground truth has a person in the path).

:func:`compare` pairs perceived and ground-truth episodes of the same seeds: for each metric the mean of each and
the mean of their differences with a percentile bootstrap confidence interval over seeds (Efron & Tibshirani 1993),
resampled by a generator of fixed seed.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass

import numpy as np

from pipeline.envs.features import NEIGHBOUR_FIELDS
from pipeline.envs.tracker import TrackerParams

HARD_BRAKE_MPS2 = -4.0
# The observed leader is the true one when it lies where the tracker would take the true one's position for a
# measurement of it: the tracker's measurement noise and gate (its defaults, those of the closed loop).
LEADER_GATE = TrackerParams()
_PRESENT, _DS, _DD, _LENGTH = (NEIGHBOUR_FIELDS.index(f) for f in ("present", "ds_m", "dd_m", "length_m"))
TTC_CRITICAL_S = 1.5
STEADY_S = 1.0  # a leader is tracked steadily once held this long without a gap
# Gap bins of the leader's recall by range (m; the last closes at the features' default range, 100 m).
LEADER_RANGE_BINS_M = (0.0, 20.0, 40.0, 60.0, 100.0)
LEADER_HELD = tuple(f"leader_held_{lo:g}_{hi:g}m" for lo, hi in itertools.pairwise(LEADER_RANGE_BINS_M))
METRICS = ("collisions_per_100km", "min_ttc_s", "share_ttc_below_1_5s", "hard_brakes", "first_tracked_range_m",
           "steady_tracked_range_m", *LEADER_HELD, "mean_speed_mps", "progress_m", "slot_missed_share",
           "slot_false_share", "slot_ds_error_m", "slot_dv_error_mps", "person_steps_share", "person_missed_share",
           "person_false_share")


@dataclass
class EpisodeLog:
    """Per-step values of one episode, appended by :meth:`add` (lists, one entry a step)."""

    dt_s: float
    speed_mps: list[float]
    accel_mps2: list[float]
    leader_gap_m: list[float]  # NaN: no ground-truth leader
    leader_closing_mps: list[float]  # ego speed - leader speed; NaN without a leader
    leader_id: list[str]  # "" without a leader
    leader_seen: list[bool]  # the agent's observation had a leader this step
    collided: bool = False
    slots: list[np.ndarray] | None = None  # per step (S, 2, 3): [truth, observed] x (present, ds, dv) per slot
    path: list[tuple[bool, bool]] | None = None  # per step: (truth, observed) has a person in the ego's path

    @classmethod
    def empty(cls, dt_s: float) -> EpisodeLog:
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s: expected a finite number > 0, got {dt_s!r}")
        return cls(dt_s, [], [], [], [], [], [], slots=[], path=[])

    def add_path(self, truth: np.ndarray, observed: np.ndarray) -> None:
        """One step's "path" rows (features.PATH_FIELDS): ground truth and observation."""
        self.path.append((bool(truth[0] > 0.5), bool(observed[0] > 0.5)))

    def add_slots(self, truth: np.ndarray, observed: np.ndarray) -> None:
        """One step's (S, 3) (present, ds, dv) of the compared neighbour slots: ground truth and observation."""
        self.slots.append(np.stack([np.asarray(truth, np.float64), np.asarray(observed, np.float64)]).swapaxes(0, 1))

    def add(self, speed_mps: float, accel_mps2: float, leader_id: str, leader_gap_m: float,
            leader_closing_mps: float, leader_seen: bool) -> None:
        self.speed_mps.append(float(speed_mps))
        self.accel_mps2.append(float(accel_mps2))
        self.leader_id.append(leader_id)
        self.leader_gap_m.append(float(leader_gap_m) if leader_id else math.nan)
        self.leader_closing_mps.append(float(leader_closing_mps) if leader_id else math.nan)
        self.leader_seen.append(bool(leader_seen))


def holds_leader(truth: np.ndarray, observed: np.ndarray, gate: TrackerParams = LEADER_GATE) -> bool:
    """Whether an observation's leader slot holds the true leader. ``truth``, ``observed``: the leader slot's rows
    in NEIGHBOUR_FIELDS order. Both filled, and the observed near face (ds - length / 2: the surface a LiDAR ranges,
    so that a track's assumed length does not count as an error) and lateral offset within the tracker's gate of the
    true ones: squared distance / sigma^2 <= ``gate.gate`` (chi-square, 2 dof), sigma = ``gate.sigma_m`` +
    ``gate.sigma_per_m`` x the true leader's range, the standard deviation the tracker gives a LiDAR-ranged position
    there (0.9 m at 30 m, 2.1 m at 90 m by default; the gate is ~3 sigma)."""
    truth, observed = np.asarray(truth, np.float64), np.asarray(observed, np.float64)
    if not (truth[_PRESENT] > 0.5 and observed[_PRESENT] > 0.5):
        return False
    sigma = gate.sigma_m + gate.sigma_per_m * math.hypot(truth[_DS], truth[_DD])
    along = (observed[_DS] - 0.5 * observed[_LENGTH]) - (truth[_DS] - 0.5 * truth[_LENGTH])
    across = observed[_DD] - truth[_DD]
    return bool((along * along + across * across) / (sigma * sigma) <= gate.gate)


def _events(flags: np.ndarray) -> int:
    """Runs of True in a boolean sequence."""
    flags = np.asarray(flags, bool)
    return int(np.count_nonzero(flags[1:] & ~flags[:-1]) + (1 if len(flags) and flags[0] else 0))


def _steady_ranges(leader_id: list[str], held: np.ndarray, gap: np.ndarray, steps: int) -> list[float]:
    """Per ground-truth leader, in order of appearance, the gap at the first step of its first run of ``steps``
    consecutive steps held (the same leader throughout); leaders never held that long give none."""
    out, done, run = [], set(), 0
    for k, lid in enumerate(leader_id):
        same = k > 0 and leader_id[k - 1] == lid
        run = (run + 1 if same else 1) if lid and held[k] else 0
        if run == steps and lid not in done:
            done.add(lid)
            out.append(float(gap[k - steps + 1]))
    return out


def episode_metrics(log: EpisodeLog) -> dict[str, float]:
    """The metrics of one episode (see the module docstring); NaN where undefined (e.g. no leader ever)."""
    speed = np.asarray(log.speed_mps, np.float64)
    progress = float(np.sum(speed) * log.dt_s)
    gap = np.asarray(log.leader_gap_m, np.float64)
    closing = np.asarray(log.leader_closing_mps, np.float64)
    closing_in = np.isfinite(gap) & (closing > 0)
    ttc = np.full(len(gap), np.inf)
    ttc[closing_in] = np.maximum(gap[closing_in], 0.0) / closing[closing_in]
    first_ranges, seen = [], set()
    for lid, saw, g in zip(log.leader_id, log.leader_seen, gap, strict=True):
        if lid and saw and lid not in seen:  # the first step the agent held this ground-truth leader
            seen.add(lid)
            first_ranges.append(g)
    held = np.asarray(log.leader_seen, bool)
    steady_ranges = _steady_ranges(log.leader_id, held, gap, max(1, round(STEADY_S / log.dt_s)))
    # The first bin takes a gap below its lower edge (bumpers overlapping in a collision), the last one above its
    # upper edge (a leader the features hold beyond the default range).
    bin_of = np.digitize(gap, LEADER_RANGE_BINS_M[1:-1])
    by_range = {name: float(np.mean(held[np.isfinite(gap) & (bin_of == k)]))
                if np.any(np.isfinite(gap) & (bin_of == k)) else math.nan for k, name in enumerate(LEADER_HELD)}
    km = progress / 1000.0
    slots = np.concatenate(log.slots) if log.slots else np.zeros((0, 2, 3))
    truth, seen = slots[:, 0, 0] > 0.5, slots[:, 1, 0] > 0.5
    both = truth & seen
    errors = np.abs(slots[both, 1, 1:] - slots[both, 0, 1:])
    path = np.array(log.path, bool).reshape(-1, 2) if log.path else np.zeros((0, 2), bool)
    person, person_seen = path[:, 0], path[:, 1]
    return {
        "collisions_per_100km": (100.0 * int(log.collided) / km) if km > 0 else (math.inf if log.collided else 0.0),
        "min_ttc_s": float(ttc.min()) if len(ttc) else math.inf,
        "share_ttc_below_1_5s": float(np.mean(ttc < TTC_CRITICAL_S)) if len(ttc) else 0.0,
        "hard_brakes": float(_events(np.asarray(log.accel_mps2) < HARD_BRAKE_MPS2)),
        "first_tracked_range_m": float(np.median(first_ranges)) if first_ranges else math.nan,
        "steady_tracked_range_m": float(np.median(steady_ranges)) if steady_ranges else math.nan,
        **by_range,
        "mean_speed_mps": float(speed.mean()) if len(speed) else math.nan,
        "progress_m": progress,
        "slot_missed_share": float(np.mean(~seen[truth])) if truth.any() else math.nan,
        "slot_false_share": float(np.mean(~truth[seen])) if seen.any() else math.nan,
        "slot_ds_error_m": float(np.median(errors[:, 0])) if len(errors) else math.nan,
        "slot_dv_error_mps": float(np.median(errors[:, 1])) if len(errors) else math.nan,
        "person_steps_share": float(np.mean(person)) if len(person) else math.nan,
        "person_missed_share": float(np.mean(~person_seen[person])) if person.any() else math.nan,
        "person_false_share": float(np.mean(~person[person_seen])) if person_seen.any() else math.nan,
    }


@dataclass(frozen=True)
class Comparison:
    """One metric over paired seeds: the means of the perceived and ground-truth runs, and their mean difference
    (perceived - ground truth) with its bootstrap confidence interval."""

    metric: str
    perceived: float
    ground_truth: float
    difference: float
    ci_low: float
    ci_high: float
    seeds: int

    def as_dict(self) -> dict[str, float | int | str]:
        return asdict(self)


def _finite_mean(values: np.ndarray) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.mean()) if len(finite) else math.nan


def compare(perceived: list[dict[str, float]], ground_truth: list[dict[str, float]], *, resamples: int = 2000,
            level: float = 0.95, seed: int = 0) -> list[Comparison]:
    """Per metric, perceived vs ground truth over paired episodes (same seeds, same order). Pairs where either
    value is not finite (an infinite TTC, no leader) are left out of that metric's difference."""
    if len(perceived) != len(ground_truth):
        raise ValueError(f"compare: {len(perceived)} perceived and {len(ground_truth)} ground-truth episodes; "
                         "expected one of each per seed")
    if not 0 < level < 1:
        raise ValueError(f"level: expected a number in (0, 1), got {level!r}")
    rng = np.random.default_rng([seed, 42])
    out = []
    for name in METRICS:
        p = np.array([m[name] for m in perceived], np.float64)
        g = np.array([m[name] for m in ground_truth], np.float64)
        both = np.isfinite(p) & np.isfinite(g)
        d = p[both] - g[both]
        if len(d):
            idx = rng.integers(0, len(d), (resamples, len(d)))
            means = d[idx].mean(axis=1)
            low, high = np.quantile(means, [(1 - level) / 2, 1 - (1 - level) / 2])
            diff = float(d.mean())
        else:
            low = high = diff = math.nan
        out.append(Comparison(name, _finite_mean(p), _finite_mean(g), diff, float(low), float(high), len(d)))
    return out
