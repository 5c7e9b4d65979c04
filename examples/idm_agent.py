"""A rule-based agent: IDM car following on the observed leader, PD lane keeping; compared with a random agent.

The IDM (Treiber, Hennecke & Helbing 2000) acceleration is
a = a_max (1 - (v / v0)^4 - (s* / s)^2), s* = s0 + v T + v dv_closing / (2 sqrt(a_max b)),
with s the bumper-to-bumper gap to the leader (centre distance minus half of both lengths).
No lane changes yet (docs/envs.md lists what is left).

    python examples/idm_agent.py [--episodes 3] [--vehicles 100] [--seed 0]
"""

from __future__ import annotations

import argparse
import math

import gymnasium as gym
import numpy as np

import pipeline.envs  # noqa: F401  (registers roadsynth/*)
from pipeline.envs.features import NEIGHBOUR_SLOTS

LEADER = NEIGHBOUR_SLOTS.index("leader")


def idm_action(env: gym.Env, obs: dict[str, np.ndarray], *, v0_mps: float = 30.0, time_gap_s: float = 1.5,
               min_gap_m: float = 2.0, a_max: float = 1.5, b: float = 2.0) -> np.ndarray:
    inner = env.unwrapped
    speed, offset, heading = (float(v) for v in obs["ego"][[0, 3, 4]])
    accel = a_max * (1.0 - (speed / v0_mps) ** 4)
    present, ds, _, dv, length, _ = obs["neighbours"][LEADER]
    if present:
        gap = max(float(ds) - 0.5 * (float(length) + inner.ego_length_m()), 0.1)
        closing = -float(dv)
        desired = min_gap_m + max(speed * time_gap_s + speed * closing / (2.0 * math.sqrt(a_max * b)), 0.0)
        accel -= a_max * (desired / gap) ** 2
    lat = -1.0 * offset - 1.6 * speed * math.tan(heading)
    return inner.action_from_mps2(accel, lat)


def run(env: gym.Env, seed: int, policy) -> tuple[float, int, str]:
    obs, info = env.reset(seed=seed)
    total, steps, done = 0.0, 0, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total, steps, done = total + reward, steps + 1, terminated or truncated
    return total, steps, info["reason"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    env = gym.make("roadsynth/Highway-v0", vehicles=args.vehicles, time_limit_s=30.0)
    env.action_space.seed(args.seed)
    try:
        for name, policy in (("random", lambda obs: env.action_space.sample()),
                             ("idm", lambda obs: idm_action(env, obs))):
            returns = []
            for episode in range(args.episodes):
                total, steps, reason = run(env, args.seed + episode, policy)
                returns.append(total)
                print(f"{name:>6} seed {args.seed + episode}: {steps} steps, return {total:.1f}, ended by {reason}")
            print(f"{name:>6} mean return {np.mean(returns):.1f}")
    finally:
        env.close()


if __name__ == "__main__":
    main()
