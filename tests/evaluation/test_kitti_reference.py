"""Vectorised KITTI AP against a plain-loop reference written from the devkit's description.

The reference follows evaluate_object.cpp step by step (cleanData, computeStatistics with and
without FP, getThresholds, the 41-point precision) for official and port modes (equal in 2D), and
for exact mode re-runs the score-priority assignment from scratch at every distinct score (so it
also checks that one assignment serves all thresholds). Problems are small, crowded and full of ties and conflicts.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from evaluation.kitti import evaluate_kitti, read_label_dir

MIN_H, MAX_OCC, MAX_TRUNC = (40, 25, 25), (0, 1, 2), (0.15, 0.3, 0.5)
THRESHOLD = 0.5  # Pedestrian, bbox


def _iou(a, b, own=False) -> float:
    w, h = min(a[2], b[2]) - max(a[0], b[0]), min(a[3], b[3]) - max(a[1], b[1])
    if w <= 0 or h <= 0:
        return 0.0
    area_a = (a[2] - a[0]) * (a[3] - a[1])
    return w * h / (area_a if own else area_a + (b[2] - b[0]) * (b[3] - b[1]) - w * h)


def _clean(gt, det, cls, d):
    ig_gt, ig_det, dc = [], [], []
    for g in gt:
        name = g.type.lower()
        valid = 1 if name == cls else 0 if (cls, name) == ("pedestrian", "person_sitting") else -1
        ignore = g.occluded > MAX_OCC[d] or g.truncated > MAX_TRUNC[d] or g.bbox[3] - g.bbox[1] <= MIN_H[d]
        ig_gt.append(0 if valid == 1 and not ignore else 1 if valid == 0 or (ignore and valid == 1) else -1)
        if name == "dontcare":
            dc.append(g.bbox)
    for e in det:
        height = abs(e.bbox[3] - e.bbox[1])
        ig_det.append(1 if height < MIN_H[d] else 0 if e.type.lower() == cls else -1)
    return ig_gt, ig_det, dc


def _stats(gt, det, ig_gt, ig_det, dc, compute_fp, thresh, by_score_only=False):
    """computeStatistics; by_score_only uses the threshold-collecting rule even with FP (exact mode)."""
    assigned = [False] * len(det)
    low = [compute_fp and e.score < thresh for e in det]
    tp = fp = fn = 0
    sim, scores = 0.0, []
    for i, g in enumerate(gt):
        if ig_gt[i] == -1:
            continue
        det_idx, valid, max_overlap, took_ignored = -1, -1e7, 0.0, False
        for j, e in enumerate(det):
            if ig_det[j] == -1 or assigned[j] or low[j]:
                continue
            overlap = _iou(e.bbox, g.bbox)
            if (not compute_fp or by_score_only) and overlap > THRESHOLD and e.score > valid:
                det_idx, valid = j, e.score
            elif compute_fp and not by_score_only and overlap > THRESHOLD:
                if (overlap > max_overlap or took_ignored) and ig_det[j] == 0:
                    max_overlap, det_idx, valid, took_ignored = overlap, j, 1, False
                elif valid == -1e7 and ig_det[j] == 1:
                    det_idx, valid, took_ignored = j, 1, True
        if det_idx == -1 and ig_gt[i] == 0:
            fn += 1
        elif det_idx != -1 and (ig_gt[i] == 1 or ig_det[det_idx] == 1):
            assigned[det_idx] = True
        elif det_idx != -1:
            tp += 1
            scores.append(det[det_idx].score)
            sim += (1 + math.cos(g.alpha - det[det_idx].alpha)) / 2
            assigned[det_idx] = True
    if compute_fp:
        fp = sum(1 for j in range(len(det)) if not (assigned[j] or ig_det[j] != 0 or low[j]))
        for region in dc:
            for j, e in enumerate(det):
                if not (assigned[j] or ig_det[j] != 0 or low[j]) and _iou(e.bbox, region, own=True) > THRESHOLD:
                    assigned[j] = True
                    fp -= 1
    return tp, fp, fn, sim, scores


def _thresholds(v, n):
    v, out, current = sorted(v, reverse=True), [], 0.0
    for i, s in enumerate(v):
        left = (i + 1) / n
        right = (i + 2) / n if i < len(v) - 1 else left
        if (right - current) < (current - left) and i < len(v) - 1:
            continue
        out.append(s)
        current += 1 / 40
    return out


def _frames(gt, det, cls, d):
    for key in gt:
        g = [_Obj(gt[key], k) for k in range(len(gt[key]))]
        e = [_Obj(det[key], k) for k in range(len(det[key]))]
        yield g, e, *_clean(g, e, cls, d)


class _Obj:
    def __init__(self, frame, k):
        self.type, self.bbox, self.alpha = frame.type[k], tuple(frame.bbox[k]), frame.alpha[k]
        self.occluded, self.truncated = frame.occluded[k], frame.truncated[k]
        self.score = frame.score[k] if frame.score is not None else 0.0


def reference(gt, det, cls, d, exact):
    frames = list(_frames(gt, det, cls, d))
    n_gt = sum(ig.count(0) for _, _, ig, _, _ in frames)
    if exact:
        points = sorted({e.score for _, es, _, _, _ in frames for e in es})
        best = [0.0] * 41
        for u in points:
            tp = fp = fn = 0
            for g, e, ig, igd, dc in frames:
                t, f, n, _, _ = _stats(g, e, ig, igd, dc, True, u, by_score_only=True)
                tp, fp, fn = tp + t, fp + f, fn + n
            if tp + fn > 0 and tp + fp > 0:
                level = 40 * tp // (tp + fn)
                best[level] = max(best[level], tp / (tp + fp))
        prec = [max(best[i:]) for i in range(41)]
        return (sum(prec[1:]) / 40, sum(prec[0::4]) / 11) if n_gt else (None, None)
    scores = [s for g, e, ig, igd, dc in frames for s in _stats(g, e, ig, igd, dc, False, 0)[4]]
    prec = [0.0] * 41
    for k, t in enumerate(_thresholds(scores, n_gt)):
        tp = fp = 0
        for g, e, ig, igd, dc in frames:
            a, b, _, _, _ = _stats(g, e, ig, igd, dc, True, t)
            tp, fp = tp + a, fp + b
        prec[k] = tp / (tp + fp) if tp + fp else 0.0
    prec = [max(prec[i:]) for i in range(41)]
    return sum(prec[1:]) / 40, sum(prec[0::4]) / 11


def _random_problem(root: Path, rng: np.random.Generator, n_frames: int) -> tuple[Path, Path]:
    kinds = ["Pedestrian"] * 6 + ["Person_sitting", "Cyclist", "DontCare"]
    for name in ("gt", "det"):
        (root / name).mkdir()
    for f in range(n_frames):
        centres = rng.uniform(0, 200, (rng.integers(1, 7), 2))
        gt_lines, det_lines = [], []
        for cx, cy in centres:
            h, w = rng.choice([20.0, 30.0, 45.0, 60.0]), rng.uniform(15, 40)
            kind = kinds[rng.integers(len(kinds))]
            occ, trunc = rng.integers(0, 4), rng.choice([0.0, 0.1, 0.2, 0.4, 0.6])
            box = (cx, cy, cx + w, cy + h)
            gt_lines.append(f"{kind} {trunc} {occ} 0.1 " + " ".join(f"{v:.2f}" for v in box) + " 1 1 1 0 0 10 0")
            for _ in range(rng.integers(0, 4)):
                jit = rng.normal(0, 4, 4)
                dbox = (cx + jit[0], cy + jit[1], cx + w + jit[2], cy + h + abs(jit[3]))
                dkind = "Pedestrian" if rng.random() < 0.8 else "Cyclist"
                score = rng.choice([0.2, 0.4, 0.5, 0.6, 0.8, 0.9])
                fields = " ".join(f"{v:.2f}" for v in dbox)
                det_lines.append(f"{dkind} -1 -1 {rng.uniform(-3, 3):.2f} {fields} 1 1 1 0 0 10 0 {score}")
        (root / "gt" / f"{f:06d}.txt").write_text("\n".join(gt_lines) + "\n")
        (root / "det" / f"{f:06d}.txt").write_text("\n".join(det_lines) + "\n")
    return root / "gt", root / "det"


@pytest.mark.parametrize("seed", range(6))
def test_matches_loop_reference(tmp_path: Path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    gt_dir, det_dir = _random_problem(tmp_path, rng, n_frames=[3, 10, 25][seed % 3])
    gt, det = read_label_dir(gt_dir, with_score=False), read_label_dir(det_dir, with_score=True)
    for mode in ("official", "port", "exact"):
        result = evaluate_kitti(gt_dir, det_dir, mode=mode, classes=("Pedestrian",), metrics=("bbox",))
        for d, name in enumerate(("easy", "moderate", "hard")):
            got = result["results"]["Pedestrian"][name]["bbox"]
            want = reference(gt, det, "pedestrian", d, exact=mode == "exact")
            assert (got["ap_r40"], got["ap_r11"]) == pytest.approx(want, abs=1e-12), (mode, name)
