"""Fixed KITTI label sets on which the official C++ devkit's numbers are pinned (devkit_golden.json).

Each case is a pair of label directories written from a seeded generator with two decimals per
number, so the files (and the devkit's answers) are the same on every machine. The cases are
chosen where a port and the devkit could differ: detections that are exact copies of the ground
truth (coincident rotated boxes), duplicates, boxes sharing edges, jittered boxes near the overlap
thresholds, DontCare regions with and without a 3D box, the "-1 -1 -1" sentinel, empty frames, and no ground
truth at all.

Used by tests/evaluation/test_kitti_devkit.py and tests/evaluation/regenerate_kitti_devkit_golden.py
(which regenerates the golden values from a devkit binary).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

CLASSES = ("Car", "Pedestrian", "Cyclist")
# name -> (seed, share of ground truth copied exactly, share jittered, false positives per frame)
CASES: dict[str, tuple[int, float, float, float]] = {
    "gt_as_detection": (1, 1.0, 0.0, 0.0),
    "partly_exact": (2, 0.5, 0.4, 0.6),
    "jittered": (3, 0.0, 0.9, 1.0),
    "jittered_small": (4, 0.0, 0.8, 0.3),
    "no_ground_truth": (5, 0.5, 0.5, 0.5),  # the ground-truth files are empty: every detection is a FP
    "sparse_detections": (6, 0.5, 0.3, 0.5),  # no Cyclist detection, Pedestrians in 2D only: not evaluated
}
N_FRAMES = {"gt_as_detection": 60, "partly_exact": 80, "jittered": 80, "jittered_small": 12, "no_ground_truth": 10,
            "sparse_detections": 30}  # fmt: skip
NO_3D_BOX = "-1.00 -1.00 -1.00 -1000.00 -1000.00 -1000.00 -10.00"
SIZES = {"Car": (1.5, 1.6, 3.9), "Van": (2.1, 1.9, 5.0), "Pedestrian": (1.75, 0.6, 0.8),
         "Person_sitting": (1.2, 0.6, 0.8), "Cyclist": (1.7, 0.6, 1.8), "Truck": (3.2, 2.5, 9.0)}  # fmt: skip
KINDS = ["Car"] * 8 + ["Van", "Pedestrian", "Pedestrian", "Pedestrian", "Person_sitting", "Cyclist", "Cyclist", "Truck"]
FOCAL, CX, CY = 720.0, 620.0, 190.0


def _fmt(values) -> str:
    return " ".join(f"{float(v):.2f}" for v in values)


def _bbox(x: float, y: float, z: float, h: float) -> tuple[float, float, float, float]:
    """A plausible 2D box of an object at depth z (its projected height sets the difficulty)."""
    u, top, bottom = FOCAL * x / z + CX, FOCAL * (y - h) / z + CY, FOCAL * y / z + CY
    half = 0.5 * (bottom - top) * 1.2
    return u - half, top, u + half, bottom


def _object(rng: np.random.Generator, kind: str, slot: int) -> list[float]:
    h, w, length = (s * rng.uniform(0.9, 1.1) for s in SIZES[kind])
    x, z = -15.0 + 7.5 * (slot % 5) + rng.uniform(-1, 1), 8.0 + 9.0 * (slot // 5) + rng.uniform(-1, 1)
    y = 1.65 + rng.uniform(-0.1, 0.1)
    ry = rng.uniform(-np.pi, np.pi)
    return [h, w, length, x, y, z, ry]


def _line(kind: str, trunc: float, occ: int, box3: list[float], score: float | None = None) -> str:
    h, w, length, x, y, z, ry = box3
    x1, y1, x2, y2 = _bbox(x, y, z, h)
    alpha = ry - math.atan2(x, z)  # libm, not a SIMD loop: the files are the same everywhere
    text = f"{kind} {trunc:.2f} {occ} {alpha:.2f} {_fmt((x1, y1, x2, y2))} {_fmt((h, w, length, x, y, z, ry))}"
    return text if score is None else f"{text} {score:.2f}"


def _dontcare(rng: np.random.Generator, slot: int, with_box: bool) -> str:
    x, z = -15.0 + 7.5 * (slot % 5), 8.0 + 9.0 * (slot // 5)
    x1, y1, x2, y2 = _bbox(x, 1.65, z, 2.0)
    if with_box:  # a DontCare region with a 3D extent (the devkit then uses it in BEV/3D too)
        return f"DontCare -1 -1 -10 {_fmt((x1, y1, x2, y2))} {_fmt((2.0, 3.0, 4.0, x, 1.65, z, 0.0))}"
    return f"DontCare -1 -1 -10 {_fmt((x1, y1, x2, y2))} -1 -1 -1 -1000 -1000 -1000 -10"


def _jitter(rng: np.random.Generator, box3: list[float], scale: float) -> list[float]:
    h, w, length, x, y, z, ry = box3
    dx, dz = rng.normal(0, 0.25 * scale, 2)
    return [h * rng.uniform(0.9, 1.1), w * rng.uniform(0.9, 1.1), length * rng.uniform(0.9, 1.1),
            x + dx, y + rng.normal(0, 0.1 * scale), z + dz, ry + rng.normal(0, 0.15 * scale)]  # fmt: skip


def _two_d_only(line: str) -> str:
    """The detection line with its 3D box replaced by the no-3D-box sentinel."""
    fields = line.split()
    return " ".join([*fields[:8], NO_3D_BOX, fields[15]])


def write_case(name: str, root: Path) -> tuple[Path, Path]:
    """Write case ``name`` as root/label_2 (ground truth) and root/results/data (detections)."""
    seed, exact_share, jitter_share, fp_rate = CASES[name]
    rng = np.random.default_rng(seed)
    gt_dir, det_dir = root / "label_2", root / "results" / "data"
    gt_dir.mkdir(parents=True)
    det_dir.mkdir(parents=True)
    for frame in range(N_FRAMES[name]):
        gt_lines, det_lines = [], []
        n_objects = 0 if frame % 11 == 5 else int(rng.integers(1, 9))  # some frames are empty
        slots = rng.permutation(20)
        for k in range(n_objects):
            kind = KINDS[int(rng.integers(len(KINDS)))]
            box3 = _object(rng, kind, int(slots[k]))
            trunc, occ = float(rng.choice([0.0, 0.0, 0.1, 0.2, 0.4])), int(rng.choice([0, 0, 1, 2, 3]))
            gt_lines.append(_line(kind, trunc, occ, box3))
            draw = rng.random()
            score = rng.uniform(0.05, 1.0)
            det_kind = kind if kind in CLASSES else ("Car" if kind in ("Van", "Truck") else "Pedestrian")
            if draw < exact_share:
                det_lines.append(_line(det_kind, -1, -1, box3, score))
                if rng.random() < 0.1:  # an exact duplicate with a lower score
                    det_lines.append(_line(det_kind, -1, -1, box3, score * 0.5))
            elif draw < exact_share + jitter_share:
                det_lines.append(_line(det_kind, -1, -1, _jitter(rng, box3, float(rng.choice([0.5, 1.0, 2.0]))), score))
        if rng.random() < 0.3:
            gt_lines.append(_dontcare(rng, int(slots[-1]), with_box=bool(rng.random() < 0.5)))
            if rng.random() < 0.7:  # a false positive inside the DontCare region
                box3 = [1.5, 1.6, 3.9, -15.0 + 7.5 * (slots[-1] % 5), 1.65, 8.0 + 9.0 * (slots[-1] // 5), 0.1]
                det_lines.append(_line("Car", -1, -1, box3, rng.uniform(0.05, 1.0)))
        for _ in range(int(rng.poisson(fp_rate))):
            kind = CLASSES[int(rng.integers(3))]
            det_lines.append(_line(kind, -1, -1, _object(rng, kind, int(rng.integers(20))), rng.uniform(0.05, 0.9)))
        if rng.random() < 0.1:  # a 2D-only detection: the no-3D-box sentinel
            det_lines.append(f"Car -1 -1 -10 {_fmt((300, 150, 360, 200))} -1 -1 -1 -1000 -1000 -1000 -10 0.30")
        if name == "no_ground_truth":
            gt_lines = []
        if name == "sparse_detections":
            det_lines = [_two_d_only(line) if line.startswith("Pedestrian ") else line
                         for line in det_lines if not line.startswith("Cyclist ")]  # fmt: skip
        (gt_dir / f"{frame:06d}.txt").write_text("".join(line + "\n" for line in gt_lines))
        (det_dir / f"{frame:06d}.txt").write_text("".join(line + "\n" for line in det_lines))
    return gt_dir, det_dir
