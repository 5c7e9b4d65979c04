"""Benchmark: anti-aliasing of the default camera, cost against quality.

Renders frames of a simulated run (``--sim``, the first ``--frames`` recorded frames spaced ``--step``
apart) with the default rig's camera under ``--condition``, without sensor noise, at: 1 sample per pixel;
N samples at edge pixels only (``pipeline.sensors.render.edge_pixels``, the default for N > 1); N samples
at every pixel. Each is compared with a reference of ``--reference`` samples at every pixel (same scene):
mean absolute error of the 8-bit sRGB image over all pixels and over the pixels where the 1-sample image
is off by more than 8 levels (aliased edges), and camera time per frame (one process, Embree on 1 thread).

    .venv/bin/python bench/bench_antialias.py --sim DIR [--frames 4] [--samples 4] [--reference 16]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.bench_render_core import sim_frames
from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import Condition
from pipeline.sensors.render import edge_pixels, render_camera
from pipeline.world.scene import FrameScene, StaticScene, make_rays
from pipeline.world.static import build_static_world


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sim", type=Path, required=True, help="a simulate-stage output folder")
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--step", type=int, default=50, help="recorded frames between rendered ones")
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--reference", type=int, default=16)
    ap.add_argument("--condition", default="morning")
    args = ap.parse_args()
    rig, _ = load_config(RigConfig, "default", "rigs")
    condition = Condition(load_config(ConditionConfig, args.condition, "conditions")[0])
    base = rig.cameras[0]
    variants = {
        "1 sample": base.model_copy(update=dict(samples_per_pixel=1)),
        f"{args.samples} at edges": base.model_copy(update=dict(samples_per_pixel=args.samples)),
        f"{args.samples} everywhere": base.model_copy(update=dict(samples_per_pixel=args.samples,
                                                          samples_everywhere=True)),
    }
    cameras = {name: Camera(cfg) for name, cfg in variants.items()}
    reference = Camera(base.model_copy(update=dict(samples_per_pixel=args.reference, samples_everywhere=True)))
    static = StaticScene(build_static_world(args.sim / "roads", seed=0).meshes)
    frames = sim_frames(args.sim, args.frames * args.step)[:: args.step]
    seconds = dict.fromkeys(cameras, 0.0)
    errors = {name: [] for name in cameras}
    aliased_errors = {name: [] for name in cameras}
    edge_share = []
    for actors, ego in frames:
        scene = FrameScene(static, actors, threads=1)
        ref = render_camera(scene, reference, ego, condition).rgb.astype(np.float32)
        images = {}
        for name, camera in cameras.items():
            start = time.perf_counter()
            images[name] = render_camera(scene, camera, ego, condition).rgb.astype(np.float32)
            seconds[name] += time.perf_counter() - start
        aliased = np.abs(images["1 sample"] - ref).max(axis=2) > 8
        for name, image in images.items():
            err = np.abs(image - ref).mean(axis=2)
            errors[name].append(err.mean())
            aliased_errors[name].append(err[aliased].mean())
        to_world = reference.camera_to_world(ego)
        hits = scene.cast_rays(make_rays(to_world.translation, reference.pixel_directions, to_world.rotation))
        depth = np.where(hits.hit, hits.t_m * reference.pixel_directions[:, 2], 0.0).astype(np.float32)
        edge_share.append(edge_pixels(hits, depth.reshape(base.height_px, base.width_px)).mean())
    n = len(frames)
    print(f"{n} frames of {args.sim}, {args.condition}, {base.width_px}x{base.height_px}; reference "
          f"{args.reference} samples everywhere; edge pixels {100 * np.mean(edge_share):.1f}% of the image")
    print(f"{'anti-aliasing':<20} {'ms/frame':>9} {'x 1 sample':>11} {'MAE all':>8} {'MAE aliased px':>15}")
    for name in cameras:
        print(f"{name:<20} {1000 * seconds[name] / n:9.0f} {seconds[name] / seconds['1 sample']:11.2f} "
              f"{np.mean(errors[name]):8.2f} {np.mean(aliased_errors[name]):15.2f}")


if __name__ == "__main__":
    main()
