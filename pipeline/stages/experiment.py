"""``roadsynth experiment run CONFIG --out DIR``: an experiment config's whole matrix from one command.

Every (scenario, seed) is simulated, each run rendered under every condition, and the finished records exported
(the merge), here or on a Ray cluster (``--executor ray``); the layout of OUT, the completion markers and the
resumption are :mod:`pipeline.stages.matrix`'s. Progress is one bar over the matrix's tasks with a line per task
as it ends (done, skipped as finished earlier, or failed with its error). A failed task does not stop the others;
the command then exits with an error naming each failed task, and a rerun does only what is not finished.
"""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

from tqdm import tqdm

from pipeline.core.config import ExperimentConfig, load_config
from pipeline.core.outputs import OutputSpec
from pipeline.stages.common import int_at_least, write_json, write_meta
from pipeline.stages.executor import ExecutorSpec, TaskFailures, add_executor_arguments, executor_from_args, run_tasks
from pipeline.stages.matrix import Matrix, matrix_tasks, record_paths, resolve_matrix

log = logging.getLogger(__name__)

INPUT_ARGS = ("config",)
HELP = "run an experiment config's matrix: simulate, render every condition, export (locally or on Ray)"
INTERRUPT_HINT = "the runs finished are kept; rerun the same command to resume"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=["run"], help="run: the matrix, then the merge")
    parser.add_argument("config", help="experiment NAME (configs/experiments/) or YAML PATH")
    parser.add_argument("--out", type=Path, required=True, help="experiment folder (sim/, records/, exports)")
    parser.add_argument("--frames", type=int_at_least(1), help="frames per record (default: the config's)")
    parser.add_argument("--export", default="coco", metavar="FORMATS",
                        help="formats the merge exports, comma-separated, or 'none' (default: coco)")
    parser.add_argument("--splits", metavar="SPEC", help="the exports' splits (as `roadsynth export --splits`)")
    parser.add_argument("--workers", type=int_at_least(1), default=os.cpu_count() or 1,
                        help="local executor: processes of each render; Ray without an address: the local "
                        "instance's CPUs (default: all cores)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_executor_arguments(parser)


def _formats(text: str) -> list[str]:
    from exporters.base import formats

    chosen = [] if text.strip() == "none" else [f.strip() for f in text.split(",") if f.strip()]
    unknown = [f for f in chosen if f not in formats()]
    if unknown:
        raise ValueError(f"--export: unknown format {', '.join(unknown)}; expected some of {', '.join(formats())} "
                         "or none")
    return chosen


def run_experiment(matrix: Matrix, out: Path, spec: ExecutorSpec, *, workers: int, formats: list[str],
                   splits: str | None = None, progress: bool = True) -> dict[str, dict]:
    """Run the matrix into ``out`` with ``spec``, then merge; returns each task's status by label. Raises
    :class:`TaskFailures` (after the merge has written status.json) when a task failed."""
    out.mkdir(parents=True, exist_ok=True)
    write_meta(out, stage="experiment", config={"experiment": matrix.experiment.model_dump(mode="json"),
                                               "frames": matrix.frames}, seed=None)
    shard_threads = spec.task_cpus if spec.distributed else None
    tasks = matrix_tasks(matrix, out, workers=1 if spec.distributed else workers, shard_threads=shard_threads)
    status: dict[str, dict] = {t.label: {"status": "pending"} for t in tasks}
    with tqdm(total=len(tasks), unit="task", desc=f"experiment {matrix.experiment.name}",
              disable=not progress) as bar:

        def done(i: int, manifest: dict) -> None:
            state = "skipped (finished earlier)" if manifest["skipped"] else "done"
            status[tasks[i].label] = {"status": "skipped" if manifest["skipped"] else "done",
                                      "summary": manifest["summary"]}
            log.info("%s: %s %s", tasks[i].label, state, manifest["summary"])
            bar.update(1)

        def failed(i: int, error: str) -> None:
            status[tasks[i].label] = {"status": "failed", "error": error}
            bar.update(1)

        failure: TaskFailures | None = None
        try:
            run_tasks(tasks, spec, on_done=done, on_failed=failed,
                      hint="the finished runs are kept; fix the cause and rerun the same command")
        except TaskFailures as exc:
            failure = exc
    _merge(matrix, out, status, formats, splits, progress, complete=failure is None)
    if failure is not None:
        raise failure
    return status


def _merge(matrix: Matrix, out: Path, status: dict[str, dict], formats: list[str], splits: str | None,
           progress: bool, *, complete: bool) -> None:
    """The exports of all records (replaced atomically) when every task finished, then status.json. An export that
    fails leaves status.json saying incomplete, with the merge's error, and is raised."""
    from exporters.base import ExportOptions, get_exporter
    from exporters.splits import SplitSpec
    from pipeline.stages.export import export_records

    if not complete:
        _write_status(out, matrix, status, complete=False)
        log.warning("not exporting: some tasks failed (status.json)")
        return
    records = record_paths(matrix, out)
    options = ExportOptions(splits=SplitSpec.parse(splits) if splits else None, progress=progress)
    for fmt in formats:
        target = out / (f"{fmt}.mcap" if get_exporter(fmt).writes_file else fmt)
        try:
            export_records(fmt, records, target, options)
        except Exception as exc:
            _write_status(out, matrix, status, complete=False,
                          merge={"status": "failed", "format": fmt, "error": f"{type(exc).__name__}: {exc}"})
            raise
        log.info("merged %d records into %s", len(records), target)
    _write_status(out, matrix, status, complete=True)


def _write_status(out: Path, matrix: Matrix, status: dict[str, dict], *, complete: bool,
                  merge: dict | None = None) -> None:
    from pipeline.core.files import atomic_file

    data = {"experiment": matrix.experiment.name, "complete": complete, "tasks": status}
    with atomic_file(out / "status.json") as tmp:
        write_json(tmp, data if merge is None else {**data, "merge": merge})


def outputs(args: argparse.Namespace) -> list[OutputSpec]:
    """The experiment folder, which a rerun resumes into (never replaced whole): see :func:`_only_the_experiments`."""
    return [OutputSpec(args.out, resumable=_only_the_experiments)]


_EXPERIMENT_FILES = ("meta.json", "status.json")
_EXPERIMENT_FOLDERS = ("sim", "records", "runs")


def _only_the_experiments(folder: Path) -> str | None:
    """Why an experiment folder holds what the experiment does not write there (None: it holds only its own): at
    the top its meta.json and status.json, its sim/, records/ and runs/ folders, and the exports of the merge (a
    folder that is a stage's output, an MCAP and its layout of ours); in sim/ and records/ only stage outputs and
    what a stopped task left (removed by the next run); in runs/ the tasks' JSON markers."""
    from pipeline.core.outputs import mcap_file, output_stage

    foreign = []
    for entry in sorted(folder.iterdir()):
        name = entry.name
        if name in _EXPERIMENT_FILES and entry.is_file():
            continue
        if name in _EXPERIMENT_FOLDERS and entry.is_dir():
            for inner in sorted(entry.iterdir()):
                ours = (inner.suffix == ".json" and inner.is_file() if name == "runs" else
                        (inner.is_dir() and output_stage(inner) is not None) or inner.name.startswith("."))
                if not ours:
                    foreign.append(f"{name}/{inner.name}")
            continue
        if entry.is_dir() and output_stage(entry) is not None:
            continue
        if entry.is_file() and (mcap_file(entry) is None or (name.endswith(".layout.json") and
                                                             mcap_file(folder / name.replace(".layout.json", ".mcap"))
                                                             is None)):
            continue
        if name.startswith(".") and (".tmp-" in name or ".old-" in name or name.endswith(".lock")):
            continue  # what a stopped merge left beside its output: removed by the next run
        foreign.append(name)
    if not foreign:
        return None
    shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
    return f"it also holds {shown}, which the experiment did not write"


def main(args: argparse.Namespace) -> int:
    experiment, path = load_config(ExperimentConfig, args.config, "experiments")
    formats = _formats(args.export)
    spec = executor_from_args(args, local_cpus=args.workers)
    matrix = resolve_matrix(experiment, args.frames, source=path)
    log.info("experiment %s from %s: %d runs x %d conditions on the %s executor -> %s", experiment.name, path,
             len(matrix.runs), len(matrix.conditions), spec.kind, args.out)
    status = run_experiment(matrix, args.out, spec, workers=args.workers, formats=formats, splits=args.splits,
                            progress=not args.no_progress)
    skipped = sum(s["status"] == "skipped" for s in status.values())
    log.info("experiment %s: %d tasks done, %d skipped as finished earlier -> %s", experiment.name,
             len(status) - skipped, skipped, args.out)
    return 0
