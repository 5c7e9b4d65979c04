"""``roadsynth closedloop``: drive the same traffic on ground truth and on perception, and compare (issue 42).

For every (scenario, seed, condition) of a :class:`pipeline.core.config.closedloop.ClosedLoopConfig`, the agent
(the reference IDM + MOBIL driver, :mod:`pipeline.envs.driver`) drives one episode on the ground-truth features
and one on the features of :class:`pipeline.envs.perception.PerceivedFeatures` (the detector on the rendered
camera, ranged by the LiDAR, tracked), with the same seed, hence the same network, demand and warm-up. Each step
logs the ego's speed and acceleration and the ground-truth leader (:mod:`pipeline.envs.closedloop_metrics`).
Writes, into ``--out`` (atomically): ``metrics.json`` (every episode's metrics, and per condition and per
(scenario, condition) the perceived - ground-truth differences with bootstrap intervals over seeds),
``report.md``, a plot per condition (``plots/CONDITION.png``) and ``meta.json``; with ``--record``, each episode as
a simulated run under ``episodes/`` (``roadsynth render`` and ``export`` read it; Foxglove through the MCAP export).

An experiment is hours of CPU: each finished episode is kept in ``OUT.partial/`` (its row, and its recording with
``--record``) beside the output, so an interrupted run resumes where it stopped when the same command is run again.
The kept rows are used only while the settings an episode depends on are unchanged (the config without its
name, description and lists, and the detector file's bytes: :func:`episode_fingerprint`); otherwise, or with
``--restart``, they are discarded. ``OUT.partial/`` is removed once ``OUT`` is written.

This module is the command's: it sits in ``pipeline/envs/`` because it drives the environment (the layer above
the stages); the CLI loads it by name like the stage modules.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np

from pipeline.core.config import load_config
from pipeline.core.config.closedloop import ClosedLoopConfig
from pipeline.envs.closedloop_metrics import (
    LEADER_HELD,
    LEADER_RANGE_BINS_M,
    METRICS,
    EpisodeLog,
    compare,
    episode_metrics,
    holds_leader,
)
from pipeline.envs.features import NEIGHBOUR_FIELDS, NEIGHBOUR_SLOTS
from pipeline.stages.executor import ExecutorSpec

log = logging.getLogger(__name__)

HELP = "drive each episode on ground truth and on perception; compare safety and progress per condition"
INPUT_ARGS = ("config",)
INTERRUPT_HINT = "the output is as it was; finished episodes are kept in OUT.partial/: rerun to resume"
MODES = ("ground_truth", "perceived")
_LEADER = NEIGHBOUR_SLOTS.index("leader")
_AHEAD = [NEIGHBOUR_SLOTS.index(s) for s in ("left_leader", "leader", "right_leader")]  # what a front camera sees
_COL = {name: k for k, name in enumerate(NEIGHBOUR_FIELDS)}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pipeline.stages.executor import add_executor_arguments

    parser.add_argument("config", help="a closed-loop config NAME (configs/closedloop/) or YAML PATH")
    parser.add_argument("--out", type=Path, required=True, help="output folder (replaced atomically)")
    parser.add_argument("--record", action="store_true", help="also record every episode as a simulated run (with "
                        "--executor ray, --out must be on storage every worker shares)")
    parser.add_argument("--restart", action="store_true", help="discard the episodes an interrupted run kept in "
                        "OUT.partial/ and run all again")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_executor_arguments(parser)


def load_detector(spec: str, config_file: Path):
    """The detector of a config's ``detector`` value (``onnx:PATH`` or ``baseline:DIR``), PATH relative to the
    config file; a missing file is an error naming the config file and the field."""
    kind, _, path = spec.partition(":")
    target = Path(path) if Path(path).is_absolute() else (config_file.parent / path)
    if not target.exists():
        raise ValueError(f"{config_file}: detector: {target} does not exist")
    if kind == "onnx":
        from pipeline.detect.onnx import OnnxDetector

        return OnnxDetector(target, batch_size=1)
    from pipeline.detect.infer import Detector

    return Detector.load(target)


def _leader(env, neighbours: np.ndarray) -> tuple[str, float, float]:
    """The ground-truth leader: (SUMO id, bumper-to-bumper gap, closing speed), ("", nan, nan) without one."""
    inner = env.unwrapped
    row = neighbours[_LEADER]
    if row[_COL["present"]] < 0.5:
        return "", float("nan"), float("nan")
    found = inner._sumo.vehicle.getLeader(inner.ego_id, float(inner.options.neighbour_range_m))
    gap = float(row[_COL["ds_m"]]) - 0.5 * (float(row[_COL["length_m"]]) + inner.ego_length_m())
    return (found[0] if found else "?"), gap, -float(row[_COL["dv_mps"]])


def run_episode(config: ClosedLoopConfig, scenario: str, seed: int, condition: str, detector=None,
                record: Path | None = None) -> tuple[EpisodeLog, str, dict | None]:
    """One episode of the reference agent: on ground-truth features (``detector`` None) or on perceived ones.
    Returns its log, how it ended (the env's ``reason``) and, if it ended in a collision, what the ego hit (the env's
    ``info["collision"]``, with ``time_s`` added)."""
    import gymnasium as gym

    import pipeline.envs  # noqa: F401  (registers the envs)
    from pipeline.envs.driver import ReferenceAgent
    from pipeline.envs.perception import PerceivedFeatures
    from pipeline.envs.tracker import TrackerParams

    kwargs = {"scenario": scenario, "time_limit_s": config.episode_s, "vehicles": config.vehicles,
              "warmup_s": config.warmup_s, "record": record}
    if detector is None:
        env = gym.make("roadsynth/Scenario-v0", **kwargs)
    else:
        env = PerceivedFeatures(gym.make("roadsynth/Scenario-v0", sensors=["camera", "lidar"], rig=config.rig,
                                         condition=condition, **kwargs), detector,
                                max_detections=config.max_detections,
                                tracker=TrackerParams(birth_score=config.birth_score))
    try:
        obs, info = env.reset(seed=seed)
        agent = ReferenceAgent(env)
        agent.reset(obs)
        episode = EpisodeLog.empty(env.unwrapped.sim.step_length_s)
        while True:
            obs, _, terminated, truncated, info = env.step(agent.act(obs))
            truth = info["ground_truth"]["neighbours"] if detector is not None else obs["neighbours"]
            lid, gap, closing = _leader(env, truth) if not (terminated or truncated) else ("", np.nan, np.nan)
            columns = [_COL["present"], _COL["ds_m"], _COL["dv_mps"]]
            episode.add(float(obs["ego"][0]), float(obs["ego"][1]), lid, gap, closing,
                        holds_leader(truth[_LEADER], obs["neighbours"][_LEADER]))
            episode.add_slots(truth[_AHEAD][:, columns], obs["neighbours"][_AHEAD][:, columns])
            episode.add_path(info["ground_truth"]["path"] if detector is not None else obs["path"], obs["path"])
            if terminated or truncated:
                episode.collided = info.get("reason") == "collision"
                hit = {**info["collision"], "time_s": float(info["time_s"])} if "collision" in info else None
                return episode, str(info.get("reason")), hit
    finally:
        env.close()


def episode_row(config: ClosedLoopConfig, config_file: Path, scenario: str, seed: int, condition: str, mode: str,
                record: Path | None) -> dict:
    """One episode as a row of metrics.json: a task of :func:`closedloop`, here or on a Ray worker (which loads the
    detector itself: a session does not travel)."""
    detector = load_detector(config.detector, config_file) if mode == "perceived" else None
    if record is not None and record.exists():  # what an interrupted attempt at this episode left
        shutil.rmtree(record)
    episode, reason, hit = run_episode(config, scenario, seed, condition, detector, record)
    return {"scenario": Path(scenario).stem, "seed": seed, "condition": Path(condition).stem, "mode": mode,
            "end": reason, "steps": len(episode.speed_mps), "metrics": episode_metrics(episode), "collision": hit}


def episode_fingerprint(config: ClosedLoopConfig, config_file: Path) -> str:
    """What an episode's row depends on besides its (scenario, seed, condition, mode): the config without its name,
    description and lists, and the detector file's (or model folder's) bytes. Rows kept by an interrupted run are
    reused only under the same fingerprint. Code changes are not in it: after one, resume with ``--restart``."""
    fields = config.model_dump(exclude={"name", "description", "scenarios", "seeds", "conditions"})
    digest = hashlib.sha256(json.dumps(fields, sort_keys=True).encode())
    _, _, path = config.detector.partition(":")
    target = Path(path) if Path(path).is_absolute() else (config_file.parent / path)
    for file in sorted(target.rglob("*")) if target.is_dir() else [target]:
        if file.is_file():
            digest.update(file.name.encode())
            with file.open("rb") as handle:
                for block in iter(lambda: handle.read(1 << 20), b""):
                    digest.update(block)
    return digest.hexdigest()


def _partial_folder(out: Path, fingerprint: str, restart: bool) -> Path:
    """``OUT.partial/``, emptied when ``restart`` or when it was kept under another fingerprint."""
    partial = out.with_name(out.name + ".partial")
    stamp = partial / "fingerprint.txt"
    if partial.exists() and (restart or not stamp.is_file() or stamp.read_text().strip() != fingerprint):
        if not restart:
            log.warning("%s holds episodes of other settings: starting again", partial)
        shutil.rmtree(partial)
    (partial / "rows").mkdir(parents=True, exist_ok=True)
    if not stamp.is_file():
        stamp.write_text(fingerprint + "\n")
    return partial


def _keep_row(partial: Path, name: str, row: dict) -> None:
    """Write one finished episode's row (atomically: a row file is whole or absent)."""
    target = partial / "rows" / f"{name}.json"
    tmp = target.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(_finite(row), sort_keys=True))
    os.replace(tmp, target)


