"""A reference driver for the environment: IDM car following and MOBIL lane changes on the feature observation.

It reads only what an agent reads — the ego row, the six neighbour slots, the signal and path rows of the feature
observation (:mod:`pipeline.envs.features`) — so the same driver runs on ground-truth features and on features a
perception stack made (docs/closedloop.md): a difference in its driving is the perception's doing.

- **IDM** (Treiber, Hennecke & Helbing 2000, "Congested traffic states in empirical observations and microscopic
  simulations", Phys. Rev. E 62): a = a_max [1 - (v / v0)^delta - (s* / s)^2] with the desired gap
  s* = s0 + max(0, v T + v dv_close / (2 sqrt(a_max b))), where s is the bumper-to-bumper gap to the leader and
  dv_close = v - v_leader the closing speed; without a leader only the free-road term.
- **MOBIL** (Kesting, Treiber & Helbing 2007, "General lane-changing model MOBIL for car-following models",
  Transportation Research Record 1999): change to an adjacent drivable lane when it is *safe* — the new follower's
  IDM acceleration after the change stays above -b_safe and no gap is negative — and *worth it*:
  (a~_ego - a_ego) + p [(a~_new_follower - a_new_follower) + (a~_old_follower - a_old_follower)] > a_th, with
  a keep-right bias (the rule of European motorways): a change to the left must also beat ``keep_right_bias``, a
  change to the right gains it. A tilde is the acceleration after the change. Followers' desired speeds are not
  observed: each is taken as the ego's desired speed.
- **Traffic signals** (the observation's "signal" row: the next signal on the ego's way): a signal that shows red
  is a standing vehicle of no length at its stop line for IDM, the way Treiber & Kesting model a red light
  ("Traffic Flow Dynamics", 2013: a virtual standing obstacle; IDM's minimum gap then keeps the ego s0 short of the
  line). At amber the ego stops the same way where it can without braking harder than ``amber_decel_mps2`` (its
  speed^2 / (2 x the distance to the line)); otherwise it drives on, and keeps driving on through that signal when it
  turns red: the amber dilemma of Gazis, Herman & Maradudin ("The problem of the amber signal light in traffic
  flow", Operations Research 8(1), 1960), decided once, so a driver who went at amber does not brake in the junction.
- **People in the path** (the observation's "path" row, :func:`pipeline.envs.features.path_row`: the nearest person
  on the centre line of the lanes the ego's route takes, within half its width, or walking into it before the ego
  gets there): a standing obstacle at the person's place for IDM, as a red light is, so the ego yields to people on
  a crossing it turns across, or on the road, and stops IDM's s0 short of them.
- **Route** (map knowledge, as SUMO's strategic lane changes use it: how far each lane lets the ego follow its
  route before it must change): a MOBIL change may not take the ego to a lane that leaves its route sooner than its
  lane does, unless both go on for ``route_lookahead_m``; and where its lane leaves the route within
  ``must_change_m`` (or the time it takes to drive ``must_change_s``), it changes to a neighbour lane that goes on
  farther as soon as MOBIL's safety criterion allows and its own braking behind its new leader stays within
  b_safe, whatever the incentive; until then it brakes for its lane's end as for a standing vehicle there (where
  it can see the gaps beside it: with a front camera alone it cannot, and drives on).
- **Desired speed**: the lower of IDM's ``desired_speed_mps`` and the road's speed limit (map knowledge; inside a
  junction the limit of the road before it).
- **Lateral control**: the target lane's centre is followed by the PD law of :class:`pipeline.envs.MetaActions`
  (a_lat = k_lat x lateral error - d_lat x lateral speed); a new change waits ``cooldown_s`` after the last one and
  until the ego is within ``settled_m`` of its lane centre.

Parameters default to Treiber & Kesting's motorway values ("Traffic Flow Dynamics", Springer 2013, table 11.2:
v0 120 km/h, T 1.5 s, s0 2 m, a 1.0 m/s^2, b 1.5 m/s^2, delta 4; section 14.3: p 0.2-0.5, a_th 0.1 m/s^2,
b_safe 4 m/s^2, a_bias 0.2-0.3 m/s^2); the desired speed is capped by the road's limit (the urban grid's is 13.9
m/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.envs.checks import check_number
from pipeline.envs.features import (
    EGO_FIELDS,
    NEIGHBOUR_FIELDS,
    NEIGHBOUR_SLOTS,
    PATH_FIELDS,
    SIGNAL_AMBER,
    SIGNAL_FIELDS,
    SIGNAL_STOP,
)

_EGO = {name: k for k, name in enumerate(EGO_FIELDS)}
_COL = {name: k for k, name in enumerate(NEIGHBOUR_FIELDS)}
_SLOT = {name: k for k, name in enumerate(NEIGHBOUR_SLOTS)}
_SIG = {name: k for k, name in enumerate(SIGNAL_FIELDS)}
_PATH = {name: k for k, name in enumerate(PATH_FIELDS)}


@dataclass(frozen=True)
class IdmParams:
    """IDM's parameters (see the module docstring); SI units."""

    desired_speed_mps: float = 120 / 3.6
    time_headway_s: float = 1.5
    min_gap_m: float = 2.0
    max_accel_mps2: float = 1.0
    comfortable_decel_mps2: float = 1.5
    delta: float = 4.0

    def __post_init__(self) -> None:
        for name in ("desired_speed_mps", "max_accel_mps2", "comfortable_decel_mps2", "delta"):
            check_number("IdmParams", name, getattr(self, name))
        for name in ("time_headway_s", "min_gap_m"):
            check_number("IdmParams", name, getattr(self, name), allow_low=True)


