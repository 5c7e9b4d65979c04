"""Benchmark: steps/s of RoadsynthEnv with feature observations against a bare libsumo step loop.

Both run the same network, the same demand and SUMO seed (the env's own .sumocfg for that seed) from the end of
the same warm-up, for --steps steps; the bare loop only calls simulationStep(). The env adds the ego's kinematic
model, moveToXY, collision/off-road checks, the neighbour queries, the observation and the reward. Prints
steps/s of each (best of --repeat) and their ratio (issue 27 aims at <= 1.5x).

    python bench/bench_env.py [--scenario highway] [--vehicles 200] [--steps 300] [--repeat 3] [--seed 1] [--nearby-k 0]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import pipeline.envs  # noqa: F401  (registers the envs)
from pipeline.traffic.simulation import close_sumo, start_sumo


def bare_steps_per_s(sumocfg, warmup_steps: int, steps: int) -> float:
    sumo = start_sumo(["-c", str(sumocfg), "--no-warnings", "true", "--no-step-log", "true"], "bench")
    try:
        for _ in range(warmup_steps):
            sumo.simulationStep()
        start = time.perf_counter()
        for _ in range(steps):
            sumo.simulationStep()
        return steps / (time.perf_counter() - start)
    finally:
        close_sumo("bench")


def env_steps_per_s(env: gym.Env, seed: int, steps: int) -> tuple[float, int]:
    """Steps/s over ``steps`` steps of a zero action (hold speed and lane); episodes that end are reset untimed."""
    env.reset(seed=seed)
    action = np.zeros(2, dtype=np.float32)
    elapsed, ends = 0.0, 0
    for _ in range(steps):
        start = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        elapsed += time.perf_counter() - start
        if terminated or truncated:
            ends += 1
            env.reset(seed=seed)
    return steps / elapsed, ends


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="highway")
    parser.add_argument("--vehicles", type=int, default=200)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--nearby-k", type=int, default=0, help="rows of the 'nearby' observation (0: none)")
    args = parser.parse_args()

    env = gym.make("roadsynth/Scenario-v0", scenario=args.scenario, vehicles=args.vehicles,
                   time_limit_s=max(60.0, args.steps * 0.2), nearby_k=args.nearby_k)
    inner = env.unwrapped
    try:
        sumocfg, _, _ = inner.sumo_inputs(args.seed)
        # The env's reset steps warm-up + 1 times before its first step.
        warmup_steps = round(inner.sim.warmup_s / inner.sim.step_length_s) + 1
        bare = max(bare_steps_per_s(sumocfg, warmup_steps, args.steps) for _ in range(args.repeat))
        runs = [env_steps_per_s(env, args.seed, args.steps) for _ in range(args.repeat)]
        feat, ends = max(r[0] for r in runs), sum(r[1] for r in runs)
    finally:
        env.close()
    print(f"scenario {args.scenario}, {args.vehicles} vehicles, nearby_k {args.nearby_k}, seed {args.seed}, "
          f"{args.steps} steps of "
          f"{inner.sim.step_length_s:g} s after a {inner.sim.warmup_s:g} s warm-up, best of {args.repeat}")
    print(f"{'loop':<28}{'steps/s':>10}{'ms/step':>10}")
    print(f"{'bare libsumo simulationStep':<28}{bare:>10.0f}{1000 / bare:>10.2f}")
    print(f"{'RoadsynthEnv (features)':<28}{feat:>10.0f}{1000 / feat:>10.2f}")
    print(f"env / bare cost ratio: {bare / feat:.2f}x (target <= 1.5x); episodes ended and reset untimed: {ends}")


if __name__ == "__main__":
    main()
