"""TIDE-style error breakdown on a hand-made image with one error of each kind."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from evaluation.error_breakdown import error_breakdown
from evaluation.io_coco import detections_from_list, ground_truth_from_dict
from evaluation.table import match_table, table_rows


def test_one_error_of_each_kind():
    cats = [{"id": 1, "name": "person"}, {"id": 3, "name": "car"}]
    objects = [  # (category, bbox)
        (3, [0, 0, 10, 10]),  # found, then duplicated
        (3, [100, 0, 10, 10]),  # localisation target (IoU 0.25)
        (1, [200, 0, 10, 10]),  # classification target (car box on a person)
        (1, [300, 0, 10, 10]),  # both: car box at IoU 0.25 on a person
        (3, [400, 0, 10, 10]),  # missed
    ]
    gt = {"images": [{"id": 1}], "categories": cats,
          "annotations": [{"id": k + 1, "image_id": 1, "category_id": c, "bbox": b, "area": 100.0, "iscrowd": 0}
                          for k, (c, b) in enumerate(objects)]}
    dets = [(3, [0, 0, 10, 10], 0.9), (3, [0, 0, 10, 9], 0.8), (3, [100, 0, 5, 5], 0.7),
            (3, [200, 0, 10, 10], 0.7), (3, [300, 0, 5, 5], 0.7), (3, [600, 600, 10, 10], 0.7),
            (1, [0, 0, 10, 10], 0.1)]  # below the score threshold: not counted
    results = [{"image_id": 1, "category_id": c, "bbox": b, "score": s} for c, b, s in dets]
    g = ground_truth_from_dict(gt)
    d = detections_from_list(results, g)
    out = error_breakdown(g, d, match_table(g, d, (0.5,)), score_threshold=0.5)
    assert out["counts"] == {"duplicate": 1, "classification": 1, "localisation": 1, "both": 1, "background": 1,
                             "missed": 1}
    assert out["fp"] == 5 and out["fn"] == 4
    assert out["per_class"]["car"]["background"] == 1 and out["per_class"]["car"]["missed"] == 1
    assert out["per_class"]["person"]["missed"] == 0


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_error_counts_partition_the_tables_false_positives(data):
    boxes = st.tuples(st.integers(0, 8), st.integers(0, 8), st.integers(1, 6), st.integers(1, 6)).map(
        lambda b: [b[0] * 5, b[1] * 5, b[2] * 5, b[3] * 5])
    anns = data.draw(st.lists(st.tuples(st.sampled_from([1, 3]), boxes, st.booleans()), max_size=6))
    dets = data.draw(st.lists(st.tuples(st.sampled_from([1, 3]), boxes, st.sampled_from([0.2, 0.6, 0.9])),
                              max_size=8))
    gt = {"images": [{"id": 1}], "categories": [{"id": 1, "name": "person"}, {"id": 3, "name": "car"}],
          "annotations": [{"id": k + 1, "image_id": 1, "category_id": c, "bbox": b, "area": 1.0, "iscrowd": int(cr)}
                          for k, (c, b, cr) in enumerate(anns)]}
    g = ground_truth_from_dict(gt)
    d = detections_from_list([{"image_id": 1, "category_id": c, "bbox": b, "score": s} for c, b, s in dets], g)
    m = match_table(g, d, (0.5,))
    out = error_breakdown(g, d, m, score_threshold=0.5)
    (row,) = [r for r in table_rows(g, d, m, 0.5) if r["group"] == "all" and r["class"] == "all"]
    assert sum(v for k, v in out["counts"].items() if k != "missed") == out["fp"] == row["fp"]
    assert out["counts"]["missed"] <= out["fn"] == row["fn"]
