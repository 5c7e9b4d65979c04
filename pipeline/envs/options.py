"""Options of the driving environment: action limits, time limit and reward weights (frozen, checked when built)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward terms (see docs/envs.md); each term is dimensionless before weighting.

    progress: route progress this step / (target speed x dt), capped to [0, 1] (target_speed_mps; None: the
        speed limit of the ego's lane): only distance gained along the
        ego's route counts, so circling or standing earns nothing and reversing is impossible (speed >= 0).
    comfort: -min((jerk / jerk_ref_mps3)^2, 1), jerk = change of longitudinal acceleration per second.
    lane_keeping: -min((lateral offset / half lane width)^2, 1).
    collision: -1 on the step the ego collides (the episode terminates).
    off_road: -1 on the step the ego leaves the carriageway (the episode terminates).
    """

    progress: float = 1.0
    comfort: float = 0.2
    lane_keeping: float = 0.1
    collision: float = 10.0
    off_road: float = 10.0
    target_speed_mps: float | None = None
    jerk_ref_mps3: float = 10.0

    def __post_init__(self) -> None:
        for name in ("progress", "comfort", "lane_keeping", "collision", "off_road"):
            if getattr(self, name) < 0:
                raise ValueError(f"reward weight {name} must be >= 0, got {getattr(self, name)}")
        if (self.target_speed_mps is not None and self.target_speed_mps <= 0) or self.jerk_ref_mps3 <= 0:
            raise ValueError("target_speed_mps and jerk_ref_mps3 must be > 0")


@dataclass(frozen=True)
class EnvOptions:
    """How the ego is driven and observed.

    accel_min_mps2 / accel_max_mps2: longitudinal acceleration limits (braking is negative).
    lat_accel_max_mps2: lateral acceleration limit (symmetric). lat_speed_max_mps: lateral speed limit
        (also never above the longitudinal speed, so the ego cannot slide sideways at standstill).
    normalize_actions: the action space is Box(-1, 1, (2,)); -1..0 maps to accel_min..0 and 0..1 to 0..accel_max
        (lateral: +-lat_accel_max), so 0 is no acceleration. False: the action space is in m/s^2 directly.
    time_limit_s: episode length after the warm-up (truncated then). neighbour_range_m: farthest neighbour observed.
    nearby_k: rows of the "nearby" observation (the K nearest vehicles within neighbour_range_m); 0 (default): no
        "nearby" (it costs ~0.1 ms a step on the 200-vehicle highway: SUMO collects every vehicle in range).
    """

    accel_min_mps2: float = -6.0
    accel_max_mps2: float = 3.0
    lat_accel_max_mps2: float = 2.0
    lat_speed_max_mps: float = 2.0
    max_speed_mps: float = 50.0
    normalize_actions: bool = True
    time_limit_s: float = 60.0
    neighbour_range_m: float = 100.0
    nearby_k: int = 0
    reward: RewardWeights = field(default_factory=RewardWeights)

    def __post_init__(self) -> None:
        for name in ("accel_min_mps2", "accel_max_mps2", "lat_accel_max_mps2", "lat_speed_max_mps", "max_speed_mps",
                     "time_limit_s", "neighbour_range_m"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name}: expected a finite number, got {value!r}")
        if isinstance(self.nearby_k, bool) or not isinstance(self.nearby_k, int):
            raise ValueError(f"nearby_k: expected an integer >= 0, got {self.nearby_k!r}")
        if not isinstance(self.normalize_actions, bool):
            raise ValueError(f"normalize_actions: expected True or False, got {self.normalize_actions!r}")
        if not (self.accel_min_mps2 < 0 < self.accel_max_mps2):
            raise ValueError(f"need accel_min_mps2 < 0 < accel_max_mps2, got {self.accel_min_mps2}, "
                             f"{self.accel_max_mps2}")
        if self.nearby_k < 0:
            raise ValueError(f"nearby_k must be >= 0, got {self.nearby_k}")
        for name in ("lat_accel_max_mps2", "lat_speed_max_mps", "max_speed_mps", "time_limit_s",
                     "neighbour_range_m"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
