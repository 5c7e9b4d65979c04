"""The paper's precision/recall table on hand-made cases with closed-form answers."""

from __future__ import annotations

import pytest

from evaluation.io_coco import detections_from_list, ground_truth_from_dict
from evaluation.table import match_table, table_rows


def gt_dict(anns, images=None, categories=None):
    images = images or [{"id": 1, "condition": "morning"}]
    categories = categories or [{"id": 3, "name": "car"}]
    return {
        "images": images,
        "categories": categories,
        "annotations": [
            {"id": k + 1, "image_id": 1, "category_id": 3, "iscrowd": 0, "area": 100.0, **a} for k, a in enumerate(anns)
        ],
    }


def rows(anns, results, ious=(0.5, 0.6, 0.7, 0.8), score_threshold=0.0, group_by=None, **gt_kw):
    g = ground_truth_from_dict(gt_dict(anns, **gt_kw))
    d = detections_from_list(results, g)
    return table_rows(g, d, match_table(g, d, ious), score_threshold, group_by)


def pick(rs, group="all", cls="all", iou=0.5):
    (row,) = [r for r in rs if r["group"] == group and r["class"] == cls and r["iou"] == iou]
    return row


def det(bbox, score, image_id=1, category_id=3):
    return {"image_id": image_id, "category_id": category_id, "bbox": bbox, "score": score}


def test_one_of_two_objects_found():
    r = pick(rows([{"bbox": [0, 0, 10, 10]}, {"bbox": [50, 50, 10, 10]}], [det([0, 0, 10, 10], 0.9)]))
    assert (r["tp"], r["fp"], r["fn"]) == (1, 0, 1)
    assert r["precision"] == 1.0 and r["recall"] == 0.5 and r["f1"] == pytest.approx(2 / 3)


def test_false_positive_ranked_above_true_positive():
    r = pick(rows([{"bbox": [0, 0, 10, 10]}], [det([50, 50, 10, 10], 0.9), det([0, 0, 10, 10], 0.8)]))
    assert (r["tp"], r["fp"], r["fn"]) == (1, 1, 0)
    assert r["precision"] == 0.5 and r["recall"] == 1.0


def test_duplicate_is_a_false_positive_greedy_by_score():
    # The higher-scored but worse-fitting box takes the object; the better box becomes a FP.
    r = pick(rows([{"bbox": [0, 0, 10, 10]}], [det([0, 0, 7, 10], 0.9), det([0, 0, 10, 10], 0.5)]))
    assert (r["tp"], r["fp"], r["fn"]) == (1, 1, 0)


def test_iou_exactly_0_6_counts_at_0_5_and_0_6_not_at_0_7():
    rs = rows([{"bbox": [0, 0, 10, 10]}], [det([0, 0, 6, 10], 0.9)])  # IoU = 60 / 100
    assert [pick(rs, iou=t)["tp"] for t in (0.5, 0.6, 0.7, 0.8)] == [1, 1, 0, 0]
    assert [pick(rs, iou=t)["fp"] for t in (0.5, 0.6, 0.7, 0.8)] == [0, 0, 1, 1]


def test_score_threshold_is_inclusive():
    anns = [{"bbox": [0, 0, 10, 10]}]
    assert pick(rows(anns, [det([0, 0, 10, 10], 0.5)], score_threshold=0.5))["tp"] == 1
    r = pick(rows(anns, [det([0, 0, 10, 10], 0.49)], score_threshold=0.5))
    assert (r["tp"], r["fp"], r["fn"], r["precision"], r["recall"]) == (0, 0, 1, None, 0.0)


def test_crowd_match_is_neither_tp_nor_fp_and_never_fn():
    r = pick(rows([{"bbox": [0, 0, 100, 100], "iscrowd": 1}], [det([10, 10, 5, 5], 0.9)]))
    assert (r["tp"], r["fp"], r["fn"]) == (0, 0, 0)


def test_group_by_condition_and_per_class_rows():
    images = [{"id": 1, "condition": "morning"}, {"id": 2, "condition": "night"}]
    cats = [{"id": 3, "name": "car"}, {"id": 1, "name": "person"}]
    anns = [{"bbox": [0, 0, 10, 10]}]
    results = [det([0, 0, 10, 10], 0.9), det([0, 0, 10, 10], 0.9, image_id=2), det([0, 0, 10, 10], 0.9, category_id=1)]
    rs = rows(anns, results, group_by="condition", images=images, categories=cats)
    assert (pick(rs, "morning")["tp"], pick(rs, "morning")["fp"]) == (1, 1)
    assert (pick(rs, "night")["tp"], pick(rs, "night")["fp"], pick(rs, "night")["fn"]) == (0, 1, 0)
    assert pick(rs, "night")["recall"] is None  # no ground truth at night
    assert (pick(rs, cls="person")["fp"], pick(rs, cls="car")["tp"]) == (1, 1)
    assert (pick(rs)["tp"], pick(rs)["fp"], pick(rs)["fn"]) == (1, 2, 0)


def test_distance_and_occlusion_bins_report_recall_only():
    anns = [
        {"bbox": [0, 0, 10, 10], "distance_m": 10.0, "occlusion": 0.0},
        {"bbox": [50, 50, 10, 10], "distance_m": 30.0, "occlusion": 0.6},
        {"bbox": [80, 80, 10, 10], "distance_m": 70.0, "occlusion": 0.3},
    ]
    rs = rows(anns, [det([0, 0, 10, 10], 0.9), det([80, 80, 10, 10], 0.9)])
    near, mid, far = (pick(rs, f"distance_m:{b}") for b in ("0-30", "30-50", "50+"))
    assert (near["recall"], mid["recall"], far["recall"]) == (1.0, 0.0, 1.0)
    assert near["precision"] is None and near["fp"] is None
    assert pick(rs, "occlusion:heavy")["fn"] == 1 and pick(rs, "occlusion:none")["tp"] == 1


def test_box_height_bins_closed_on_the_left():
    anns = [{"bbox": [0, 0, 10, 29.99]}, {"bbox": [20, 0, 10, 30]}, {"bbox": [40, 0, 10, 59.5]},
            {"bbox": [60, 0, 10, 60]}, {"bbox": [80, 0, 10, 200]}]
    rs = rows(anns, [det([0, 0, 10, 29.99], 0.9), det([40, 0, 10, 59.5], 0.9), det([80, 0, 10, 200], 0.9)])
    small, mid, tall = (pick(rs, f"height_px:{b}") for b in ("<30", "30-60", "60+"))
    assert (small["tp"], small["fn"]) == (1, 0)
    assert (mid["tp"], mid["fn"], mid["recall"]) == (1, 1, 0.5)  # 30 and 59.5 px
    assert (tall["tp"], tall["fn"], tall["recall"]) == (1, 1, 0.5)  # 60 and 200 px
    assert small["precision"] is None and small["fp"] is None
    order = [r["group"] for r in rs if r["group"].startswith("height_px:") and r["class"] == "all"]
    assert list(dict.fromkeys(order)) == ["height_px:<30", "height_px:30-60", "height_px:60+"]