@dataclass(frozen=True)
class MobilParams:
    """MOBIL's parameters (see the module docstring); SI units."""

    politeness: float = 0.3
    threshold_mps2: float = 0.1
    safe_decel_mps2: float = 4.0
    keep_right_bias_mps2: float = 0.2

    def __post_init__(self) -> None:
        check_number("MobilParams", "politeness", self.politeness, allow_low=True, high=1.0)
        check_number("MobilParams", "safe_decel_mps2", self.safe_decel_mps2)
        for name in ("threshold_mps2", "keep_right_bias_mps2"):
            check_number("MobilParams", name, getattr(self, name), allow_low=True)


def idm_accel(speed_mps: float, params: IdmParams, gap_m: float | None = None,
              leader_speed_mps: float | None = None) -> float:
    """IDM's acceleration (m/s^2) at ``speed_mps`` behind a leader ``gap_m`` ahead (bumper to bumper) driving at
    ``leader_speed_mps``; without a leader (``gap_m`` None) the free-road term alone. A gap at or below zero (an
    overlap) gives -inf: no finite braking undoes it."""
    v, p = max(speed_mps, 0.0), params
    free = p.max_accel_mps2 * (1.0 - (v / p.desired_speed_mps) ** p.delta)
    if gap_m is None:
        return free
    if gap_m <= 0.0:
        return -math.inf
    closing = v - (v if leader_speed_mps is None else leader_speed_mps)
    desired = p.min_gap_m + max(0.0, v * p.time_headway_s
                                + v * closing / (2.0 * math.sqrt(p.max_accel_mps2 * p.comfortable_decel_mps2)))
    return free - p.max_accel_mps2 * (desired / gap_m) ** 2


@dataclass(frozen=True)
class Neighbour:
    """One neighbour slot, read from a feature observation's row: centre-to-centre ``ds_m`` along the road, its
    speed and length."""

    ds_m: float
    speed_mps: float
    length_m: float


def _neighbours(obs: dict[str, np.ndarray]) -> dict[str, Neighbour]:
    ego_speed = float(obs["ego"][_EGO["speed_mps"]])
    rows = np.asarray(obs["neighbours"], np.float64)
    return {slot: Neighbour(float(rows[k, _COL["ds_m"]]), ego_speed + float(rows[k, _COL["dv_mps"]]),
                            float(rows[k, _COL["length_m"]]))
            for slot, k in _SLOT.items() if rows[k, _COL["present"]] > 0.5}


@dataclass(frozen=True)
class LaneChoice:
    """A MOBIL evaluation of one adjacent lane: ``safe``, the ``incentive`` (m/s^2, bias included), whether it
    beats the threshold (``change``) and the ego's own IDM acceleration behind its new leader (``ego_accel_mps2``)."""

    side: int  # +1 left, -1 right
    safe: bool
    incentive: float
    change: bool
    ego_accel_mps2: float = 0.0


