"""COCO AP/AR against pycocotools' COCOeval on many random problems (stats, precision, recall to 1e-12).

Boxes sit on a coarse integer grid so IoUs land exactly on thresholds, scores come from a small set so
they tie, areas hit the area-range bounds (32**2, 96**2) exactly, and problems include crowds, empty
images, categories without ground truth and categories without detections.
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

from evaluation.coco_ap import accumulate_coco, coco_stats_by_group, summarize_coco
from evaluation.inputs import image_groups
from evaluation.io_coco import detections_from_list, ground_truth_from_dict

GRID = st.integers(0, 12).map(lambda v: v * 4)
SIZE = st.sampled_from([0, 4, 8, 16, 24, 32, 40, 64, 96, 100, 120, 160])
AREA_SPECIAL = st.sampled_from([None, 0.0, 32.0**2, 96.0**2, 500.0, 5000.0, 20000.0])
SCORE = st.sampled_from([0.1, 0.3, 0.5, 0.5, 0.7, 0.9, 1.0])


def reference(gt: dict, results: list) -> COCOeval:
    """pycocotools on deep copies (it mutates its inputs), silenced."""
    with contextlib.redirect_stdout(io.StringIO()):
        coco_gt = COCO()
        coco_gt.dataset = copy.deepcopy(gt)
        coco_gt.createIndex()
        coco_dt = coco_gt.loadRes(copy.deepcopy(results))
        ev = COCOeval(coco_gt, coco_dt, "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return ev


def ours(gt: dict, results: list):
    g = ground_truth_from_dict(gt, "gt.json")
    acc = accumulate_coco(g, detections_from_list(results, g, "results.json"))
    return acc, summarize_coco(acc, g.category_names)


def assert_identical(gt: dict, results: list) -> None:
    ev = reference(gt, results)
    acc, summary = ours(gt, results)
    np.testing.assert_allclose(summary["stats"], ev.stats, rtol=0, atol=1e-12)
    np.testing.assert_allclose(acc.precision, ev.eval["precision"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(acc.recall, ev.eval["recall"], rtol=0, atol=1e-12)


@st.composite
def problems(draw):
    n_img = draw(st.integers(1, 4))
    n_cat = draw(st.integers(1, 3))
    images = [{"id": i * 7 + 3, "condition": "night" if i % 2 else "day"} for i in range(n_img)]
    categories = [{"id": c * 2 + 1, "name": f"class{c}"} for c in range(n_cat)]
    anns, results = [], []
    for img in images:
        for _ in range(draw(st.integers(0, 6))):
            x, y, w, h = draw(GRID), draw(GRID), draw(SIZE), draw(SIZE)
            area = draw(AREA_SPECIAL)
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": img["id"],
                    "category_id": draw(st.sampled_from(categories))["id"],
                    "bbox": [x, y, w, h],
                    "area": float(w * h) if area is None else area,
                    "iscrowd": int(draw(st.integers(0, 9)) == 0),
                }
            )
        for _ in range(draw(st.integers(0, 8))):
            x, y, w, h = draw(GRID), draw(GRID), draw(SIZE), draw(SIZE)
            results.append(
                {
                    "image_id": img["id"],
                    "category_id": draw(st.sampled_from(categories))["id"],
                    "bbox": [x, y, w, h],
                    "score": draw(SCORE),
                }
            )
    # Detections near ground truth, so that matches (and exact threshold hits) are common.
    for ann in draw(st.lists(st.sampled_from(anns), max_size=8)) if anns else []:
        dx, dy, dw = (
            draw(st.sampled_from([0, 2, 4])),
            draw(st.sampled_from([0, 2, 4])),
            draw(st.sampled_from([0, 4, 8])),
        )
        x, y, w, h = ann["bbox"]
        results.append(
            {
                "image_id": ann["image_id"],
                "category_id": ann["category_id"],
                "bbox": [x + dx, y + dy, w + dw, h],
                "score": draw(SCORE),
            }
        )
    return {"images": images, "annotations": anns, "categories": categories}, results


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(problems())
def test_identical_to_pycocotools_on_random_problems(problem):
    gt, results = problem
    if not results:  # pycocotools cannot load an empty results list (IndexError)
        return
    assert_identical(gt, results)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(problems())
def test_stats_by_group_are_each_groups_images_evaluated_alone(problem):
    """The stats of a group equal those of a COCO file holding only its images (read by the reader, exactly) and
    pycocotools' on that file (to 1e-12): what the report stage's per-condition COCO AP is."""
    gt, results = problem
    g = ground_truth_from_dict(gt, "gt.json")
    names, index = image_groups(g, "condition")
    by_group = coco_stats_by_group(g, detections_from_list(results, g, "results.json"), index, names)
    assert list(by_group) == sorted({img["condition"] for img in gt["images"]})
    for name in names:
        ids = {img["id"] for img in gt["images"] if img["condition"] == name}
        alone = dict(gt, images=[img for img in gt["images"] if img["id"] in ids],
                     annotations=[a for a in gt["annotations"] if a["image_id"] in ids])
        alone_results = [r for r in results if r["image_id"] in ids]
        assert by_group[name] == ours(alone, alone_results)[1]["stats"]
        if alone_results:  # pycocotools cannot load an empty results list
            np.testing.assert_allclose(by_group[name], reference(alone, alone_results).stats, rtol=0, atol=1e-12)


def _random_problem(rng: np.random.Generator, n_img: int, n_cat: int = 3, crowd: float = 0.02):
    images = [{"id": i + 1} for i in range(n_img)]
    categories = [{"id": c + 1, "name": f"c{c}"} for c in range(n_cat)]
    anns, results = [], []
    for i in range(n_img):
        for _ in range(rng.poisson(8)):
            x, y = rng.uniform(0, 400, 2)
            w, h = rng.uniform(4, 200, 2)
            cat = int(rng.integers(1, n_cat + 1))
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i + 1,
                    "category_id": cat,
                    "bbox": [x, y, w, h],
                    "area": w * h * rng.uniform(0.6, 1.0),
                    "iscrowd": int(rng.random() < crowd),
                }
            )
            for _ in range(rng.poisson(2)):
                j = rng.normal(0, 0.12, 4)
                results.append(
                    {
                        "image_id": i + 1,
                        "category_id": cat,
                        "score": float(np.round(rng.random(), 2)),
                        "bbox": [x + j[0] * w, y + j[1] * h, w * (1 + j[2]), abs(h * (1 + j[3]))],
                    }
                )
        for _ in range(rng.poisson(6)):
            x, y = rng.uniform(0, 400, 2)
            w, h = rng.uniform(4, 200, 2)
            results.append(
                {
                    "image_id": i + 1,
                    "category_id": int(rng.integers(1, n_cat + 1)),
                    "bbox": [x, y, w, h],
                    "score": float(np.round(rng.random(), 2)),
                }
            )
    return {"images": images, "annotations": anns, "categories": categories}, results


def test_identical_on_a_larger_problem_with_over_100_detections_per_image():
    rng = np.random.default_rng(5)
    gt, results = _random_problem(rng, 60)
    # One image with 150 detections of one class: exercises the per-image max_dets = 100 cut.
    results += [
        {"image_id": 1, "category_id": 1, "bbox": [float(k), 10.0, 30.0, 30.0], "score": 0.5} for k in range(150)
    ]
    assert_identical(gt, results)


def test_category_without_ground_truth_is_minus_one_like_pycocotools():
    gt = {
        "images": [{"id": 1}],
        "categories": [{"id": 1, "name": "a"}, {"id": 2, "name": "b"}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 10, 10], "area": 100, "iscrowd": 0}],
    }
    results = [{"image_id": 1, "category_id": 2, "bbox": [0, 0, 10, 10], "score": 0.9}]
    assert_identical(gt, results)
    acc, summary = ours(gt, results)
    assert (acc.precision[:, :, 1] == -1).all()
    assert summary["per_class"]["b"]["ap"] == -1 and not summary["per_class"]["b"]["valid"]
    assert summary["per_class"]["a"]["ap"] == 0.0


def test_result_categories_the_gt_lacks_are_ignored_like_pycocotools(tmp_path):
    """A COCO-80 detector on a 3-class dataset: stats equal pycocotools' on the full file and on the file
    filtered to the ground truth's categories; the extra ones are counted per id in metrics.json."""
    import json

    from evaluation import evaluate

    rng = np.random.default_rng(11)
    gt, results = _random_problem(rng, 30)
    extra = []
    for r in results[::3]:  # same boxes and (tied) scores under categories the GT lacks, interleaved
        extra.append({**r, "category_id": int(rng.choice([10, 44, 90]))})
    mixed = [x for pair in zip(results, extra + [None] * len(results), strict=False) for x in pair if x is not None]
    assert len(mixed) == len(results) + len(extra)
    ev_mixed, ev_filtered = reference(gt, mixed), reference(gt, results)
    np.testing.assert_allclose(ev_mixed.stats, ev_filtered.stats, rtol=0, atol=0)
    assert_identical(gt, mixed)
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    (tmp_path / "dt.json").write_text(json.dumps(mixed))
    result = evaluate(tmp_path / "gt.json", tmp_path / "dt.json", metrics="coco")
    np.testing.assert_allclose(result.metrics["coco"]["stats"], ev_filtered.stats, rtol=0, atol=1e-12)
    counts = {str(c): sum(e["category_id"] == c for e in extra) for c in (10, 44, 90)}
    assert result.metrics["ignored"]["detections_by_category_not_in_gt"] == {k: v for k, v in counts.items() if v}
    assert result.metrics["ignored"]["detections_of_categories_not_in_gt"] == len(extra)
