"""Benchmark: steps/s of RoadsynthEnv with feature observations against a bare libsumo step loop, with camera +
LiDAR against the render stage's frames/s, and highway-env's highway-v0 / highway-fast-v0 beside them.

Features: both run the same network, the same demand and SUMO seed (the env's own .sumocfg for that seed) from the
end of the same warm-up, for --steps steps; the bare loop only calls simulationStep(). The env adds the ego's
kinematic model, moveToXY, collision/off-road checks, the neighbour queries, the observation and the reward.
Prints steps/s of each (best of --repeat) and their ratio (issue 27 aims at <= 1.5x).

Sensors (--sensor-steps N > 0): the env with sensors=["camera", "lidar"] (default rig, noon) drives N steps and
records them (record=); then ``roadsynth render`` renders that recorded run (all N + 1 frames, --render-workers
processes, default all cores) with the same rig and condition. Prints the env's steps/s (without and with its
reset, which builds the static world) and render's frames/s (the whole stage: static world, workers, PNG and
Parquet writing); issue 27 aims at env >= 80% of render.

Perception (--perception MODEL.onnx or a model folder): the same camera + LiDAR env, default rig, noon, without and
with perception in the loop (``perception=MODEL``: the detector on every frame, LiDAR ranging, the tracker;
docs/closedloop.md), --perception-steps steps each after an untimed reset; prints the cost perception adds per
step (issue 42 aims at <= 15 % with YOLOX-nano on the CPU).

highway-env (if installed; it is not a roadsynth dependency): steps/s of highway-v0 and highway-fast-v0 with their
default config and a constant IDLE action (resets untimed). One of their steps is a 1 s policy step (15 or 5
simulation steps); one of ours is 0.1 s, so the table also gives simulated seconds per second.

    python bench/bench_env.py [--scenario highway] [--vehicles 200] [--steps 300] [--repeat 3] [--seed 1]
        [--nearby-k 0] [--sensor-steps 20] [--render-workers N] [--highway-env-steps 100]
        [--perception MODEL.onnx] [--perception-steps 10]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

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


def sensor_steps_per_s(args, record_root: Path) -> tuple[float, float, int, Path]:
    """The sensor env's steps/s without and with its reset, the steps taken, and the recorded run."""
    env = gym.make("roadsynth/Scenario-v0", scenario=args.scenario, vehicles=args.vehicles,
                   time_limit_s=args.sensor_steps * 0.1 + 10.0, sensors=["camera", "lidar"], record=record_root)
    action = np.zeros(2, dtype=np.float32)
    try:
        start = time.perf_counter()
        env.reset(seed=args.seed)
        reset_s = time.perf_counter() - start
        start = time.perf_counter()
        steps = 0
        for _ in range(args.sensor_steps):
            _, _, terminated, truncated, _ = env.step(action)
            steps += 1
            if terminated or truncated:
                break
        elapsed = time.perf_counter() - start
    finally:
        env.close()  # writes the recorded episode (untimed)
    return steps / elapsed, steps / (elapsed + reset_s), steps, record_root / "episode-0000"


def render_frames_per_s(sim_dir: Path, out: Path, workers: int) -> tuple[float, int]:
    from pipeline.core.config import ConditionConfig, RigConfig, load_config
    from pipeline.stages.render import render

    rig, _ = load_config(RigConfig, "default", "rigs")
    noon, _ = load_config(ConditionConfig, "noon", "conditions")
    start = time.perf_counter()
    summary = render(sim_dir, noon, rig, out, workers=workers, progress=False)
    return summary["frames"] / (time.perf_counter() - start), summary["frames"]


def camera_steps_per_s(args, perception: str | None) -> float:
    """Steps/s of the camera + LiDAR env (default rig, noon), with perception in the loop when given."""
    env = gym.make("roadsynth/Scenario-v0", scenario=args.scenario, vehicles=args.vehicles,
                   time_limit_s=args.perception_steps * 0.1 + 10.0, sensors=["camera", "lidar"],
                   perception=perception)
    action = np.zeros(2, dtype=np.float32)
    try:
        env.reset(seed=args.seed)
        start = time.perf_counter()
        for _ in range(args.perception_steps):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                raise RuntimeError("the episode ended during the perception bench; use fewer --perception-steps")
        return args.perception_steps / (time.perf_counter() - start)
    finally:
        env.close()


