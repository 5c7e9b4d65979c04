"""Benchmark COCO bbox AP: pycocotools vs faster-coco-eval vs roadsynth's evaluation.coco_ap, in one run.

Problem (issue 5): 5000 images, 3 classes, ~10 ground truths and ~30 detections per image, 1% crowd,
scores rounded to 2 decimals (many ties). Each tool starts from the same in-memory COCO dict and results
list (deep-copied beforehand: pycocotools mutates its inputs) and runs load + evaluate + accumulate +
summarize; ours includes its strict validation. Prints seconds, speed-up over pycocotools and whether
the 12 stats (and, for ours, the precision array) equal pycocotools' to 1e-12.

Then the whole process, as a user runs it, from the same problem written to JSON files: ``roadsynth
evaluate --metrics coco`` (interpreter start, imports, reading and validating the files, metrics.json,
plot data and report.md; no PNGs, as without ``--png``) against a Python process running pycocotools'
COCO(file), loadRes(file), evaluate, accumulate, summarize. Best of ``--repeat`` each, alternating.

    .venv/bin/python bench/bench_coco_eval.py [--images 5000] [--seed 0] [--repeat 1] [--no-process]
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import logging
import time

import numpy as np


def make_problem(n_images: int, seed: int, n_classes: int = 3) -> tuple[dict, list]:
    """A COCO instances dict and a results list with realistic overlaps (vectorised generation)."""
    rng = np.random.default_rng(seed)
    n_gt = rng.poisson(10, n_images)
    img = np.repeat(np.arange(1, n_images + 1), n_gt)
    m = len(img)
    wh = rng.uniform(8, 250, (m, 2))
    xy = rng.uniform(0, 1280, (m, 2))
    cat = rng.integers(1, n_classes + 1, m)
    crowd = rng.random(m) < 0.01
    area = wh.prod(axis=1) * rng.uniform(0.6, 1.0, m)
    anns = [{"id": i + 1, "image_id": int(img[i]), "category_id": int(cat[i]), "iscrowd": int(crowd[i]),
             "bbox": [*xy[i].tolist(), *wh[i].tolist()], "area": float(area[i])} for i in range(m)]
    # ~2 detections per object (jittered, 10% wrong class) + ~10 background detections per image.
    k = rng.poisson(2, m)
    src = np.repeat(np.arange(m), k)
    jitter = rng.normal(0, 0.12, (len(src), 4))
    d_xy = xy[src] + jitter[:, :2] * wh[src]
    d_wh = np.abs(wh[src] * (1 + jitter[:, 2:]))
    d_cat = np.where(rng.random(len(src)) < 0.9, cat[src], rng.integers(1, n_classes + 1, len(src)))
    n_bg = rng.poisson(10, n_images)
    bg_img = np.repeat(np.arange(1, n_images + 1), n_bg)
    b = len(bg_img)
    boxes = np.concatenate([np.hstack([d_xy, d_wh]), np.hstack([rng.uniform(0, 1280, (b, 2)),
                                                                 rng.uniform(8, 250, (b, 2))])])
    d_img = np.concatenate([img[src], bg_img])
    d_cat = np.concatenate([d_cat, rng.integers(1, n_classes + 1, b)])
    score = np.round(rng.random(len(d_img)), 2)
    order = rng.permutation(len(d_img))
    results = [{"image_id": int(d_img[i]), "category_id": int(d_cat[i]), "bbox": boxes[i].tolist(),
                "score": float(score[i])} for i in order]
    gt = {"images": [{"id": i} for i in range(1, n_images + 1)],
          "categories": [{"id": c, "name": f"class{c}"} for c in range(1, n_classes + 1)], "annotations": anns}
    return gt, results


def run_pycocotools(gt: dict, results: list):
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt = COCO()
        coco_gt.dataset = gt
        coco_gt.createIndex()
        ev = COCOeval(coco_gt, coco_gt.loadRes(results), "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return np.asarray(ev.stats), ev.eval["precision"]


def run_faster_coco_eval(gt: dict, results: list):
    from faster_coco_eval import COCO, COCOeval_faster

    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt = COCO(gt)
        ev = COCOeval_faster(coco_gt, coco_gt.loadRes(results), "bbox", print_function=lambda *a, **k: None)
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return np.asarray(ev.stats[:12]), ev.eval["precision"]


def run_ours(gt: dict, results: list):
    from evaluation.coco_ap import accumulate_coco, summarize_coco
    from evaluation.io_coco import detections_from_list, ground_truth_from_dict

    g = ground_truth_from_dict(gt, "bench-gt")
    acc = accumulate_coco(g, detections_from_list(results, g, "bench-results"))
    return np.asarray(summarize_coco(acc, g.category_names)["stats"]), acc.precision


PYCOCOTOOLS_SCRIPT = """
import contextlib, io, json, sys
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval
with contextlib.redirect_stdout(io.StringIO()):
    gt = COCO(sys.argv[1])
    ev = COCOeval(gt, gt.loadRes(sys.argv[2]), "bbox")
    ev.evaluate()
    ev.accumulate()
    ev.summarize()
