"""An experiment's matrix as tasks: simulate every (scenario, seed), render each run under every condition, merge.

Layout of an experiment folder OUT (the Makefile's ``paper`` target uses the same names)::

    OUT/meta.json                      the experiment (stage ``experiment``)
    OUT/sim/SCENARIO-SEED/             `roadsynth simulate` outputs
    OUT/records/SCENARIO-SEED-COND/    `roadsynth render` outputs
    OUT/runs/NAME.json                 completion markers: a task's key (the hash of its inputs) and summary
    OUT/status.json                    the merge: every task's status and error (and the merge's, if it failed)
    OUT/FORMAT[.mcap]                  the merge: exports of all records (only when every record is finished)

Kubric's pattern: each task writes its own folder atomically, then its marker (the manifest it returns, small);
a task whose marker holds the key of its current inputs and whose folder is there is skipped on a rerun, so a
stopped or partly failed experiment resumes where it was. The merge reads only finished folders and is safe to
run again (its outputs are replaced atomically with the same bytes). Each task is a pure function of its inputs
(configs resolved here, once, and passed as validated models), so the executor does not change a byte.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

from pipeline.core.config import ConditionConfig, ConfigError, ExperimentConfig, RigConfig, ScenarioConfig, load_config
from pipeline.core.config.resolve import resolve_scenario
from pipeline.core.files import atomic_file
from pipeline.stages.common import config_hash, write_json
from pipeline.stages.executor import Task

log = logging.getLogger(__name__)

MARKER_VERSION = 1


@dataclass(frozen=True)
class Matrix:
    """The experiment's resolved configs: one simulation per (scenario, seed), rendered under each condition."""

    experiment: ExperimentConfig
    scenarios: list[ScenarioConfig]
    conditions: list[ConditionConfig]
    rig: RigConfig
    frames: int | None

    @property
    def runs(self) -> list[tuple[ScenarioConfig, int]]:
        return [(s, seed) for s in self.scenarios for seed in self.experiment.seeds]


def resolve_matrix(experiment: ExperimentConfig, frames: int | None = None, source: str | Path = "the experiment",
                   ) -> Matrix:
    """Every config the experiment names, validated now (a bad one fails before any task runs); ``source`` (the
    experiment file) is named in errors. Two scenarios or two conditions of one name are refused: tasks, folders
    and markers are named after them, so they would be one run that each overwrites or skips."""
    scenarios = [resolve_scenario(name, vehicles=experiment.vehicles, duration_s=experiment.duration_s,
                                  warmup_s=experiment.warmup_s) for name in experiment.scenarios]
    conditions = [load_config(ConditionConfig, c, "conditions") for c in experiment.conditions]
    _refuse_same_names(source, "scenarios", scenarios, "the runs (sim/NAME-SEED, records/NAME-SEED-CONDITION)")
    _refuse_same_names(source, "conditions", conditions, "the records (records/SCENARIO-SEED-NAME)")
    matrix = Matrix(experiment, [c for c, _ in scenarios], [c for c, _ in conditions],
                    load_config(RigConfig, experiment.rig, "rigs")[0],
                    frames if frames is not None else experiment.frames)
    _refuse_same_folders(source, matrix, [p for _, p in scenarios], [p for _, p in conditions])
    return matrix


def _refuse_same_names(source: str | Path, key: str, loaded: list[tuple[ScenarioConfig | ConditionConfig, Path]],
                       named: str) -> None:
    first: dict[str, int] = {}
    for i, (config, path) in enumerate(loaded):
        j = first.setdefault(config.name, i)
        if j == i:
            continue
        other, what = loaded[j][1], key[:-1]
        if path.resolve() == other.resolve():
            raise ConfigError(f"{source}: {key}[{j}] and {key}[{i}] are both {path} (name: {config.name}); {named} "
                              f"are named after it, so they would be one run: list each {what} once")
        raise ConfigError(f"{source}: {key}[{j}] ({other}) and {key}[{i}] ({path}) both have name: {config.name}; "
                          f"{named} are named after it, so they would be one run: give each {what} file its own name")