def closedloop(config: ClosedLoopConfig, config_file: Path, out: Path, *, record: bool = False,
               progress: bool = True, executor: ExecutorSpec | None = None, restart: bool = False) -> dict:
    """Run every episode twice and write the outputs into ``out`` (see the module docstring); returns metrics.
    ``executor``: where the episodes run (:mod:`pipeline.stages.executor`: here, one after the other, by default; on
    Ray, each in a fresh worker process, as libsumo runs one simulation per process); the rows keep the config's
    order either way, so the outputs are the same. Episodes an interrupted run kept in ``OUT.partial/`` are not run
    again (``restart``: they are)."""
    from tqdm import tqdm

    from pipeline.stages.common import atomic_output_dir, write_json, write_meta
    from pipeline.stages.executor import Task, run_tasks

    executor = executor or ExecutorSpec("local")
    load_detector(config.detector, config_file)  # a missing or bad detector fails before any episode runs
    out = Path(out)
    partial = _partial_folder(out, episode_fingerprint(config, config_file), restart)
    episodes = [(s, n, c) for s in config.scenarios for n in config.seeds for c in config.conditions]
    names, rows_by_name, tasks = [], {}, []
    for scenario, seed, condition in episodes:
        for mode in MODES:
            name = f"{Path(scenario).stem}-{seed}-{Path(condition).stem}-{mode}"
            names.append(name)
            kept = partial / "rows" / f"{name}.json"
            if kept.is_file() and (not record or (partial / "episodes" / name).is_dir()):
                rows_by_name[name] = json.loads(kept.read_text())
                continue
            tasks.append(Task(name, episode_row, (config, config_file, scenario, seed, condition, mode,
                                                  partial / "episodes" / name if record else None),
                              fresh_process=True))
    if rows_by_name:
        log.info("resuming: %d of %d episodes were kept in %s", len(rows_by_name), len(names), partial)
    bar = tqdm(total=len(names), initial=len(rows_by_name), disable=not progress, desc="closed-loop episodes",
               unit="episode")

    def done(i: int, row: dict) -> None:
        _keep_row(partial, tasks[i].label, row)
        bar.update()

    for task, row in zip(tasks, run_tasks(tasks, executor, on_done=done, hint="finished episodes are kept in "
                                          f"{partial}: rerun to resume", noun="episodes"), strict=True):
        rows_by_name[task.label] = json.loads(json.dumps(_finite(row), sort_keys=True))  # as a kept row reads
    bar.close()
    rows = [rows_by_name[name] for name in names]
    with atomic_output_dir(out) as tmp:
        comparisons = _comparisons(rows)
        metrics = {"episodes": rows, "comparisons": comparisons, "metric_names": list(METRICS)}
        write_json(tmp / "metrics.json", _finite(metrics))
        (tmp / "report.md").write_text(_report(config, rows, comparisons))
        _plots(comparisons, tmp / "plots")
        if record:
            (tmp / "episodes").mkdir()
            for name in names:
                shutil.copytree(partial / "episodes" / name, tmp / "episodes" / name)
        write_meta(tmp, stage="closedloop", config=config.model_dump(), seed=None)
    shutil.rmtree(partial)
    return metrics