def mobil(speed_mps: float, ego_length_m: float, neighbours: dict[str, Neighbour], side: int, idm: IdmParams,
          params: MobilParams, observed=NEIGHBOUR_SLOTS) -> LaneChoice:
    """MOBIL's verdict on changing to the lane on ``side`` (+1 left, -1 right), from the neighbour slots (centre
    offsets along the road) of the current and the target lane (see the module docstring). ``observed``: the slots
    the observation can fill at all (its sensors' coverage); a change is unsafe when the target lane's follower
    slot is not among them, since an empty slot there does not mean an empty lane."""
    if side not in (1, -1):
        raise ValueError(f"side: expected +1 (left) or -1 (right), got {side!r}")
    prefix = "left_" if side == 1 else "right_"
    leader, follower = neighbours.get("leader"), neighbours.get("follower")
    new_leader, new_follower = neighbours.get(prefix + "leader"), neighbours.get(prefix + "follower")

    def gap(front: Neighbour | None, back_ds: float, back_length: float, front_is_ego: bool = False) -> float | None:
        """Bumper-to-bumper gap from a vehicle at ``back_ds`` (length ``back_length``) to ``front``."""
        if front is None and not front_is_ego:
            return None
        front_ds, front_length = (0.0, ego_length_m) if front_is_ego else (front.ds_m, front.length_m)
        return front_ds - back_ds - 0.5 * (front_length + back_length)

    def accel(back_speed: float, g: float | None, front_speed: float | None) -> float:
        return idm_accel(back_speed, idm, g, front_speed)

    a_ego = accel(speed_mps, gap(leader, 0.0, ego_length_m), None if leader is None else leader.speed_mps)
    a_ego_new = accel(speed_mps, gap(new_leader, 0.0, ego_length_m),
                      None if new_leader is None else new_leader.speed_mps)
    gain = a_ego_new - a_ego
    others = 0.0
    safe = a_ego_new > -math.inf and prefix + "follower" in observed  # no overlap; the lane behind is seen
    if new_follower is not None:
        before = accel(new_follower.speed_mps, gap(new_leader, new_follower.ds_m, new_follower.length_m),
                       None if new_leader is None else new_leader.speed_mps)
        after = accel(new_follower.speed_mps, gap(None, new_follower.ds_m, new_follower.length_m, True), speed_mps)
        safe = safe and after >= -params.safe_decel_mps2
        others += after - before
    if follower is not None:
        before = accel(follower.speed_mps, gap(None, follower.ds_m, follower.length_m, True), speed_mps)
        after = accel(follower.speed_mps, gap(leader, follower.ds_m, follower.length_m),
                      None if leader is None else leader.speed_mps)
        others += after - before
    incentive = gain + params.politeness * others - side * params.keep_right_bias_mps2
    return LaneChoice(side, safe, incentive, safe and incentive > params.threshold_mps2, a_ego_new)


