"""Benchmark of the KITTI evaluation on a synthetic problem shaped like KITTI val.

3769 frames, about 8 ground-truth objects (Car, Pedestrian, Cyclist, Van, Person_sitting, DontCare,
...) and about 20 detections per frame (noisy copies of most objects plus false positives). Prints
a table of wall-clock timings; the target is BEV + 3D AP in under 10 s on 2 cores.

    .venv/bin/python bench/bench_kitti_eval.py [--frames 3769] [--seed 0]
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from pathlib import Path

import numpy as np

from evaluation.kitti import evaluate_kitti, read_label_dir

log = logging.getLogger("bench_kitti_eval")

TYPES = ("Car", "Pedestrian", "Cyclist", "Van", "Person_sitting", "Truck", "DontCare")
TYPE_P = (0.55, 0.15, 0.07, 0.07, 0.02, 0.04, 0.10)
SIZES = {  # mean h, w, l in metres
    "Car": (1.5, 1.6, 3.9), "Pedestrian": (1.75, 0.65, 0.85), "Cyclist": (1.7, 0.6, 1.75),
    "Van": (2.2, 1.9, 5.1), "Person_sitting": (1.25, 0.55, 0.8), "Truck": (3.2, 2.5, 10.0), "DontCare": (1, 1, 1),
}  # fmt: skip
FOCAL_PX, CX_PX, CY_PX = 721.5, 609.6, 172.9


def _objects(rng: np.random.Generator, types: np.ndarray) -> dict[str, np.ndarray]:
    n = len(types)
    size = np.array([SIZES[t] for t in types]) * rng.uniform(0.9, 1.1, (n, 3))
    loc = np.column_stack([rng.uniform(-15, 15, n), rng.normal(1.65, 0.1, n), rng.uniform(5, 60, n)])
    ry = rng.uniform(-np.pi, np.pi, n)
    u = FOCAL_PX * loc[:, 0] / loc[:, 2] + CX_PX
    half_w = FOCAL_PX * np.maximum(size[:, 1], size[:, 2]) / loc[:, 2] / 2
    y2 = FOCAL_PX * loc[:, 1] / loc[:, 2] + CY_PX
    y1 = y2 - FOCAL_PX * size[:, 0] / loc[:, 2]
    bbox = np.column_stack([np.clip(u - half_w, 0, 1241), y1, np.clip(u + half_w, 0, 1241), y2])
    bbox[:, 2] = np.maximum(bbox[:, 2], bbox[:, 0] + 1)
    alpha = ry - np.arctan2(loc[:, 0], loc[:, 2])
    return {"size": size, "loc": loc, "ry": ry, "bbox": bbox, "alpha": alpha}


def _line(t, trunc, occ, alpha, bbox, size, loc, ry, score=None) -> str:
    if t == "DontCare":
        fields = [t, "-1", "-1", "-10", *(f"{v:.2f}" for v in bbox), "-1", "-1", "-1", "-1000", "-1000", "-1000", "-10"]
    else:
        fields = [t, f"{trunc:.2f}", str(occ), f"{alpha:.2f}", *(f"{v:.2f}" for v in bbox)]
        fields += [*(f"{v:.2f}" for v in size), *(f"{v:.2f}" for v in loc), f"{ry:.2f}"]
    if score is not None:
        fields.append(f"{score:.4f}")
    return " ".join(fields)


def make_problem(root: Path, n_frames: int, seed: int) -> tuple[Path, Path]:
    """Write label_2-style gt/ and det/ directories under root; returns their paths."""
    rng = np.random.default_rng(seed)
    gt_dir, det_dir = root / "gt", root / "det"
    gt_dir.mkdir()
    det_dir.mkdir()
    for frame in range(n_frames):
        types = rng.choice(TYPES, size=rng.poisson(8), p=TYPE_P)
        gt = _objects(rng, types)
        trunc = rng.choice([0.0, 0.0, 0.0, 0.2, 0.4, 0.7], len(types))
        occ = rng.choice([0, 0, 1, 1, 2, 3], len(types))
        gt_lines = [
            _line(t, trunc[i], occ[i], gt["alpha"][i], gt["bbox"][i], gt["size"][i], gt["loc"][i], gt["ry"][i])
            for i, t in enumerate(types)
        ]
        found = (types != "DontCare") & (rng.random(len(types)) < 0.8)
        det_types = list(types[found])
        det = {k: v[found].copy() for k, v in gt.items()}
        det["loc"] += rng.normal(0, 0.1, det["loc"].shape)
        det["size"] *= rng.normal(1, 0.03, det["size"].shape)
        det["ry"] += rng.normal(0, 0.1, len(det_types))
        det["bbox"] += rng.normal(0, 1.0, det["bbox"].shape)
        det["bbox"][:, 2:] = np.maximum(det["bbox"][:, 2:], det["bbox"][:, :2] + 1)
        scores = list(rng.uniform(0.3, 1.0, len(det_types)))
        n_fp = max(0, 20 - len(det_types))
        fp_types = rng.choice(TYPES[:3], size=n_fp, p=(0.7, 0.2, 0.1))
        fp = _objects(rng, fp_types)
        det_types += list(fp_types)
        for k in det:
            det[k] = np.concatenate([det[k], fp[k]])
        scores += list(rng.uniform(0.0, 0.7, n_fp))
        det_lines = [
            _line(t, -1, -1, det["alpha"][i], det["bbox"][i], det["size"][i], det["loc"][i], det["ry"][i], scores[i])
            for i, t in enumerate(det_types)
        ]
        name = f"{frame:06d}.txt"
        (gt_dir / name).write_text("\n".join(gt_lines) + "\n")
        (det_dir / name).write_text("\n".join(det_lines) + "\n")
    return gt_dir, det_dir


def _timed(fn):
    """(result, (wall seconds, CPU seconds of this process)); CPU time is robust to other load."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return out, (time.perf_counter() - wall, time.process_time() - cpu)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3769)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        (gt_dir, det_dir), t = _timed(lambda: make_problem(Path(tmp), args.frames, args.seed))
        rows.append(("write synthetic problem (not scored)", t, ""))
        gt, t_gt = _timed(lambda: read_label_dir(gt_dir, with_score=False))
        det, t_det = _timed(lambda: read_label_dir(det_dir, with_score=True))
        n_gt, n_det = sum(len(f) for f in gt.values()), sum(len(f) for f in det.values())
        t_parse = (t_gt[0] + t_det[0], t_gt[1] + t_det[1])
        rows.append((f"parse labels ({n_gt} GT, {n_det} det lines)", t_parse, ""))
        for mode in ("official", "port", "exact"):
            for metrics in (("bev", "3d"), ("bbox", "bev", "3d", "aos")):
                result, t = _timed(lambda m=mode, ms=metrics: evaluate_kitti(gt_dir, det_dir, mode=m, metrics=ms))
                car = result["results"]["Car"]["moderate"]
                shown = ", ".join(f"{m} {100 * car[m]['ap_r40']:.2f}" for m in metrics)
                rows.append((f"evaluate_kitti {mode:8s} {'+'.join(metrics)}", t, f"Car mod R40: {shown}"))
    width = max(len(r[0]) for r in rows)
    print(f"KITTI evaluation benchmark: {args.frames} frames, seed {args.seed}")
    print(f"{'step':{width}s}  {'wall s':>7s}  {'CPU s':>7s}  note")
    for name, (wall, cpu), note in rows:
        print(f"{name:{width}s}  {wall:7.2f}  {cpu:7.2f}  {note}")


if __name__ == "__main__":
    main()
