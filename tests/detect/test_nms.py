"""Class-wise greedy NMS and box IoU: closed-form cases and a plain greedy reference."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pipeline.detect.infer import box_iou, nms


def boxes(*rows):
    return torch.tensor(rows, dtype=torch.float32)


def test_iou_closed_form():
    a = boxes([0, 0, 10, 10])
    b = boxes([5, 0, 15, 10], [20, 20, 30, 30], [0, 0, 10, 10], [2, 2, 2, 8])
    iou = box_iou(a, b)[0]
    assert iou.tolist() == pytest.approx([50 / 150, 0.0, 1.0, 0.0])


def test_overlapping_box_is_suppressed_and_distinct_ones_stay():
    b = boxes([0, 0, 10, 10], [1, 0, 11, 10], [50, 50, 60, 60])
    keep = nms(b, torch.tensor([0.9, 0.8, 0.7]), 0.5)
    assert keep.tolist() == [0, 2]  # IoU(0, 1) = 90/110 > 0.5


def test_result_is_ordered_by_score():
    b = boxes([0, 0, 10, 10], [50, 50, 60, 60], [100, 0, 110, 10])
    assert nms(b, torch.tensor([0.2, 0.9, 0.5]), 0.5).tolist() == [1, 2, 0]


def test_threshold_is_strict():
    b = boxes([0, 0, 10, 10], [5, 0, 15, 10])  # IoU exactly 1/3
    assert nms(b, torch.tensor([0.9, 0.8]), 1 / 3 + 1e-6).tolist() == [0, 1]
    assert nms(b, torch.tensor([0.9, 0.8]), 1 / 3 - 1e-6).tolist() == [0]


def test_chain_a_suppressed_box_suppresses_nothing():
    # A overlaps B, B overlaps C, A does not overlap C: greedy keeps A and C (Fast-NMS would drop C).
    b = boxes([0, 0, 10, 10], [6, 0, 16, 10], [12, 0, 22, 10])
    assert box_iou(b[:1], b[2:])[0, 0] == 0
    assert nms(b, torch.tensor([0.9, 0.8, 0.7]), 0.2).tolist() == [0, 2]  # IoU(A, B) = IoU(B, C) = 0.25


def test_classes_do_not_suppress_each_other():
    b = boxes([0, 0, 10, 10], [0, 0, 10, 10], [0, 0, 10, 10])
    keep = nms(b, torch.tensor([0.9, 0.8, 0.7]), 0.5, classes=torch.tensor([3, 8, 3]))
    assert keep.tolist() == [0, 1]


def test_empty():
    assert nms(torch.zeros((0, 4)), torch.zeros(0), 0.5).tolist() == []


def greedy_reference(b: np.ndarray, s: np.ndarray, c: np.ndarray, t: float) -> list[int]:
    order = sorted(range(len(s)), key=lambda i: (-s[i], i))
    kept: list[int] = []
    for i in order:
        ok = True
        for j in kept:
            if c[i] != c[j]:
                continue
            ix = max(0.0, min(b[i, 2], b[j, 2]) - max(b[i, 0], b[j, 0]))
            iy = max(0.0, min(b[i, 3], b[j, 3]) - max(b[i, 1], b[j, 1]))
            inter = ix * iy
            union = (b[i, 2] - b[i, 0]) * (b[i, 3] - b[i, 1]) + (b[j, 2] - b[j, 0]) * (b[j, 3] - b[j, 1]) - inter
            if inter / union > t:
                ok = False
                break
        if ok:
            kept.append(i)
    return kept


@pytest.mark.parametrize("seed", range(5))
def test_matches_a_plain_greedy_loop(seed):
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 100, (200, 2))
    wh = rng.uniform(5, 40, (200, 2))
    b = np.concatenate([xy, xy + wh], axis=1)
    s = rng.random(200)
    c = rng.integers(0, 3, 200)
    keep = nms(torch.from_numpy(b), torch.from_numpy(s), 0.4, torch.from_numpy(c))
    assert keep.tolist() == greedy_reference(b, s, c, 0.4)
