"""A random agent on roadsynth/Highway-v0: the smallest complete use of the environment (docs/envs.md).

    python examples/random_agent.py [--episodes 3] [--vehicles 100] [--seed 0]
"""

from __future__ import annotations

import argparse

import gymnasium as gym

import pipeline.envs  # noqa: F401  (registers roadsynth/*)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    env = gym.make("roadsynth/Highway-v0", vehicles=args.vehicles, time_limit_s=30.0)
    env.action_space.seed(args.seed)
    try:
        for episode in range(args.episodes):
            _, info = env.reset(seed=args.seed + episode)
            total, steps, done = 0.0, 0, False
            while not done:
                _, reward, terminated, truncated, info = env.step(env.action_space.sample())
                total, steps, done = total + reward, steps + 1, terminated or truncated
            print(f"episode {episode} (seed {info['run_seed']}, ego {info['ego_id']}): {steps} steps, "
                  f"return {total:.1f}, ended by {info['reason']}")
    finally:
        env.close()


if __name__ == "__main__":
    main()
