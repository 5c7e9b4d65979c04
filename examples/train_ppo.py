"""Train stable-baselines3 PPO on roadsynth/Highway-v0 with meta-actions, and compare it with random agents.

    pip install "roadsynth[rl]"
    python examples/train_ppo.py [--timesteps 30000] [--envs 2] [--curve docs/envs_ppo_curve.png]

The agent chooses a MetaAction (keep, faster, slower, lane left, lane right) every 0.5 s (each decision held for 5
steps of 0.1 s, their rewards summed) from the env's feature observation, normalised by VecNormalize. Training
episodes cycle over run seeds 0-7 (one demand each, built once); the evaluation uses the unseen seeds 100-109 for
the trained agent, a random meta-action agent, an agent that always keeps its lane and speed (KEEP), and a random
continuous-action agent (examples/random_agent.py), and prints the mean return of each. The learning curve
(training episode returns against env steps, with the baselines' mean returns) is saved as a PNG.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import pipeline.envs  # noqa: F401  (registers roadsynth/*)
from pipeline.envs import MetaActions

ENV_KWARGS = {"vehicles": 100, "warmup_s": 30.0, "time_limit_s": 30.0}
TRAIN_SEEDS = tuple(range(8))
EVAL_SEEDS = tuple(range(100, 110))
REPEAT = 5  # env steps per decision


class HoldAction(gym.Wrapper):
    """Each action is held for ``repeat`` env steps; the rewards are summed (the episode may end earlier)."""

    def __init__(self, env: gym.Env, repeat: int) -> None:
        super().__init__(env)
        self.repeat = repeat

    def step(self, action):
        total = 0.0
        for _ in range(self.repeat):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += reward
            if terminated or truncated:
                break
        return obs, total, terminated, truncated, info


class CycleSeeds(gym.Wrapper):
    """reset() without a seed takes the next of ``seeds`` (so each seed's demand is built once and reused)."""

    def __init__(self, env: gym.Env, seeds: tuple[int, ...], offset: int = 0) -> None:
        super().__init__(env)
        self.seeds, self.count = seeds, offset

    def reset(self, *, seed=None, options=None):
        if seed is None:
            seed = self.seeds[self.count % len(self.seeds)]
            self.count += 1
        return self.env.reset(seed=seed, options=options)


def make_meta_env(seeds: tuple[int, ...] = TRAIN_SEEDS, offset: int = 0) -> gym.Env:
    from stable_baselines3.common.monitor import Monitor

    env = gym.make("roadsynth/Highway-v0", **ENV_KWARGS, disable_env_checker=True)
    return Monitor(CycleSeeds(HoldAction(MetaActions(env), REPEAT), seeds, offset))


def evaluate(policy, env: gym.Env, seeds: tuple[int, ...]) -> list[float]:
    """Return of one episode per seed; ``policy(obs)`` gives the action."""
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total, done = total + reward, terminated or truncated
        returns.append(total)
    return returns


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=30000, help="decisions to train for (x 5 env steps)")
    parser.add_argument("--envs", type=int, default=2, help="training envs, one process each")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--curve", type=Path, default=Path("docs/envs_ppo_curve.png"))
    args = parser.parse_args()

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    torch.set_num_threads(1)
    venv = VecNormalize(SubprocVecEnv([lambda i=i: make_meta_env(offset=i * 3) for i in range(args.envs)]),
                        norm_obs=True, norm_reward=False)
    model = PPO("MultiInputPolicy", venv, n_steps=256, batch_size=128, n_epochs=5, gamma=0.95, learning_rate=5e-4,
                seed=args.seed, verbose=0, device="cpu")
    start = time.perf_counter()
    model.learn(total_timesteps=args.timesteps)
    train_s = time.perf_counter() - start
    curve = [(float(t), float(r)) for t, r in _monitor_curve(venv)]
    venv.training = False

    eval_env = make_meta_env(EVAL_SEEDS)

    def trained(obs):
        return int(model.predict(venv.normalize_obs({k: v[None] for k, v in obs.items()}), deterministic=True)[0][0])

    rng = np.random.default_rng(args.seed)
    results = {"PPO (meta-actions)": evaluate(trained, eval_env, EVAL_SEEDS),
               "random meta-actions": evaluate(lambda _: int(rng.integers(5)), eval_env, EVAL_SEEDS),
               "always KEEP": evaluate(lambda _: 0, eval_env, EVAL_SEEDS)}
    eval_env.close()
    continuous = gym.make("roadsynth/Highway-v0", **ENV_KWARGS)
    continuous.action_space.seed(args.seed)
    results["random continuous"] = evaluate(lambda _: continuous.action_space.sample(), continuous, EVAL_SEEDS)
    continuous.close()
    venv.close()

    print(f"trained {args.timesteps} decisions ({args.timesteps * REPEAT} env steps) in {train_s:.0f} s "
          f"with {args.envs} envs")
    print(f"{'agent':<22} {'mean return':>11}  returns on seeds {EVAL_SEEDS[0]}-{EVAL_SEEDS[-1]}")
    for name, returns in results.items():
        print(f"{name:<22} {np.mean(returns):>11.1f}  {', '.join(f'{r:.1f}' for r in returns)}")
    _plot(curve, results, args.curve, train_s)


def _monitor_curve(venv) -> list[tuple[int, float]]:
    """(cumulative decisions at the episode's end, episode return) of every training episode, in order of end."""
    rows = []
    per_env = zip(venv.env_method("get_episode_rewards"), venv.env_method("get_episode_lengths"),
                  venv.env_method("get_episode_times"), strict=True)
    for rewards, lengths, times in per_env:
        rows += [(t, r, n) for r, n, t in zip(rewards, lengths, times, strict=True)]
    rows.sort()
    total, curve = 0, []
    for _, reward, length in rows:
        total += length
        curve.append((total, reward))
    return curve


def _plot(curve, results, path: Path, train_s: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps, returns = np.array(curve).T if curve else (np.zeros(0), np.zeros(0))
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(steps * REPEAT, returns, ".", alpha=0.3, color="tab:blue", label="PPO training episodes")
    if len(returns) >= 10:
        window = 10
        ax.plot(steps[window - 1:] * REPEAT, np.convolve(returns, np.ones(window) / window, "valid"),
                color="tab:blue", label="PPO, mean of 10 episodes")
    for (name, values), colour in zip(results.items(), ("tab:green", "tab:orange", "tab:red", "tab:gray"), strict=True):
        seeds = f"seeds {EVAL_SEEDS[0]}-{EVAL_SEEDS[-1]}"
        ax.axhline(np.mean(values), color=colour, ls="--", label=f"{name}: {np.mean(values):.1f} ({seeds})")
    ax.set_xlabel("env steps (0.1 s each)")
    ax.set_ylabel("episode return")
    ax.set_title(f"roadsynth/Highway-v0, 100 vehicles, 30 s episodes; {train_s / 60:.1f} min of training")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    print(f"learning curve: {path}")


if __name__ == "__main__":
    main()
