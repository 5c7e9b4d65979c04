"""COCO AP on hand-made cases with closed-form answers."""

from __future__ import annotations

import numpy as np
import pytest

from evaluation.coco_ap import accumulate_coco, summarize_coco
from evaluation.io_coco import detections_from_list, ground_truth_from_dict


def coco(anns, results, n_img=1):
    gt = {
        "images": [{"id": i + 1} for i in range(n_img)],
        "categories": [{"id": 3, "name": "car"}],
        "annotations": [{"id": k + 1, "image_id": 1, "category_id": 3, "iscrowd": 0, **a} for k, a in enumerate(anns)],
    }
    g = ground_truth_from_dict(gt)
    acc = accumulate_coco(g, detections_from_list(results, g))
    return acc, summarize_coco(acc, g.category_names)


def box(x, y, w, h):
    return {"bbox": [x, y, w, h], "area": float(w * h)}


def det(x, y, w, h, score):
    return {"image_id": 1, "category_id": 3, "bbox": [x, y, w, h], "score": score}


def test_one_of_two_objects_found_gives_51_of_101_recall_points():
    _, s = coco([box(0, 0, 10, 10), box(50, 50, 10, 10)], [det(0, 0, 10, 10, 0.9)])
    assert s["stats"][0] == pytest.approx(51 / 101, abs=1e-15)
    assert s["stats"][8] == pytest.approx(0.5, abs=1e-15)  # AR100


def test_false_positive_ranked_above_true_positive_halves_precision():
    acc, s = coco([box(0, 0, 10, 10)], [det(50, 50, 10, 10, 0.9), det(0, 0, 10, 10, 0.8)])
    np.testing.assert_allclose(acc.precision[0, :, 0, 0, 2], 0.5, atol=1e-15)
    assert s["stats"][1] == pytest.approx(0.5, abs=1e-15)
    # With maxDets 1 only the false positive is kept: recall 0.
    assert s["stats"][6] == 0.0


def test_iou_exactly_on_threshold_matches_and_just_below_does_not():
    # IoU exactly 0.6 (60 / 100): TP at 0.5, 0.55, 0.6; FP from 0.65 up.
    acc, _ = coco([box(0, 0, 10, 10)], [det(0, 0, 6, 10, 0.9)])
    recall = acc.recall[:, 0, 0, 2]
    np.testing.assert_array_equal(recall, [1, 1, 1, 0, 0, 0, 0, 0, 0, 0])


def test_area_range_bounds_are_inclusive():
    # area exactly 32**2 is both small and medium.
    _, s = coco([{"bbox": [0, 0, 32, 32], "area": 1024.0}], [det(0, 0, 32, 32, 0.9)])
    # precision is tp / (tp + fp + eps), hence approx.
    assert s["stats"][3] == pytest.approx(1.0, abs=1e-12) and s["stats"][4] == pytest.approx(1.0, abs=1e-12)
    assert s["stats"][5] == -1


def test_detection_inside_crowd_region_is_ignored_not_false_positive():
    anns = [box(0, 0, 10, 10), {**box(100, 100, 100, 100), "iscrowd": 1}]
    _, s = coco(anns, [det(120, 120, 10, 10, 0.95), det(0, 0, 10, 10, 0.9)])
    assert s["stats"][0] == pytest.approx(1.0, abs=1e-12)