print(json.dumps(ev.stats.tolist()))
"""


def whole_process(gt: dict, results: list, repeat: int) -> None:
    """Seconds of ``roadsynth evaluate --metrics coco`` and of a pycocotools script, each a fresh process."""
    import json
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        (tmp / "gt.json").write_text(json.dumps(gt))
        (tmp / "dt.json").write_text(json.dumps(results))
        gt_path, dt_path = str(tmp / "gt.json"), str(tmp / "dt.json")
        commands = {
            "pycocotools": [sys.executable, "-c", PYCOCOTOOLS_SCRIPT, gt_path, dt_path],
            "roadsynth evaluate": [sys.executable, "-m", "pipeline.stages.cli", "evaluate", "--gt", gt_path,
                                   "--detections", dt_path, "--metrics", "coco", "--out", str(tmp / "eval")],
        }
        best = dict.fromkeys(commands, float("inf"))
        for _ in range(repeat):
            for name, cmd in commands.items():
                t0 = time.perf_counter()
                subprocess.run(cmd, cwd=repo, check=True, capture_output=True)
                best[name] = min(best[name], time.perf_counter() - t0)
        stats = json.loads((tmp / "eval" / "metrics.json").read_text())["coco"]["stats"]
        ref = subprocess.run(commands["pycocotools"], cwd=repo, check=True, capture_output=True, text=True).stdout
    diff = float(np.max(np.abs(np.array(stats) - np.array(json.loads(ref)))))
    print(f"whole process (files {(len(json.dumps(gt)) + len(json.dumps(results))) / 1e6:.0f} MB):")
    print(f"{'command':<20}{'seconds':>10}{'vs pycocotools':>16}")
    for name, seconds in best.items():
        print(f"{name:<20}{seconds:>10.2f}{best['pycocotools'] / seconds:>15.1f}x")
    print(f"max |stats diff| of the two processes: {diff:.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=5000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--repeat", type=int, default=1, help="best of N runs per tool")
    parser.add_argument("--no-process", action="store_true", help="skip the whole-process comparison")
    args = parser.parse_args()
    logging.disable(logging.INFO)
    gt, results = make_problem(args.images, args.seed)
    n_crowd = sum(a["iscrowd"] for a in gt["annotations"])
    print(f"problem: {args.images} images, 3 classes, {len(gt['annotations'])} ground truths ({n_crowd} crowd), "
          f"{len(results)} detections, {len({r['score'] for r in results})} distinct scores")
    tools = {"pycocotools": run_pycocotools, "faster-coco-eval": run_faster_coco_eval, "roadsynth": run_ours}
    timings, outputs = {}, {}
    for name, fn in tools.items():
        best = float("inf")
        for _ in range(args.repeat):
            g, r = copy.deepcopy(gt), copy.deepcopy(results)
            t0 = time.perf_counter()
            outputs[name] = fn(g, r)
            best = min(best, time.perf_counter() - t0)
        timings[name] = best
    ref_stats, ref_precision = outputs["pycocotools"]
    print(f"{'tool':<18}{'seconds':>10}{'vs pycocotools':>16}{'vs faster-coco-eval':>21}{'max |stats diff|':>18}"
          f"{'stats match':>13}{'precision match':>17}")
    for name in tools:
        stats, precision = outputs[name]
        diff = float(np.max(np.abs(stats - ref_stats)))
        p_match = precision.shape == ref_precision.shape and float(np.max(np.abs(precision - ref_precision))) <= 1e-12
        print(f"{name:<18}{timings[name]:>10.3f}{timings['pycocotools'] / timings[name]:>15.1f}x"
              f"{timings['faster-coco-eval'] / timings[name]:>20.2f}x{diff:>18.2e}{diff <= 1e-12!s:>13}{p_match!s:>17}")
    print("stats (pycocotools):", np.array2string(ref_stats, precision=4, separator=", "))
    if not args.no_process:
        whole_process(gt, results, args.repeat)


if __name__ == "__main__":
    main()
