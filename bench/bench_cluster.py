"""Benchmark: the Ray executor against the local one (issue 28).

Three tables, each measured within this one run (the machine's load changes between runs; ratios are the figures):

1. Render throughput: the same `roadsynth render` command (a subprocess each, as a user runs it) with the local
   executor (``--workers W``, the forked pool) and with ``--executor ray --ray-address`` against a Ray head of W CPUs
   started here (``ray.cluster_utils.Cluster``: what ``ray start --head`` starts, stopped by its handle);
   alternated ``--repeats`` times; frames/s of each and Ray / local (target >= 0.9). Both include the command's
   start (imports, static world); Ray's includes its workers' start (each command is a new Ray job, with fresh
   worker processes).
2. Per-task scheduling overhead on that head: no-op tasks through :func:`pipeline.stages.executor.run_tasks` and
   bare ``ray.remote`` no-ops, submitted all at once (wall / task) and one after another (round trip).
3. Matrix scaling: `roadsynth experiment run --executor ray` of a small matrix (--seeds highway seeds x noon and
   night, --matrix-frames frames each) on a fresh local Ray of 1 and of 2 CPUs; wall time and speed-up, beside
   the speed-up of 2 busy processes over 1 on this machine at the time (its ceiling while others share the cores).

    python bench/bench_cluster.py [--frames 60] [--workers 2] [--repeats 2] [--tasks 200] [--sim DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH", "")) if p)
    return {**env, **extra}


def _roadsynth(*args: str) -> float:
    """Wall seconds of one `roadsynth` command (a subprocess); fails loudly with its stderr. A client of a Ray
    cluster with token authentication (Ray's default) says so: RAY_AUTH_MODE=token (docs/cluster.md)."""
    start = time.perf_counter()
    env = _env(RAY_AUTH_MODE="token") if "--ray-address" in args else _env()
    proc = subprocess.run([sys.executable, "-m", "pipeline.stages.cli", *args], env=env, capture_output=True,
                          text=True, check=False)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"roadsynth {' '.join(args)} failed:\n{proc.stderr[-3000:]}")
    return wall


def _load() -> str:
    return "load average {:.1f} {:.1f} {:.1f}".format(*os.getloadavg())


def render_throughput(sim: Path, work: Path, frames: int, workers: int, repeats: int, address: str) -> None:
    base = ["render", "--sim", str(sim), "--condition", "noon", "--frames", str(frames), "--no-progress",
            "--workers", str(workers)]
    walls: dict[str, list[float]] = {"local": [], "ray": []}
    rendered = None
    for r in range(repeats):
        for kind in ("local", "ray"):
            out = work / f"render-{kind}-{r}"
            extra = ["--executor", "ray", "--ray-address", address] if kind == "ray" else []
            walls[kind].append(_roadsynth(*base, *extra, "--out", str(out)))
            rendered = len(json.loads((out / "meta.json").read_text())["config"]["frames"])
            if r or kind == "ray":
                same = _same_tree(work / "render-local-0", out)
                if not same:
                    raise SystemExit(f"{out} differs from {work / 'render-local-0'}")
            if r:
                shutil.rmtree(out)
    frames = rendered  # the standing rule may keep fewer than asked
    print(f"\n1. render throughput: {frames} frames of the default rig, {workers} CPUs ({_load()})")
    print(f"{'executor':10s} {'wall s (each run)':>26s} {'median s':>9s} {'frames/s':>9s}")
    median = {k: statistics.median(v) for k, v in walls.items()}
    for kind, values in walls.items():
        print(f"{kind:10s} {' '.join(f'{v:6.1f}' for v in values):>26s} {median[kind]:9.1f} "
              f"{frames / median[kind]:9.2f}")
    print(f"Ray / local throughput: {median['local'] / median['ray']:.2f} (target >= 0.9); records byte-identical "
          "but for meta.json's command line")


def _same_tree(a: Path, b: Path) -> bool:
    sys.path.insert(0, str(REPO))
    from tests.conftest import tree_hashes

    return tree_hashes(a, skip=("meta.json",)) == tree_hashes(b, skip=("meta.json",))


def _noop(i: int) -> int:
    return i


