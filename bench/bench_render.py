"""Benchmark: the render stage end to end against the bare Embree casts it needs.

Simulates the highway (200 vehicles; or takes --sim), renders N frames (default 100) of the default rig
— 800x600 camera + 64-channel LiDAR + all ground truth, written to disk — with the stage's process pool,
then times, frame by frame, only the Embree casts those frames need (camera primary rays, sun shadow
rays of lit hits, LiDAR rays; static world and actors, scenes built outside the timing; see
bench_render_core.BareCasts). Prints frames per second and the ratio stage time / bare casts
(targets: >= 10 labelled frames/s on 2 cores, ratio <= 2.5), and the same ratio of CPU seconds, which other
work on the machine does not skew.

    python bench/bench_render.py [--frames 100] [--sim DIR] [--condition noon] [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from bench_render_core import BareCasts, frame_rays, sim_frames

from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.sensors import conditions
from pipeline.sensors.groundtruth import project_actors
from pipeline.stages.render import render, select_frames
from pipeline.stages.rig import build_sensors
from pipeline.stages.simulate import resolve_scenario, simulate
from pipeline.world.scene import FrameScene, StaticScene, make_rays
from pipeline.world.static import build_static_world


def cpu_seconds() -> float:
    """CPU seconds of this process and its descendants so far, finished ones included (those reaped by a live
    process count in its children's times: the pool's workers in the forkserver's)."""
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


def bare_seconds(sim: Path, frames: list[int], rig: RigConfig, condition_cfg: ConditionConfig) -> tuple[float, float]:
    """Wall and CPU seconds of the bare casts of ``frames``."""
    world = build_static_world(sim / "roads", seed=0)
    static = StaticScene(world.meshes)
    caster = BareCasts(world.meshes)
    (camera,), (lidar,) = build_sensors(rig)
    condition = conditions.condition_from_config(condition_cfg)
    lidar = type(lidar)(condition.lidar(lidar.config))
    scenes = dict(zip(range(max(frames) + 1), sim_frames(sim, max(frames) + 1), strict=False))
    total = 0.0
    for f in frames:
        actors, ego = scenes[f]
        scene = FrameScene(static, actors)
        cam_to_world = camera.camera_to_world(ego)
        mask = project_actors(scene, camera, cam_to_world).pixel_mask(camera.width, camera.height)
        crays = make_rays(cam_to_world.translation, camera.pixel_directions, cam_to_world.rotation)
        hits = scene.cast_rays(crays, actor_rays=mask)
        rays = frame_rays(camera, lidar, scene, ego, condition.lighting, crays, mask, hits)
        total += sum(caster.time(scene, rays).values())
    return total, caster.cpu_s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--sim", type=Path)
    ap.add_argument("--condition", default="noon")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    rig, _ = load_config(RigConfig, "default", "rigs")
    condition, _ = load_config(ConditionConfig, args.condition, "conditions")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        sim = args.sim
        if sim is None:
            config, _ = resolve_scenario("highway", duration_s=args.frames / 10.0, warmup_s=90.0)
            sim = tmp / "sim"
            simulate(config, 1, sim, progress=False)
        start, cpu = time.perf_counter(), cpu_seconds()
        render(sim, condition, rig, tmp / "record", frames=args.frames, workers=args.workers, shard_size=5,
               progress=False)
        stage_s, stage_cpu_s = time.perf_counter() - start, cpu_seconds() - cpu
        size_mb = sum(p.stat().st_size for p in (tmp / "record").rglob("*") if p.is_file()) / 1e6
        import pandas as pd

        frames = select_frames(pd.read_parquet(sim / "trajectories.parquet", columns=["frame"])["frame"].to_numpy(),
                               args.frames)
        bare_s, bare_cpu_s = bare_seconds(sim, frames, rig, condition)
    n = len(frames)
    rows = [
        ("frames rendered (800x600 camera + 64x1800 LiDAR + GT, on disk)", f"{n} ({size_mb:.0f} MB)"),
        (f"render stage, {args.workers} workers, incl. static world build", f"{stage_s:.1f} s"),
        ("labelled frames per second (target >= 10)", f"{n / stage_s:.2f}"),
        ("bare Embree casts of the same frames (all cores)", f"{bare_s:.1f} s ({n / bare_s:.1f} frames/s)"),
        ("ratio stage / bare casts (target <= 2.5)", f"{stage_s / bare_s:.2f}"),
        # CPU seconds do not depend on what else the machine runs (wall times do, a lot, on shared cores).
        ("CPU: render stage (all processes) / bare casts", f"{stage_cpu_s:.1f} s / {bare_cpu_s:.1f} s = "
                                                          f"{stage_cpu_s / bare_cpu_s:.2f}"),
        ("load average (1 min) at the end", f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"),
    ]
    width = max(len(k) for k, _ in rows)
    print(f"{'measure':<{width}} | value\n{'-' * width}-|------")
    for key, value in rows:
        print(f"{key:<{width}} | {value}")


if __name__ == "__main__":
    main()