def highway_env_steps_per_s(env_id: str, steps: int) -> float | None:
    try:
        import highway_env  # noqa: F401  (registers highway-v0, highway-fast-v0)
    except ImportError:
        return None
    env = gym.make(env_id)
    idle = 1  # DiscreteMetaAction: 0 LANE_LEFT, 1 IDLE, 2 LANE_RIGHT, 3 FASTER, 4 SLOWER
    try:
        env.reset(seed=0)
        elapsed = 0.0
        for _ in range(steps):
            start = time.perf_counter()
            _, _, terminated, truncated, _ = env.step(idle)
            elapsed += time.perf_counter() - start
            if terminated or truncated:
                env.reset()
    finally:
        env.close()
    return steps / elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="highway")
    parser.add_argument("--vehicles", type=int, default=200)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--nearby-k", type=int, default=0, help="rows of the 'nearby' observation (0: none)")
    parser.add_argument("--sensor-steps", type=int, default=20, help="steps with camera + LiDAR (0: skip)")
    parser.add_argument("--render-workers", type=int, default=os.cpu_count() or 1,
                        help="the render stage's processes (default: all cores, as `roadsynth render`)")
    parser.add_argument("--highway-env-steps", type=int, default=100, help="steps of each highway-env env (0: skip)")
    parser.add_argument("--perception", help="an ONNX detector or model folder: time perception in the loop")
    parser.add_argument("--perception-steps", type=int, default=10, help="camera steps timed with and without it")
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

    if args.sensor_steps > 0:
        with tempfile.TemporaryDirectory(prefix="bench-env-") as tmp:
            sensors, sensors_reset, steps, run = sensor_steps_per_s(args, Path(tmp) / "episodes")
            render_fps, frames = render_frames_per_s(run, Path(tmp) / "record", args.render_workers)
        print(f"\ncamera 800x600 + LiDAR 64x1800 (default rig, noon), {steps} env steps; render of the recorded "
              f"run ({frames} frames, {args.render_workers} workers), {os.cpu_count()} cores, "
              f"load average {os.getloadavg()[0]:.1f}")
        print(f"{'loop':<40}{'frames/s':>10}{'vs render':>11}")
        print(f"{'roadsynth render (whole stage)':<40}{render_fps:>10.2f}{1.0:>11.2f}")
        print(f"{'RoadsynthEnv (camera + LiDAR) steps':<40}{sensors:>10.2f}{sensors / render_fps:>11.2f}")
        print(f"{'  the same with its reset':<40}{sensors_reset:>10.2f}{sensors_reset / render_fps:>11.2f}")
        print("target: env >= 0.80 x render")

    if args.perception:
        plain = camera_steps_per_s(args, None)
        perceived = camera_steps_per_s(args, args.perception)
        print(f"\ncamera + LiDAR env (default rig, noon), {args.perception_steps} steps each, perception "
              f"{args.perception}, load average {os.getloadavg()[0]:.1f}")
        print(f"{'loop':<40}{'steps/s':>10}{'ms/step':>10}")
        print(f"{'camera + LiDAR':<40}{plain:>10.2f}{1000 / plain:>10.0f}")
        print(f"{'camera + LiDAR + perception':<40}{perceived:>10.2f}{1000 / perceived:>10.0f}")
        print(f"perception adds {100 * (plain / perceived - 1):.1f} % per step (target <= 15 %)")

    if args.highway_env_steps > 0:
        rows = [(name, highway_env_steps_per_s(name, args.highway_env_steps), 1.0)
                for name in ("highway-v0", "highway-fast-v0")]
        rows.append(("roadsynth/Highway-v0 (features)", feat, inner.sim.step_length_s))
        print(f"\n{'env':<34}{'steps/s':>10}{'sim s per step':>16}{'sim s/s':>10}")
        for name, rate, step_s in rows:
            if rate is None:
                print(f"{name:<34}{'highway-env not installed':>36}")
                continue
            print(f"{name:<34}{rate:>10.1f}{step_s:>16g}{rate * step_s:>10.1f}")


if __name__ == "__main__":
    main()