def scheduling_overhead(address: str, tasks: int) -> None:
    import ray

    from pipeline.stages.executor import ExecutorSpec, Task, run_tasks

    os.environ["RAY_AUTH_MODE"] = "token"
    ray.init(address=address, log_to_driver=False)
    try:
        spec = ExecutorSpec("ray", address)
        bare = ray.remote(_noop)
        ray.get([bare.remote(i) for i in range(tasks)])  # warm the workers up
        rows = []
        start = time.perf_counter()
        ray.get([bare.remote(i) for i in range(tasks)])
        rows.append(("ray.remote no-op, all at once", time.perf_counter() - start, tasks))
        start = time.perf_counter()
        run_tasks([Task(f"noop {i}", _noop, (i,)) for i in range(tasks)], spec)
        rows.append(("run_tasks no-op, all at once", time.perf_counter() - start, tasks))
        one = max(tasks // 4, 1)
        start = time.perf_counter()
        for i in range(one):
            ray.get(bare.remote(i))
        rows.append(("ray.remote no-op, one by one", time.perf_counter() - start, one))
        start = time.perf_counter()
        for i in range(one):
            run_tasks([Task(f"noop {i}", _noop, (i,))], spec)
        rows.append(("run_tasks no-op, one by one", time.perf_counter() - start, one))
    finally:
        ray.shutdown()
    print(f"\n2. per-task scheduling overhead ({_load()})")
    print(f"{'':34s} {'tasks':>6s} {'wall s':>7s} {'ms/task':>8s}")
    for name, wall, n in rows:
        print(f"{name:34s} {n:6d} {wall:7.2f} {1000 * wall / n:8.2f}")


def matrix_scaling(work: Path, seeds: int, frames: int) -> None:
    config = work / "matrix.yaml"
    config.write_text(yaml.safe_dump({"name": "bench", "scenarios": ["highway"], "seeds": list(range(1, seeds + 1)),
                                      "conditions": ["noon", "night"], "vehicles": 60, "warmup_s": 30,
                                      "duration_s": frames / 10 + 1, "frames": frames}))
    walls = {}
    for cpus in (1, 2):
        walls[cpus] = _roadsynth("experiment", "run", str(config), "--out", str(work / f"matrix-{cpus}"),
                                 "--executor", "ray", "--workers", str(cpus), "--export", "none", "--no-progress")
    if not _same_tree(work / "matrix-1", work / "matrix-2"):
        raise SystemExit("the matrix differs between 1 and 2 workers")
    ceiling = _machine_speed_up()
    print(f"\n3. matrix scaling: {seeds} highway runs x 2 conditions x {frames} frames, a fresh local Ray each "
          f"({_load()})")
    print(f"{'Ray CPUs':>8s} {'wall s':>7s} {'speed-up':>9s}")
    for cpus, wall in walls.items():
        print(f"{cpus:8d} {wall:7.1f} {walls[1] / wall:9.2f}")
    print(f"this machine's own speed-up of 2 busy processes over 1, measured now: {ceiling:.2f} (the ceiling)")


_BUSY = "x = 0\nfor i in range(30_000_000):\n    x += i\n"


def _machine_speed_up() -> float:
    """Work done per second by 2 CPU-bound processes at once over 1 alone (2.0 on 2 idle cores; less when other
    work shares them): what any 2-worker run can gain on this machine now."""
    def wall(n: int) -> float:
        start = time.perf_counter()
        procs = [subprocess.Popen([sys.executable, "-c", _BUSY]) for _ in range(n)]
        for proc in procs:
            proc.wait()
        return time.perf_counter() - start

    return 2 * wall(1) / wall(2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60, help="frames of the render (the paper's records have 60)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--tasks", type=int, default=200)
    parser.add_argument("--seeds", type=int, default=2, help="matrix: runs of the highway")
    parser.add_argument("--matrix-frames", type=int, default=40)
    parser.add_argument("--sections", default="1,2,3", help="which tables (comma-separated)")
    parser.add_argument("--sim", type=Path,
                        help="a simulate output (default: a highway of 120 vehicles, --frames / 10 + 2 s)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_cluster_") as tmp:
        work = Path(tmp)
        sections = set(args.sections.split(","))
        if "3" in sections:
            matrix_scaling(work, args.seeds, args.matrix_frames)
        if not sections & {"1", "2"}:
            return
        sim = args.sim
        if sim is None:
            sim = work / "sim"
            _roadsynth("simulate", "--scenario", "highway", "--seed", "3", "--vehicles", "120", "--warmup", "60",
                       "--duration", str(args.frames / 10 + 2), "--no-progress", "--out", str(sim))
        from ray.cluster_utils import Cluster

        head = Cluster(initialize_head=True, head_node_args={"num_cpus": args.workers, "include_dashboard": False})
        try:
            if "1" in sections:
                render_throughput(sim, work, args.frames, args.workers, args.repeats, head.address)
            if "2" in sections:
                scheduling_overhead(head.address, args.tasks)
        finally:
            head.shutdown()


if __name__ == "__main__":
    main()