def _refuse_same_folders(source: str | Path, matrix: Matrix, scenario_files: list[Path],
                         condition_files: list[Path]) -> None:
    """Distinct names can still join into one folder name (scenario ``a`` with condition ``2-x`` and scenario
    ``a-1`` seed 2 with condition ``x``): refuse that too, naming both."""
    seen: dict[str, str] = {}
    for scenario, scenario_file in zip(matrix.scenarios, scenario_files, strict=True):
        for seed in matrix.experiment.seeds:
            for condition, condition_file in zip(matrix.conditions, condition_files, strict=True):
                folder = f"{sim_name(scenario, seed)}-{condition.name}"
                task = (f"scenario {scenario.name} ({scenario_file}) seed {seed} condition {condition.name} "
                        f"({condition_file})")
                if folder in seen:
                    raise ConfigError(f"{source}: {seen[folder]} and {task} would both write records/{folder}; "
                                      "rename a scenario or a condition")
                seen[folder] = task


def sim_name(scenario: ScenarioConfig, seed: int) -> str:
    return f"{scenario.name}-{seed}"


def record_paths(matrix: Matrix, out: Path) -> list[Path]:
    """The record folders of the matrix, in matrix order (scenario, seed, condition)."""
    return [out / "records" / f"{sim_name(s, seed)}-{c.name}" for s, seed in matrix.runs for c in matrix.conditions]


def _marker(out: Path, name: str) -> Path:
    return out / "runs" / f"{name}.json"


def _finished(out: Path, name: str, folder: Path, key: str) -> dict | None:
    """The marker of task ``name`` when it holds ``key`` and its output folder is there, else None."""
    try:
        manifest = json.loads(_marker(out, name).read_text())
    except (OSError, ValueError):
        return None
    if manifest.get("key") != key or not (folder / "meta.json").is_file():
        return None
    return {**manifest, "skipped": True}


def _mark(out: Path, name: str, stage: str, key: str, summary: dict) -> dict:
    manifest = {"run": name, "stage": stage, "key": key, "summary": summary, "version": MARKER_VERSION}
    path = _marker(out, name)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        write_json(tmp, manifest)
    return {**manifest, "skipped": False}


def sim_key(scenario: ScenarioConfig, seed: int) -> str:
    return config_hash({"scenario": scenario.model_dump(mode="json"), "seed": seed, "marker": MARKER_VERSION})


def simulate_task(scenario: ScenarioConfig, seed: int, out: Path) -> dict:
    """Simulate one run into ``out/sim/NAME`` unless its marker says it is done; returns the marker."""
    from pipeline.core.outputs import output_lock
    from pipeline.stages.simulate import simulate

    name, key = sim_name(scenario, seed), sim_key(scenario, seed)
    folder = out / "sim" / name
    done = _finished(out, name, folder, key)
    if done is not None:
        return done
    folder.parent.mkdir(parents=True, exist_ok=True)
    with output_lock(folder, "simulate"):
        stats = simulate(scenario, seed, folder, progress=False)
    summary = {k: stats[k] for k in ("frames", "vehicles_inserted", "collisions", "teleports")}
    return _mark(out, name, "simulate", key, summary)


def render_task(scenario: ScenarioConfig, seed: int, condition: ConditionConfig, rig: RigConfig, frames: int | None,
                out: Path, workers: int, shard_threads: int | None) -> dict:
    """Render one run under one condition into ``out/records/NAME`` unless its marker says it is done."""
    from pipeline.stages.render import render

    sim = sim_name(scenario, seed)
    name = f"{sim}-{condition.name}"
    key = config_hash({"sim": sim_key(scenario, seed), "condition": condition.model_dump(mode="json"),
                       "rig": rig.model_dump(mode="json"), "frames": frames, "marker": MARKER_VERSION})
    folder = out / "records" / name
    done = _finished(out, name, folder, key)
    if done is not None:
        return done
    summary = render(out / "sim" / sim, condition, rig, folder, frames=frames, workers=workers, progress=False,
                     shard_threads=shard_threads)
    return _mark(out, name, "render", key, {k: summary[k] for k in ("frames", "labels", "visible_camera_labels")})


def matrix_tasks(matrix: Matrix, out: Path, *, workers: int, shard_threads: int | None) -> list[Task]:
    """Simulate tasks, each followed by its run's render tasks (which wait for it)."""
    tasks: list[Task] = []
    for scenario, seed in matrix.runs:
        sim = len(tasks)
        tasks.append(Task(f"simulate {sim_name(scenario, seed)}", simulate_task, (scenario, seed, out),
                          fresh_process=True))  # libsumo: one simulation per process
        for condition in matrix.conditions:
            tasks.append(Task(f"render {sim_name(scenario, seed)} condition {condition.name}", render_task,
                              (scenario, seed, condition, matrix.rig, matrix.frames, out, workers, shard_threads),
                              after=(sim,)))
    return tasks