@dataclass
class ReferenceDriver:
    """IDM + MOBIL on feature observations; :meth:`accelerations` gives (longitudinal, lateral) m/s^2 for one
    step. Stateful (the lateral target and the time since the last change): call :meth:`reset` with each
    episode's first observation.

    Args:
        idm, mobil: the models' parameters.
        ego_length_m: the ego's length (its gaps are centre offsets minus half of both lengths).
        dt_s: the step length (for the cooldown).
        k_lat, d_lat: the lateral PD gains (1/s^2, 1/s), as :class:`pipeline.envs.MetaActions`'.
        cooldown_s: least time between two lane changes.
        settled_m: a new change waits until the ego is this close to its target lane's centre.
        observed_slots: the neighbour slots the observation can fill (all for ground truth; a front camera's
            perception fills only the leaders): no change to a lane whose follower slot is not observed.
        amber_decel_mps2: at amber the ego stops where that needs no harder braking than this (see the module
            docstring), else drives on through the signal.
        route_lookahead_m, must_change_m, must_change_s: the route rule's distances (see the module docstring).
    """

    idm: IdmParams = field(default_factory=IdmParams)
    mobil: MobilParams = field(default_factory=MobilParams)
    ego_length_m: float = 4.5
    dt_s: float = 0.1
    k_lat: float = 1.0
    d_lat: float = 1.6
    cooldown_s: float = 4.0
    settled_m: float = 0.3
    observed_slots: tuple[str, ...] = NEIGHBOUR_SLOTS
    amber_decel_mps2: float = 4.0
    route_lookahead_m: float = 150.0
    must_change_m: float = 50.0
    must_change_s: float = 5.0
    target_offset_m: float = 0.0
    since_change_s: float = math.inf
    last_offset_m: float = 0.0
    passing_m: float = math.nan  # the distance to the signal the ego decided to drive on through (NaN: none)

    def __post_init__(self) -> None:
        for name in ("ego_length_m", "dt_s", "k_lat", "d_lat", "amber_decel_mps2", "route_lookahead_m", "must_change_m",
                     "must_change_s"):
            check_number("ReferenceDriver", name, getattr(self, name))
        for name in ("cooldown_s", "settled_m"):
            check_number("ReferenceDriver", name, getattr(self, name), allow_low=True)

    def reset(self, obs: dict[str, np.ndarray]) -> None:
        self.target_offset_m = 0.0
        self.since_change_s = math.inf
        self.passing_m = math.nan
        self.last_offset_m = float(obs["ego"][_EGO["lateral_offset_m"]])

    def stop_line_m(self, obs: dict[str, np.ndarray], speed_mps: float) -> float | None:
        """The distance to a stop line the ego must stop at (a red signal's, or an amber one's it can stop at;
        see the module docstring), or None; it remembers deciding to drive on through an amber signal."""
        row = obs.get("signal")
        if row is None or row[_SIG["present"]] < 0.5:
            self.passing_m = math.nan
            return None
        distance, state = float(row[_SIG["distance_m"]]), round(float(row[_SIG["state"]]))
        if not distance <= self.passing_m + 1.0:  # not the signal it drives through (a farther one, or none decided)
            self.passing_m = math.nan
        if (state == SIGNAL_AMBER and math.isnan(self.passing_m)
                and speed_mps * speed_mps > 2.0 * self.amber_decel_mps2 * max(distance, 1e-3)):
            self.passing_m = distance  # too near to stop comfortably: drive on through
        if not math.isnan(self.passing_m):
            self.passing_m = distance
            return None
        return distance if state in (SIGNAL_AMBER, SIGNAL_STOP) else None

    def accelerations(self, obs: dict[str, np.ndarray], lane_width_m: float,
                      lane_drivable=lambda side: True, lane_reach=lambda side: math.inf,
                      speed_limit_mps: float = math.inf) -> tuple[float, float]:
        """(longitudinal, lateral) acceleration, m/s^2, for the observation ``obs``; ``lane_width_m`` of the ego's
        lane; ``lane_drivable(side)`` whether the lane on ``side`` (+1 left, -1 right) of the target lane exists and
        admits the ego, ``lane_reach(side)`` how far the ego's route goes on it before a change (0: the target lane
        itself; :meth:`pipeline.envs.RoadsynthEnv.lane_reach_m`), ``speed_limit_mps`` the road's limit (IDM's
        desired speed is the lower of it and ``idm.desired_speed_mps``); map knowledge, not perception."""
        ego = obs["ego"]
        speed, offset = float(ego[_EGO["speed_mps"]]), float(ego[_EGO["lateral_offset_m"]])
        heading = float(ego[_EGO["heading_rel_rad"]])
        if lane_width_m > 0 and abs(offset - self.last_offset_m) > 0.5 * lane_width_m:
            # The ego crossed a lane border: the target, relative to the new lane, moves by one lane width.
            self.target_offset_m -= lane_width_m * math.copysign(1.0, self.last_offset_m)
        self.last_offset_m = offset
        self.since_change_s += self.dt_s
        idm = self.idm if speed_limit_mps >= self.idm.desired_speed_mps else replace(
            self.idm, desired_speed_mps=speed_limit_mps)
        neighbours = _neighbours(obs)
        leader = neighbours.get("leader")
        gap = None if leader is None else leader.ds_m - 0.5 * (leader.length_m + self.ego_length_m)
        lon = idm_accel(speed, idm, gap, None if leader is None else leader.speed_mps)
        stop = self.stop_line_m(obs, speed)
        if stop is not None:  # the stop line as a standing vehicle of no length
            lon = min(lon, idm_accel(speed, idm, max(stop, 1e-3), 0.0))
        person = obs.get("path")
        if person is not None and person[_PATH["present"]] >= 0.5:  # a person in the path: standing, for IDM
            lon = min(lon, idm_accel(speed, idm, max(float(person[_PATH["distance_m"]]), 1e-3), 0.0))
        here = lane_reach(0)
        must_change = here < max(self.must_change_m, self.must_change_s * speed)  # its lane leaves the route soon
        settled = abs(self.target_offset_m - offset) < self.settled_m and abs(self.target_offset_m) < self.settled_m
        ready = settled and self.since_change_s >= self.cooldown_s
        beside = ({side: lane_reach(side) for side in (1, -1) if lane_drivable(side)}
                  if lane_width_m > 0 and (must_change or ready) else {})  # the lanes beside: how far each goes on
        if must_change and any(reach > here and ("left_follower" if side == 1 else "right_follower")
                               in self.observed_slots for side, reach in beside.items()):
            # A lane that goes on lies beside it and a gap there can be seen: wait for one before the lane's end.
            lon = min(lon, idm_accel(speed, idm, max(here, 1e-3), 0.0))
        if ready and lane_width_m > 0:
            choices = [mobil(speed, self.ego_length_m, neighbours, side, idm, self.mobil, self.observed_slots)
                       for side in beside]
            if must_change:
                must = [c for c in choices if c.safe and c.ego_accel_mps2 >= -self.mobil.safe_decel_mps2
                        and beside[c.side] > here]
                best = max(must, key=lambda c: (beside[c.side], c.incentive), default=None)
            else:
                keeps = [c for c in choices if c.change and beside[c.side] >= min(here, self.route_lookahead_m)]
                best = max(keeps, key=lambda c: c.incentive, default=None)
            if best is not None:
                self.target_offset_m += best.side * lane_width_m
                self.since_change_s = 0.0
        lat = self.k_lat * (self.target_offset_m - offset) - self.d_lat * speed * math.tan(heading)
        return max(lon, -1e3), lat


