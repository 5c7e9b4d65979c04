"""The table's greedy matching against pycocotools' per-image matching (area 'all', no max_dets cut).

pycocotools matches exactly as the paper's table defines (greedy by score, IoU >= threshold, one-to-one,
crowds ignored), so its TP/FP counts at the same thresholds are a reference for ours.
"""

from __future__ import annotations

import contextlib
import copy
import io

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from evaluation.io_coco import detections_from_list, ground_truth_from_dict
from evaluation.table import match_table, table_rows

IOUS = (0.5, 0.6, 0.7, 0.8)
COORD = st.integers(0, 10).map(lambda v: v * 5)
SIZE = st.sampled_from([5, 10, 15, 20, 30, 50])


@st.composite
def problems(draw):
    images = [{"id": i + 1} for i in range(draw(st.integers(1, 3)))]
    categories = [{"id": 1, "name": "a"}, {"id": 2, "name": "b"}]
    anns, results = [], []
    for img in images:
        for _ in range(draw(st.integers(0, 5))):
            w, h = draw(SIZE), draw(SIZE)
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": img["id"],
                    "category_id": draw(st.sampled_from([1, 2])),
                    "bbox": [draw(COORD), draw(COORD), w, h],
                    "area": float(w * h),
                    "iscrowd": int(draw(st.integers(0, 7)) == 0),
                }
            )
        for _ in range(draw(st.integers(1, 8))):
            results.append(
                {
                    "image_id": img["id"],
                    "category_id": draw(st.sampled_from([1, 2])),
                    "bbox": [draw(COORD), draw(COORD), draw(SIZE), draw(SIZE)],
                    "score": draw(st.sampled_from([0.2, 0.5, 0.8])),
                }
            )
    return {"images": images, "annotations": anns, "categories": categories}, results


def reference_counts(gt, results):
    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt = COCO()
        coco_gt.dataset = copy.deepcopy(gt)
        coco_gt.createIndex()
        ev = COCOeval(coco_gt, coco_gt.loadRes(copy.deepcopy(results)), "bbox")
        ev.params.iouThrs = np.array(IOUS)
        ev.params.maxDets = [10_000]
        ev.params.areaRng, ev.params.areaRngLbl = [[0, 1e10]], ["all"]
        ev.evaluate()
    tp = np.zeros(len(IOUS), int)
    fp = np.zeros(len(IOUS), int)
    for e in ev.evalImgs:
        if e is None:
            continue
        counted = ~e["dtIgnore"].astype(bool)
        tp += ((e["dtMatches"] > 0) & counted).sum(axis=1)
        fp += ((e["dtMatches"] == 0) & counted).sum(axis=1)
    return tp, fp


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(problems())
def test_table_counts_equal_pycocotools_matching(problem):
    gt, results = problem
    g = ground_truth_from_dict(gt)
    d = detections_from_list(results, g)
    rows = [r for r in table_rows(g, d, match_table(g, d, IOUS), 0.0) if r["group"] == "all" and r["class"] == "all"]
    tp, fp = reference_counts(gt, results)
    assert [r["tp"] for r in rows] == tp.tolist()
    assert [r["fp"] for r in rows] == fp.tolist()
    n_objects = sum(1 for a in gt["annotations"] if not a["iscrowd"])
    assert all(r["tp"] + r["fn"] == n_objects for r in rows)
