"""Discrete meta-actions (keep, faster, slower, lane left, lane right) over RoadsynthEnv, for highway-env-style agents.

Each meta-action moves a target (speed, lateral position) that persists across steps; every step a
proportional-derivative controller turns the gap to that target into the env's continuous (longitudinal,
lateral) acceleration. The lateral target is kept relative to the ego's current lane centre, not as a lane
index: SUMO's indices shift where an edge gains or loses a lane (an on-ramp's merge lane ends), while the
ego's offset only jumps by a lane width when it crosses a border. A lane change toward a lane the current edge
does not have, or that the ego may not use (a sidewalk, a parking lane), is ignored.
"""

from __future__ import annotations

import enum
import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class MetaAction(enum.IntEnum):
    KEEP = 0
    FASTER = 1
    SLOWER = 2
    LANE_LEFT = 3
    LANE_RIGHT = 4


class MetaActions(gym.ActionWrapper):
    """Discrete(5) actions (MetaAction) over a RoadsynthEnv.

    Args:
        speed_step_mps: how much FASTER / SLOWER move the target speed.
        k_speed: longitudinal gain (1/s): acceleration = k_speed x (target speed - speed).
        k_lat, d_lat: lateral gains (1/s^2, 1/s): acceleration = k_lat x lateral error - d_lat x lateral speed.
    """

    def __init__(self, env: gym.Env, *, speed_step_mps: float = 5.0, k_speed: float = 0.6, k_lat: float = 1.0,
                 d_lat: float = 1.6) -> None:
        super().__init__(env)
        self.action_space = spaces.Discrete(len(MetaAction))
        self.speed_step_mps, self.k_speed, self.k_lat, self.d_lat = speed_step_mps, k_speed, k_lat, d_lat
        self._obs: dict[str, np.ndarray] | None = None
        self._last_offset_m = 0.0
        self.target_speed_mps = 0.0
        self.target_offset_m = 0.0  # lateral target relative to the current lane's centre (positive left)

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._obs = obs
        self._last_offset_m = float(obs["ego"][3])
        self.target_speed_mps = float(obs["ego"][0])
        self.target_offset_m = 0.0
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        offset = float(obs["ego"][3])
        width = self.env.unwrapped.lane_width_m() if not (terminated or truncated) else 0.0
        if width and abs(offset - self._last_offset_m) > 0.5 * width:
            # The ego crossed a lane border: the target, relative to the new lane, moves by one lane width.
            self.target_offset_m -= width * math.copysign(1.0, self._last_offset_m)
        self._obs, self._last_offset_m = obs, offset
        return obs, reward, terminated, truncated, info

    def action(self, action) -> np.ndarray:
        inner = self.env.unwrapped
        o = inner.options
        meta = MetaAction(int(action))
        speed, lane, offset, heading = (float(v) for v in self._obs["ego"][[0, 2, 3, 4]])
        width = inner.lane_width_m()
        if meta is MetaAction.FASTER:
            self.target_speed_mps = min(self.target_speed_mps + self.speed_step_mps, o.max_speed_mps)
        elif meta is MetaAction.SLOWER:
            self.target_speed_mps = max(self.target_speed_mps - self.speed_step_mps, 0.0)
        elif meta in (MetaAction.LANE_LEFT, MetaAction.LANE_RIGHT):
            step = 1 if meta is MetaAction.LANE_LEFT else -1
            if inner.lane_drivable(int(lane) + round(self.target_offset_m / width) + step):
                self.target_offset_m += step * width
        lon = self.k_speed * (self.target_speed_mps - speed)
        error = self.target_offset_m - offset
        lat = self.k_lat * error - self.d_lat * speed * math.tan(heading)
        return inner.action_from_mps2(lon, lat)