class ReferenceAgent:
    """:class:`ReferenceDriver` as an agent of a :class:`pipeline.envs.RoadsynthEnv` (or a wrapper of one):
    ``act(obs)`` gives the env's action. Lane widths, which lanes exist and how far each goes along the ego's route
    come from the env (map knowledge), and
    which neighbour slots its observation can fill from the env's ``observed_slots`` where a wrapper declares it
    (:class:`pipeline.envs.perception.PerceivedFeatures`: the leaders only), all six otherwise."""

    def __init__(self, env, driver: ReferenceDriver | None = None) -> None:
        self.env = env
        self.driver = driver if driver is not None else ReferenceDriver()
        self.speed_limit_mps = math.inf  # the last road's limit (held through a junction)

    def reset(self, obs: dict[str, np.ndarray]) -> None:
        inner = self.env.unwrapped
        self.driver.ego_length_m = inner.ego_length_m()
        self.driver.dt_s = inner.sim.step_length_s
        try:
            observed = self.env.get_wrapper_attr("observed_slots")
        except AttributeError:
            observed = NEIGHBOUR_SLOTS
        self.driver.observed_slots = tuple(observed)
        self.speed_limit_mps = math.inf
        self.driver.reset(obs)

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        inner = self.env.unwrapped
        width = inner.lane_width_m()
        lane = round(float(obs["ego"][_EGO["lane_index"]]))

        def target() -> int:  # the target lane, as the driver holds it when it decides (read then, not now)
            return lane + (round(self.driver.target_offset_m / width) if width > 0 else 0)

        def drivable(side: int) -> bool:  # whether the lane beside the target lane exists and admits the ego
            return inner.lane_drivable(target() + side)

        def reach(side: int) -> float:  # how far the route goes on the lane beside the target lane (0: on it)
            return inner.lane_reach_m(target() + side)

        limit = inner.speed_limit_mps()
        if limit is not None:
            self.speed_limit_mps = limit
        lon, lat = self.driver.accelerations(obs, width, drivable, reach, self.speed_limit_mps)
        return inner.action_from_mps2(lon, lat)