def _comparisons(rows: list[dict]) -> dict[str, list[dict]]:
    """Perceived vs ground truth per condition (all scenarios) and per scenario/condition."""
    groups: dict[str, list[tuple[dict, dict]]] = {}
    for r in rows:
        if r["mode"] != "perceived":
            continue
        gt = next(g for g in rows if g["mode"] == "ground_truth" and
                  (g["scenario"], g["seed"], g["condition"]) == (r["scenario"], r["seed"], r["condition"]))
        for key in (r["condition"], f"{r['scenario']}/{r['condition']}"):
            groups.setdefault(key, []).append((r["metrics"], gt["metrics"]))
    return {key: [c.as_dict() for c in compare([p for p, _ in pairs], [g for _, g in pairs])]
            for key, pairs in groups.items()}


def _finite(value):
    """JSON-safe: non-finite floats as None (metrics.json is strict JSON)."""
    if isinstance(value, float):
        return value if np.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


def _fmt(value: float) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.3g}"


def _report(config: ClosedLoopConfig, rows: list[dict], comparisons: dict[str, list[dict]]) -> str:
    lines = [f"# Closed loop: {config.name}", "", config.description, "",
             f"Agent: {config.agent} (IDM + MOBIL). Detector: `{config.detector}`. Episodes of {config.episode_s:g} s "
             f"after the warm-up; seeds {', '.join(map(str, config.seeds))}. Each episode driven twice with the same "
             "seed: on ground-truth features and on perceived ones (docs/closedloop.md). Differences are perceived "
             "minus ground truth, with a 95 % bootstrap interval over seeds.", ""]
    ends = {}
    for r in rows:
        ends.setdefault((r["mode"], r["end"]), 0)
        ends[(r["mode"], r["end"])] += 1
    lines += ["Episode ends: " + ", ".join(f"{mode} {end}: {n}" for (mode, end), n in sorted(ends.items())), ""]
    hits = [r for r in rows if r.get("collision")]
    if hits:
        lines += ["Collisions (SUMO's record of each: the other party, SUMO's collision type, the lane):", "",
                  "| scenario | condition | seed | mode | s into the episode | hit | its type | ego m/s | its m/s | "
                  "SUMO type | lane |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in sorted(hits, key=lambda r: (r["scenario"], r["condition"], r["seed"], r["mode"])):
            c = r["collision"]
            lines.append(f"| {r['scenario']} | {r['condition']} | {r['seed']} | {r['mode']} | {c['time_s']:.1f} | "
                         f"{c['other_kind']} {c['other']} | {c['other_type']} | {c['ego_speed_mps']:.1f} | "
                         f"{c['other_speed_mps']:.1f} | {c['type']} | {c['lane']} |")
        lines.append("")
    for key, table in comparisons.items():
        lines += [f"## {key}", "", "| metric | perceived | ground truth | difference | 95 % interval | seeds |",
                  "|---|---|---|---|---|---|"]
        for c in table:
            lines.append(f"| {c['metric']} | {_fmt(c['perceived'])} | {_fmt(c['ground_truth'])} | "
                         f"{_fmt(c['difference'])} | [{_fmt(c['ci_low'])}, {_fmt(c['ci_high'])}] | {c['seeds']} |")
        if "/" not in key:
            lines += ["", f"![{key}](plots/{key}.png)"]
        lines.append("")
    lines += ["## The lead vehicle by range", "", "![lead vehicle held by range](plots/leader_by_range.png)", ""]
    return "\n".join(lines)


def _plots(comparisons: dict[str, list[dict]], folder: Path) -> None:
    """One figure per condition: per metric, the perceived and ground-truth means as bars, the perceived bar's whisker
    the ground-truth mean plus the 95 % interval of the paired difference (where the difference is defined)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    for key, table in comparisons.items():
        if "/" in key:
            continue
        cols = 4
        rows = -(-len(table) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.3 * rows), squeeze=False)
        for ax, c in zip(axes.flat, table, strict=False):
            values = [v if v is not None and np.isfinite(v) else 0.0 for v in (c["perceived"], c["ground_truth"])]
            ax.bar([0, 1], values, color=["#c0504d", "#4f81bd"])
            top = max(values)
            interval = [c[k] for k in ("ci_low", "ci_high", "ground_truth")]
            if all(v is not None and np.isfinite(v) for v in interval):
                low, high = values[1] + c["ci_low"], values[1] + c["ci_high"]
                ax.errorbar([0], [values[0]], yerr=[[max(values[0] - low, 0.0)], [max(high - values[0], 0.0)]],
                            color="black", capsize=3, linewidth=1)
                top = max(top, high)
            ax.set_ylim(min(0.0, *values) * 1.15, max(top * 1.15, 1e-3))
            ax.set_xticks([0, 1], ["perceived", "truth"])
            ax.set_title(f"{c['metric'].replace('_', ' ')} (n {c['seeds']})", fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in list(axes.flat)[len(table):]:
            ax.axis("off")
        fig.suptitle(f"{key}: perceived vs ground truth (whisker: 95 % interval of the paired difference)", fontsize=9)
        fig.tight_layout()
        fig.savefig(folder / f"{key}.png", dpi=100, metadata={"Software": "roadsynth closedloop"})
        plt.close(fig)
    _leader_by_range_plot(comparisons, folder, plt)


def _leader_by_range_plot(comparisons: dict[str, list[dict]], folder: Path, plt) -> None:
    """``leader_by_range.png``: per condition (all scenarios), the perceived lead vehicle's recall by its range
    (the ``leader_held_*`` metrics: episodes' means, with the paired difference's 95 % interval as a band)."""
    centres = 0.5 * (np.asarray(LEADER_RANGE_BINS_M[:-1]) + np.asarray(LEADER_RANGE_BINS_M[1:]))
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    for key, table in comparisons.items():
        if "/" in key:
            continue
        rows = {c["metric"]: c for c in table}
        mean, low, high = (np.array([np.nan if rows[m][k] is None else rows[m][k] for m in LEADER_HELD], float)
                           for k in ("perceived", "ci_low", "ci_high"))
        line, = ax.plot(centres, mean, marker="o", label=key)
        ax.fill_between(centres, 1.0 + low, 1.0 + high, color=line.get_color(), alpha=0.12, linewidth=0)
    ax.set_xticks(centres, [f"{lo:g}-{hi:g}" for lo, hi in itertools.pairwise(LEADER_RANGE_BINS_M)])
    ax.set_xlabel("ground-truth gap to the lead vehicle, m")
    ax.set_ylabel("share of steps held")
    ax.set_ylim(0.0, 1.05)
    ax.set_title("Lead vehicle held by the perceived features, by range (ground truth: 1)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "leader_by_range.png", dpi=100, metadata={"Software": "roadsynth closedloop"})
    plt.close(fig)


def main(args: argparse.Namespace) -> int:
    from pipeline.stages.executor import executor_from_args

    config, path = load_config(ClosedLoopConfig, args.config, "closedloop")
    metrics = closedloop(config, path, args.out, record=args.record, progress=not args.no_progress,
                         executor=executor_from_args(args), restart=args.restart)
    for key, table in metrics["comparisons"].items():
        if "/" not in key:
            brief = {c["metric"]: c["difference"] for c in table}
            log.info("%s: perceived - ground truth %s", key, json.dumps(_finite(brief)))
    log.info("wrote %s", args.out)
    return 0
