"""Benchmark: the render stage end to end against the bare Embree casts it needs.

Simulates the highway (200 vehicles; or takes --sim), renders N frames (default 100) of the default rig —
800x600 camera + 64-channel LiDAR + all ground truth, written to disk — with the stage's process pool, then
times, frame by frame, only the Embree casts those frames need (camera primary rays, sun shadow rays of lit
hits, LiDAR rays; static world and actors, scenes built outside the timing; see bench_render_core.BareCasts).
The baseline casts every primary ray against the static world and every shadow ray against the static world and
the actors, as the issue defines it; the stage itself skips those that its conservative tests rule out (most of the
sky; the shadow rays that cannot meet an actor or, from near hits, the static world; actors out of every ray's
reach), and casts against each actor as its class's canonical mesh (no per-frame actor BVH to build, which the
baseline's scene building, untimed, has). Prints frames per second and the ratio stage time /
bare casts (targets, for the fast preset, the look before realism: >= 10 labelled frames/s on 2 cores, ratio
<= 2.5), and the same ratio of CPU seconds, which other work on the machine does not skew; and the default
(realistic) rig's CPU time against the fast preset's on the same frames (target <= 4). Then profiles --breakdown
consecutive frames (default 10) on one
thread, as each pool worker renders them, and prints where a frame's time goes by part (Embree casts, PNG
encoding, ground truth, shading, ...) with the frames/s that total allows on this machine's cores, and the bound
if all but the casts were free.

Also prints the default rig's labelled frames per CPU-second (all the stage's processes, start-up included) and
that rate as a share of the bare casts' (issue 41: >= 0.3), the peak resident memory of each render worker, the
frames/s beside MetaDrive's (METADRIVE_FPS, 800x600, measured on the development machine), and what a
100,000-frame dataset costs in CPU-hours at this rate. The stage loads the run's static world from the build cache
when an earlier render of the same simulation built it (pipeline.world.static.load_static_world, with its merged
geometry: load_static_geometry), as every render of a simulation but its first does; --cold-world removes both first,
to measure a first render. The breakdown is in CPU
time (cProfile timing with ``time.process_time``: other work on shared cores does not inflate it).

    python bench/bench_render.py [--frames 100] [--sim DIR] [--scenario highway] [--condition noon] [--workers 2]
        [--breakdown 10] [--no-fast] [--cold-world]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from bench_render_core import BareCasts, frame_rays, sim_frames

from pipeline.core.build_cache import cache_path
from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.sensors import conditions
from pipeline.sensors.groundtruth import project_actors
from pipeline.stages.render import check_sim, render
from pipeline.stages.rig import build_sensors
from pipeline.stages.simulate import resolve_scenario, simulate
from pipeline.world.scene import FrameScene, StaticScene, make_rays
from pipeline.world.static import GEOMETRY_CACHE_NAME, WORLD_CACHE_NAME, build_static_world, static_world_key


def cpu_seconds() -> float:
    """CPU seconds of this process and its descendants so far, finished ones included (those reaped by a live
    process count in its children's times: a pool's workers forked from a forkserver in the server's)."""
    import psutil

    me = psutil.Process()
    total = 0.0
    for proc in [me, *me.children(recursive=True)]:
        try:
            t = proc.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system + t.children_user + t.children_system
    return total


# MetaDrive's rendered frames/s at 800x600 on the development machine (issue 41's reference figure).
METADRIVE_FPS = 4.88
DATASET_FRAMES = 100_000  # the dataset the scaling line costs


class PeakWorkerMemory:
    """The largest resident set (bytes) any descendant process of this one reached while the context was open
    (polled every ``period_s``): a render's pool workers."""

    def __init__(self, period_s: float = 0.05) -> None:
        self.period_s, self.peak, self._stop = period_s, 0, threading.Event()

    def _poll(self) -> None:
        import psutil

        me = psutil.Process()
        while not self._stop.is_set():
            for proc in me.children(recursive=True):
                try:
                    self.peak = max(self.peak, proc.memory_info().rss)
                except psutil.Error:
                    continue
            self._stop.wait(self.period_s)

    def __enter__(self) -> PeakWorkerMemory:
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def bare_seconds(sim: Path, frames: list[int], rig: RigConfig, condition_cfg: ConditionConfig) -> tuple[float, float]:
    """Wall and CPU seconds of the bare casts of ``frames``."""
    world = build_static_world(sim / "roads", seed=0)
    static = StaticScene(world.meshes)
    caster = BareCasts(world.meshes)
    (camera,), (lidar,) = build_sensors(rig)
    condition = conditions.Condition(condition_cfg)
    lidar = type(lidar)(condition.lidar(lidar))
    scenes = dict(zip(range(max(frames) + 1), sim_frames(sim, max(frames) + 1), strict=False))
    total = 0.0
    for f in frames:
        actors, ego = scenes[f]
        scene = FrameScene(static, actors)
        cam_to_world = camera.camera_to_world(ego)
        mask = project_actors(scene, camera, cam_to_world).pixel_mask(camera.width, camera.height)
        crays = make_rays(cam_to_world.translation, camera.pixel_directions, cam_to_world.rotation)
        hits = scene.cast_rays(crays, actor_rays=mask)
        rays = frame_rays(camera, lidar, scene, ego, condition, crays, mask, hits)
        total += sum(caster.time(scene, rays).values())
    return total, caster.cpu_s


EMBREE, PNG, PARQUET = "Embree casts", "PNG encoding (4 images)", "Parquet writes"
GT = "ground truth (2D/3D boxes, occlusion, truncation)"
POST = "post effects + tone map"
RAYS = "camera rays, hit attributes, depth"
SCENE = "frame scene (actors in reach, placed)"
# Where one frame's CPU time goes (--breakdown): built-in calls that are a part wherever they run ...
LEAF_PARTS = {"cast_rays": EMBREE, "test_occlusions": EMBREE}
LEAF_CALLER_PARTS: dict[str, str] = {}  # ... or, by "function@file.py", the part of the one that called them
# ... and the pipeline functions that own the rest of the time (numpy, OpenCV, pandas) they call.
STEP_PARTS = {
    "shade": "shading (sun, sky, lights, wet road)", "apply_post": POST, "to_srgb8": POST, "camera_labels": GT,
    "project_actors": GT, "_camera_rows": GT, "_lidar_rows": GT, "_label_table": GT,
    "render_lidar": "LiDAR model (noise, drop-out, intensity)", "__init__@scene.py": SCENE,
    "actors_in_reach": SCENE, "write_png": PNG,
    "_write_camera": "images converted for writing", "_write_points": PARQUET, "write_parquet": PARQUET,
    "render_camera": RAYS, "cast_rays@scene.py": RAYS, "render_shard": "trajectories, signals, other",
}


def _part_of(func: tuple[str, int, str]) -> str | None:
    filename, _, name = func
    if filename == "~":  # a built-in: "<built-in method open3d.pybind.t.geometry.cast_rays>"
        return LEAF_PARTS.get(name.split()[-1].strip("<>").split(".")[-1])
    if "pyarrow" in filename:
        return PARQUET
    if "pipeline" not in filename:
        return None
    return STEP_PARTS.get(f"{name}@{Path(filename).name}") or STEP_PARTS.get(name)


def breakdown(sim: Path, rig: RigConfig, condition_cfg: ConditionConfig, frames: list[int],
              tmp: Path) -> list[tuple[str, float]]:
    """(part, seconds) of rendering ``frames`` in this process on one thread (as each pool worker does), from a
    cProfile run. A call's own time goes to its part (LEAF_PARTS, or LEAF_CALLER_PARTS by the caller; pyarrow) or
    else, up the profile's call graph, to the innermost step that called it (STEP_PARTS), split among callers by
    their share of its time."""
    import cProfile
    import dataclasses
    import pstats

    from pipeline.stages.render import pickle_static_world
    from pipeline.stages.render_frames import ShardJob, render_shard

    tmp.mkdir(parents=True, exist_ok=True)
    seed = int(check_sim(sim)["seed"])
    pickle_static_world(sim, seed, tmp / "static.pkl")
    job = ShardJob(0, tuple(frames[:1]), sim, tmp / "static.pkl", tmp / "rec", tmp / "shards", rig, condition_cfg,
                   seed, threads=1)
    render_shard(job)  # loads the world and builds its BVH outside the profile
    profile = cProfile.Profile(time.process_time)  # CPU time: other work on shared cores does not count
    profile.runcall(render_shard, dataclasses.replace(job, index=1, frames=tuple(frames)))
    stats = pstats.Stats(profile).stats
    owners: dict = {}

    def owner(func, depth: int = 0) -> dict[str, float]:
        if func in owners:
            return owners[func]
        part = _part_of(func)
        if part is not None and func[0] == "~" and func in stats:  # a built-in leaf: some callers own their calls
            callers = stats[func][4]
            total = sum(c[2] for c in callers.values()) or 1.0
            share = {}
            for (filename, _, name), c in callers.items():
                mine = LEAF_CALLER_PARTS.get(f"{name}@{Path(filename).name}", part)
                share[mine] = share.get(mine, 0.0) + c[2] / total
            owners[func] = share or {part: 1.0}
            return owners[func]
        if part is not None or depth > 50 or func not in stats:
            owners[func] = {part or "other": 1.0}
            return owners[func]
        callers = stats[func][4]
        total = sum(c[3] for c in callers.values()) or 1.0
        share: dict[str, float] = {}
        for caller, c in callers.items():
            for name, frac in owner(caller, depth + 1).items():
                share[name] = share.get(name, 0.0) + frac * (c[3] / total if callers else 1.0)
        owners[func] = share or {"other": 1.0}
        return owners[func]

    parts: dict[str, float] = {}
    for func, (_, _, tottime, _, _) in stats.items():
        for name, frac in owner(func).items():
            parts[name] = parts.get(name, 0.0) + tottime * frac
    return sorted(parts.items(), key=lambda kv: -kv[1])


STARTUP_SCRIPT = """
import sys, time
from pathlib import Path
start = time.process_time()
from pipeline.stages.render import WORKER_MODULES
for name in WORKER_MODULES:
    __import__(name)
imported = time.process_time()
from pipeline.stages.render import check_sim
from pipeline.world.static import build_static_world
build_static_world(Path(sys.argv[1]) / "roads", seed=int(check_sim(Path(sys.argv[1]))["seed"]))
print(imported - start, time.process_time() - imported)
"""


def startup_seconds(sim: Path) -> tuple[float, float]:
    """CPU seconds a render pays before its frames, measured in a fresh process: the renderer's imports (a
    `roadsynth render` process's, before the stage starts; its workers fork from it) and the static world build
    (the main process's, before the workers start)."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", STARTUP_SCRIPT, str(sim)], check=True, capture_output=True, text=True)
    imports_s, world_s = (float(v) for v in out.stdout.split())
    return imports_s, world_s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--sim", type=Path)
    ap.add_argument("--scenario", default="highway", help="scenario simulated when --sim is not given")
    ap.add_argument("--condition", default="noon")
    ap.add_argument("--no-fast", action="store_true", help="skip the fast preset's render (and its rows)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--cold-world", action="store_true",
                    help="remove the run's static world from the build cache first, so that the stage builds it (as "
                         "the first render of a simulation does; later ones load it)")
    ap.add_argument("--breakdown", type=int, default=10, metavar="N",
                    help="also profile N of the frames on one thread and print where the time goes (0: skip)")
    args = ap.parse_args()
    rig, _ = load_config(RigConfig, "default", "rigs")
    condition, _ = load_config(ConditionConfig, args.condition, "conditions")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        sim = args.sim
        if sim is None:
            config, _ = resolve_scenario(args.scenario, duration_s=args.frames / 10.0, warmup_s=90.0)
            sim = tmp / "sim"
            simulate(config, 1, sim, progress=False)
        world_key = static_world_key(sim / "roads", int(check_sim(sim)["seed"]))
        cached_world = cache_path(WORLD_CACHE_NAME, world_key)
        if args.cold_world:  # the world and its merged geometry, as a simulation's first render finds them: absent
            cached_world.unlink(missing_ok=True)
            cache_path(GEOMETRY_CACHE_NAME, world_key).unlink(missing_ok=True)
        world_was_cached = cached_world.is_file()
        start, cpu = time.perf_counter(), cpu_seconds()
        with PeakWorkerMemory() as memory:
            render(sim, condition, rig, tmp / "record", frames=args.frames, workers=args.workers, shard_size=5,
                   progress=False)
        stage_s, stage_cpu_s = time.perf_counter() - start, cpu_seconds() - cpu
        size_mb = sum(p.stat().st_size for p in (tmp / "record").rglob("*") if p.is_file()) / 1e6
        # The same frames in the fast preset (one sample per pixel, direct light only: the look before realism).
        fast = rig.model_copy(update={"cameras": [c.model_copy(update={"quality": "fast", "samples_per_pixel": 1})
                                                  for c in rig.cameras]})
        fast_s = fast_cpu_s = np.nan
        if not args.no_fast:
            start, cpu = time.perf_counter(), cpu_seconds()
            render(sim, condition, fast, tmp / "record_fast", frames=args.frames, workers=args.workers,
                   shard_size=5, progress=False)
            fast_s, fast_cpu_s = time.perf_counter() - start, cpu_seconds() - cpu
        import pandas as pd

        # The frames the stage rendered (its selection skips an ego's standing repeats: an urban ego that waits at
        # a red light for the whole run gives fewer frames than --frames asks), so the rates and the bare casts count
        # exactly those.
        frames = pd.read_parquet(tmp / "record" / "frames.parquet", columns=["frame"])["frame"].tolist()
        bare_s, bare_cpu_s = bare_seconds(sim, frames, rig, condition)
        imports_s, world_s = startup_seconds(sim) if args.breakdown > 0 else (0.0, 0.0)
        # Consecutive frames from the middle of the run, as a worker renders them (its caches warm, e.g. the sun map's
        # tiles).
        middle = max(0, (len(frames) - args.breakdown) // 2)
        parts = breakdown(sim, rig, condition, frames[middle: middle + args.breakdown],
                          tmp / "breakdown") if args.breakdown > 0 else []
    n = len(frames)
    rows = [
        ("frames rendered (800x600 camera + 64x1800 LiDAR + GT, on disk)", f"{n} ({size_mb:.0f} MB)"),
        (f"render stage, {args.workers} workers, incl. the static world", f"{stage_s:.1f} s"),
        ("the run's static world (first render of a simulation: built; later ones: loaded; --cold-world)",
         "loaded from the build cache" if world_was_cached else "built"),
        ("labelled frames per second (the default rig: realistic quality)", f"{n / stage_s:.2f}"),
        ("the same frames in the fast preset (1 sample, direct light; target >= 10)",
         f"{fast_s:.1f} s, {n / fast_s:.2f} frames/s"),
        ("bare Embree casts of the same frames (all cores)", f"{bare_s:.1f} s ({n / bare_s:.1f} frames/s)"),
        ("ratio fast preset / bare casts (target <= 2.5)", f"{fast_s / bare_s:.2f}"),
        ("ratio realistic / bare casts", f"{stage_s / bare_s:.2f}"),
        # CPU seconds do not depend on what else the machine runs (wall times do, a lot, on shared cores).
        ("CPU: render stage (all processes) / bare casts", f"{stage_cpu_s:.1f} s / {bare_cpu_s:.1f} s = "
                                                          f"{stage_cpu_s / bare_cpu_s:.2f}"),
        ("CPU: realistic / fast preset (target <= 4)", f"{stage_cpu_s:.1f} s / {fast_cpu_s:.1f} s = "
                                                       f"{stage_cpu_s / fast_cpu_s:.2f}"),
        ("labelled frames per CPU-second (realistic rig, all processes, start-up included)",
         f"{n / stage_cpu_s:.3f}"),
        ("bare casts' frames per CPU-second", f"{n / bare_cpu_s:.3f}"),
        ("realistic / bare casts' frames per CPU-second (issue 41: >= 0.3)", f"{bare_cpu_s / stage_cpu_s:.3f}"),
        (f"peak resident memory of a render worker ({args.workers} workers)", f"{memory.peak / 2**20:.0f} MiB"),
        (f"ours vs MetaDrive at 800x600 on this machine ({METADRIVE_FPS} frames/s)",
         f"{n / stage_s:.2f} vs {METADRIVE_FPS} frames/s (ours labelled, with LiDAR and radar)"),
        (f"CPU-hours for {DATASET_FRAMES:,} frames at this rate (this scenario and condition)",
         f"{DATASET_FRAMES * stage_cpu_s / n / 3600:.1f} ({DATASET_FRAMES * stage_cpu_s / n / 3600 / args.workers:.1f} "
         f"h on {args.workers} cores)"),
        ("load average (1 min) at the end", f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"),
    ]
    if args.no_fast:
        rows = [r for r in rows if "fast preset" not in r[0]]
    width = max(len(k) for k, _ in rows)
    print(f"{'measure':<{width}} | value\n{'-' * width}-|------")
    for key, value in rows:
        print(f"{key:<{width}} | {value}")
    if parts:
        count = min(args.breakdown, len(frames))
        total = sum(t for _, t in parts)
        embree = sum(t for name, t in parts if name == EMBREE)
        width = max(len(k) for k, _ in parts)
        print(f"\nwhere one frame's CPU time goes: {count} frames on one thread, cProfile (adds ~5%)\n"
              f"{'part':<{width}} | ms/frame | share\n{'-' * width}-|----------|------")
        for name, t in parts:
            print(f"{name:<{width}} | {1000 * t / count:8.1f} | {100 * t / total:4.1f}%")
        cores = os.cpu_count() or 1
        print(f"{'total':<{width}} | {1000 * total / count:8.1f} |\n"
              f"frames/s on {cores} cores at this total: {cores * count / total:.1f}; "
              f"with everything but the Embree casts free: {cores * count / embree:.1f}")
        # Once per render, before the frames: the process imports the renderer, builds the static world, then forks
        # the workers.
        frames_s = n * total / count / cores
        print(f"start-up, once per render (fresh process, CPU): imports {imports_s:.2f} s, static world build "
              f"{world_s:.2f} s; {n} frames at the total above on {cores} cores after the world build: "
              f"{n / (world_s + frames_s):.1f} frames/s, and after the imports too: "
              f"{n / (imports_s + world_s + frames_s):.1f} frames/s")


if __name__ == "__main__":
    main()
