"""Benchmark: what the default rig's front radar costs a rendered frame, and what its scans hold.

Simulates the highway (200 vehicles, 90 s warm-up; or takes --sim), then renders the same N frames (default 10)
as the render stage's worker does (render_shard: images, sweeps, scans and label tables written; its set-up
excluded) with the default rig and with the default rig less its radars, alternating --repeats times (default 2)
and keeping each one's fastest run, so that other work on the machine skews both alike. Prints the wall and CPU
seconds per frame of each, the radar's added cost and the ratio radar on / off (the issue's limit: 1.15), and
the radar's own scan per frame (render_radar alone, scenes built outside the timing). Then renders a record with
the radar and prints detections per frame, the share on objects, the RCS by class (each object's detections
summed, averaged in dB over objects; and the median per detection), the clutter by class and the radial
velocities seen on objects.

    python bench/bench_radar.py [--frames 10] [--sim DIR] [--condition noon] [--repeats 2]
"""

from __future__ import annotations

import argparse
import json
import pickle
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from bench_render_core import sim_frames

from pipeline.core.classes import SemanticClass
from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.core.record import DatasetRecord
from pipeline.sensors.radar import actors_in_radar_reach, render_radar
from pipeline.stages.render import render, select_frames
from pipeline.stages.render_frames import ShardJob, render_shard
from pipeline.stages.simulate import resolve_scenario, simulate
from pipeline.world.scene import FrameScene, StaticScene
from pipeline.world.static import build_static_world


def cpu_seconds() -> float:
    import os

    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def frame_seconds(job: ShardJob) -> tuple[float, float]:
    """Wall and CPU seconds per frame of the stage rendering ``job``'s frames (images, sweeps, scans, labels
    written), after a one-frame job has built the shard state (static scene, sensors) and compiled everything."""
    render_shard(replace(job, index=job.index + 1000, frames=job.frames[:1]))
    wall, cpu = time.perf_counter(), cpu_seconds()
    render_shard(job)
    return (time.perf_counter() - wall) / len(job.frames), (cpu_seconds() - cpu) / len(job.frames)


def scan_seconds(sim: Path, rig: RigConfig, count: int, seed: int) -> tuple[float, float]:
    """Mean seconds of the rig's radar scans of one of the first ``count`` frames, the actors within the radars'
    reach placed (as the stage does; velocities left out, which the cost does not depend on), after one untimed:
    wall and CPU seconds."""
    static = StaticScene(build_static_world(sim / "roads", seed=seed).meshes)
    frames = sim_frames(sim, count)
    wall = cpu = 0.0
    for k, (actors, pose) in enumerate([frames[0], *frames]):
        scene = FrameScene(static, actors, active=actors_in_radar_reach(actors, pose, rig.radars))
        t, c = time.perf_counter(), cpu_seconds()
        for config in rig.radars:
            render_radar(scene, config, pose, np.random.default_rng([seed, k]))
        if k:
            wall, cpu = wall + time.perf_counter() - t, cpu + cpu_seconds() - c
    return wall / count, cpu / count


def scan_figures(record: Path) -> None:
    rec = DatasetRecord(record)
    labels = rec.labels
    for radar in rec.info.radars:
        scans = {f: rec.radar_detections(radar.name, f) for f in rec.frames["frame"]}
        counts = np.array([len(s) for s in scans.values()])
        on = np.array([(s["instance_id"] > 0).sum() for s in scans.values()])
        print(f"radar {radar.name}: detections per frame mean {counts.mean():.1f} (min {counts.min()}, "
              f"max {counts.max()}; cap {radar.max_detections}); on objects {on.sum() / max(counts.sum(), 1):.1%} "
              f"({on.mean():.1f} per frame)")
        rows = []
        for frame, s in scans.items():
            det = s[s["instance_id"] > 0]
            for tid, grp in det.groupby("instance_id"):
                cls = labels[(labels["frame"] == frame) & (labels["track_id"] == tid)]["cls"].iloc[0]
                rows.append((cls, 10 * np.log10(np.sum(10 ** (grp["rcs_dbsm"] / 10))), grp["rcs_dbsm"].median()))
        by = pd.DataFrame(rows, columns=["cls", "object_dbsm", "detection_dbsm"]).groupby("cls")
        table = by.agg(objects=("object_dbsm", "size"), object_rcs_dbsm=("object_dbsm", "mean"),
                       median_detection_rcs_dbsm=("detection_dbsm", "median"))
        print(table.round(1).to_string())
        clutter = pd.concat([s[s["instance_id"] == 0] for s in scans.values()])
        names = clutter["semantic"].map(lambda v: SemanticClass(v).name.lower()).value_counts()
        print("clutter detections by class:", ", ".join(f"{k} {v}" for k, v in names.items()))
        moving = pd.concat([s[s["instance_id"] > 0] for s in scans.values()])["radial_velocity_mps"]
        print(f"radial velocity on objects: {moving.min():.1f} .. {moving.max():.1f} m/s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10)
    parser.add_argument("--sim", type=Path)
    parser.add_argument("--condition", default="noon")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    rig, _ = load_config(RigConfig, "default", "rigs")
    bare = rig.model_copy(update={"radars": []})
    condition, _ = load_config(ConditionConfig, args.condition, "conditions")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sim = args.sim
        if sim is None:
            config, _ = resolve_scenario("highway", vehicles=200, duration_s=args.frames / 10.0, warmup_s=90.0)
            sim = tmp / "sim"
            simulate(config, 1, sim, progress=False)
        seed = int(json.loads((sim / "meta.json").read_text())["seed"])
        traj = pd.read_parquet(sim / "trajectories.parquet")
        frames = tuple(select_frames(traj["frame"].to_numpy(), args.frames, traj[traj["is_ego"]]))
        with (tmp / "static.pkl").open("wb") as fh:
            pickle.dump(build_static_world(sim / "roads", seed=seed), fh, protocol=pickle.HIGHEST_PROTOCOL)
        best = {"radar off": (np.inf, np.inf), "radar on": (np.inf, np.inf)}
        for rep in range(args.repeats):
            for name, r in (("radar off", bare), ("radar on", rig)):
                work = tmp / f"{name.replace(' ', '-')}-{rep}"
                job = ShardJob(0, frames, sim, tmp / "static.pkl", work / "record", work / "shards", r, condition,
                               seed, threads=0)
                wall, cpu = frame_seconds(job)
                best[name] = (min(best[name][0], wall), min(best[name][1], cpu))
        own = scan_seconds(sim, rig, len(frames), seed)
        print(f"default rig, {len(frames)} frames of the highway under {condition.name}, the stage's frame render "
              f"in this process (all cores; best of {args.repeats}; shard set-up excluded)")
        print(f"{'':12s} {'wall s/frame':>13s} {'CPU s/frame':>12s}")
        for name, (wall, cpu) in best.items():
            print(f"{name:12s} {wall:13.3f} {cpu:12.3f}")
        (w0, c0), (w1, c1) = best["radar off"], best["radar on"]
        print(f"radar adds {(w1 - w0) * 1e3:.0f} ms/frame wall, {(c1 - c0) * 1e3:.0f} ms CPU; "
              f"ratio on/off: wall {w1 / w0:.3f}, CPU {c1 / c0:.3f} (limit 1.15)")
        print(f"the radar's own scan (render_radar alone): {own[0] * 1e3:.1f} ms/frame wall, {own[1] * 1e3:.1f} ms CPU")
        render(sim, condition, rig, tmp / "record", frames=args.frames, workers=1, progress=False)
        scan_figures(tmp / "record")


if __name__ == "__main__":
    main()
