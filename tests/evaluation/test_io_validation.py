"""Strict validation of COCO inputs: each bad input fails with a message naming file, entry and field."""

from __future__ import annotations

import copy
import json
import math

import pytest

from evaluation.io_coco import detections_from_list, ground_truth_from_dict, read_coco_gt, read_coco_results
from evaluation.validate import InputError

GT = {
    "images": [{"id": 1, "condition": "night"}, {"id": 2}],
    "categories": [{"id": 3, "name": "car"}, {"id": 1, "name": "person"}],
    "annotations": [
        {"id": 1, "image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10], "area": 100.0, "iscrowd": 0},
        {"id": 2, "image_id": 2, "category_id": 1, "bbox": [5, 5, 10, 20], "area": 200, "iscrowd": 0},
    ],
}
RESULTS = [{"image_id": 1, "category_id": 3, "bbox": [0, 0, 10, 10], "score": 0.9},
           {"image_id": 2, "category_id": 1, "bbox": [1, 1, 2, 2], "score": 0.1}]


def bad_gt(section, index, **changes):
    gt = copy.deepcopy(GT)
    gt[section][index].update(changes)
    return gt


def bad_results(index, **changes):
    results = copy.deepcopy(RESULTS)
    results[index].update(changes)
    return results


def test_valid_inputs_read():
    g = ground_truth_from_dict(GT, "gt.json")
    d = detections_from_list(RESULTS, g, "res.json")
    assert g.category_names == ["person", "car"] and g.image_attrs[0] == {"condition": "night"}
    assert d.category_index.tolist() == [1, 0] and len(d) == 2


@pytest.mark.parametrize(
    ("gt", "message"),
    [
        (bad_gt("annotations", 1, id=0), r"gt.json: annotations\[1\]: field 'id' is 0"),
        (bad_gt("images", 1, id=0), r"images\[1\]: field 'id' is 0"),
        (bad_gt("categories", 0, id=0), r"categories\[0\]: field 'id' is 0"),
        (bad_gt("annotations", 1, id=1), r"annotations\[1\]: duplicate id 1 \(also at annotations\[0\]\)"),
        (bad_gt("images", 1, id=1), r"images\[1\]: duplicate id 1"),
        (bad_gt("categories", 1, name="car"), r"categories\[1\]: duplicate name 'car'"),
        (bad_gt("annotations", 1, image_id=9), r"annotations\[1\]: field 'image_id' is 9, not an id"),
        (bad_gt("annotations", 0, category_id=2), r"annotations\[0\]: field 'category_id' is 2"),
        (bad_gt("annotations", 1, bbox=[0, 0, -1, 5]), r"annotations\[1\]: field 'bbox' is \[0, 0, -1, 5\]"),
        (bad_gt("annotations", 1, bbox=[0, 0, math.nan, 5]), r"annotations\[1\]: field 'bbox'"),
        (bad_gt("annotations", 1, bbox=[0, 0, 5]), r"annotations\[1\]: field 'bbox'"),
        (bad_gt("annotations", 0, bbox=["0", 0, 5, 5]), r"annotations\[0\]: field 'bbox'"),
        (bad_gt("annotations", 1, area=-3.0), r"annotations\[1\]: field 'area' is -3.0"),
        (bad_gt("annotations", 1, area=math.nan), r"annotations\[1\]: field 'area' is nan"),
        (bad_gt("annotations", 1, iscrowd=2), r"annotations\[1\]: field 'iscrowd' is 2"),
        (bad_gt("annotations", 1, id="2"),
         r"annotations\[1\]: field 'id' is '2' \(expected a non-zero 64-bit integer\)"),
        (bad_gt("annotations", 1, image_id=2.0), r"annotations\[1\]: field 'image_id' is 2.0"),
        (bad_gt("annotations", 0, distance_m=-1.0), r"annotations\[0\]: field 'distance_m' is -1.0"),
        (bad_gt("annotations", 0, occlusion=1.5), r"annotations\[0\]: field 'occlusion' is 1.5"),
        ({"images": []}, r"gt.json: missing top-level field 'annotations'"),
        ([], r"expected a COCO instances object, got a JSON list \(is this a results file"),
    ],
)
def test_bad_ground_truth_names_file_entry_and_field(gt, message):
    with pytest.raises(InputError, match=message):
        ground_truth_from_dict(gt, "gt.json")


def test_missing_area_is_named():
    gt = copy.deepcopy(GT)
    del gt["annotations"][1]["area"]
    with pytest.raises(InputError, match=r"annotations\[1\]: missing field 'area'"):
        ground_truth_from_dict(gt, "gt.json")


@pytest.mark.parametrize(
    ("results", "message"),
    [
        (bad_results(1, score=math.nan), r"res.json: results\[1\]: field 'score' is nan"),
        (bad_results(1, score=None), r"results\[1\]: missing field 'score'|results\[1\]: field 'score' is None"),
        (bad_results(0, score="high"), r"results\[0\]: field 'score' is 'high'"),
        (bad_results(1, image_id=7), r"results\[1\]: field 'image_id' is 7, not an id of the ground truth's images"),
        (bad_results(0, category_id="car"), r"results\[0\]: field 'category_id' is 'car'"),
        (bad_results(0, category_id=2.0), r"results\[0\]: field 'category_id' is 2.0"),
        (bad_results(0, category_id=0), r"results\[0\]: field 'category_id' is 0"),
        (bad_results(1, image_id=True), r"results\[1\]: field 'image_id' is True"),  # JSON true is not 1
        (bad_results(1, score=False), r"results\[1\]: field 'score' is False"),
        (bad_results(1, bbox=[0, 0, 5, -5]), r"results\[1\]: field 'bbox'"),
        (bad_results(1, bbox=[0, 0, 5, math.inf]), r"results\[1\]: field 'bbox'"),
        ({"annotations": []}, r"got a JSON dict \(is this a ground-truth file"),
        ([1, 2], r"results\[0\]: expected a JSON object"),
    ],
)
def test_bad_results_name_file_entry_and_field(results, message):
    g = ground_truth_from_dict(GT, "gt.json")
    with pytest.raises(InputError, match=message):
        detections_from_list(results, g, "res.json")


def test_results_of_categories_the_gt_lacks_are_counted_not_scored():
    # pycocotools evaluates the ground truth's categories only; the others are counted per id.
    results = [*copy.deepcopy(RESULTS), {"image_id": 1, "category_id": 2, "bbox": [0, 0, 3, 3], "score": 0.5},
               {"image_id": 2, "category_id": 90, "bbox": [0, 0, 3, 3], "score": 0.4},
               {"image_id": 2, "category_id": 2, "bbox": [1, 0, 3, 3], "score": 0.3}]
    d = detections_from_list(results, ground_truth_from_dict(GT), "res.json")
    assert d.not_in_gt == {2: 2, 90: 1}
    assert len(d) == 2 and d.category_index.tolist() == [1, 0] and d.score.tolist() == [0.9, 0.1]
    # an unknown image id stays an error, whatever the category
    results[3]["image_id"] = 9
    with pytest.raises(InputError, match=r"results\[3\]: field 'image_id' is 9"):
        detections_from_list(results, ground_truth_from_dict(GT), "res.json")


def test_missing_score_is_named():
    results = copy.deepcopy(RESULTS)
    del results[1]["score"]
    with pytest.raises(InputError, match=r"results\[1\]: missing field 'score'"):
        detections_from_list(results, ground_truth_from_dict(GT), "res.json")


def test_files_round_trip_and_bad_json_names_the_file(tmp_path):
    (tmp_path / "gt.json").write_text(json.dumps(GT))
    (tmp_path / "res.json").write_text(json.dumps(RESULTS))
    g = read_coco_gt(tmp_path / "gt.json")
    assert len(read_coco_results(tmp_path / "res.json", g)) == 2
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(InputError, match="broken.json: not valid JSON"):
        read_coco_gt(tmp_path / "broken.json")


def test_empty_results_are_zero_detections():
    assert len(detections_from_list([], ground_truth_from_dict(GT))) == 0


# Found by the fuzz (tests/evaluation/test_reader_fuzz.py); each raised a bare numpy/Python error before.
@pytest.mark.parametrize(
    ("gt", "results", "message"),
    [
        # a list among the numbers: numpy's "inhomogeneous shape" ValueError, naming no file
        (bad_gt("images", 0, id=[]), RESULTS, r"gt.json: images\[0\]: field 'id' is \[\]"),
        (GT, bad_results(1, score=[0.5, 1]), r"res.json: results\[1\]: field 'score' is \[0.5, 1\]"),
        (bad_gt("annotations", 1, area=[1, 2]), RESULTS, r"annotations\[1\]: field 'area' is \[1, 2\]"),
        # an integer beyond float64: OverflowError (bbox, area, score), TypeError from np.isfinite (occlusion)
        (GT, bad_results(0, bbox=[10**400, 0, 1, 1]), r"results\[0\]: field 'bbox' is \[1000"),
        (GT, bad_results(0, score=10**400), r"results\[0\]: field 'score' is 1000"),
        (bad_gt("annotations", 0, area=10**400), RESULTS, r"annotations\[0\]: field 'area' is 1000"),
        (bad_gt("annotations", 0, occlusion=10**400), RESULTS, r"annotations\[0\]: field 'occlusion' is 1000"),
        # an integer beyond int64: "invalid values" naming no entry
        (GT, bad_results(1, image_id=2**63), r"results\[1\]: field 'image_id' is 9223372036854775808"),
        # a bad optional field was blamed on an entry that merely lacks it
        (bad_gt("annotations", 1, distance_m=-1.0), RESULTS, r"annotations\[1\]: field 'distance_m' is -1.0"),
    ],
)
def test_fuzz_findings_fail_naming_file_entry_and_field(gt, results, message):
    with pytest.raises(InputError, match=message):
        detections_from_list(results, ground_truth_from_dict(gt, "gt.json"), "res.json")


def test_integers_beyond_int64_that_are_valid_numbers_read_as_floats():
    g = ground_truth_from_dict(bad_gt("annotations", 0, area=10**30, distance_m=10**20), "gt.json")
    d = detections_from_list(bad_results(0, bbox=[0, 0, 10**30, 5]), g, "res.json")
    assert g.area[0] == 1e30 and g.distance_m[0] == 1e20 and g.distance_valid.tolist() == [True, False]
    assert d.bbox[0].tolist() == [0.0, 0.0, 1e30, 5.0]


@pytest.mark.parametrize("raw", [b"\xff\xfe\x00garbage", b"\x89PNG\r\n\x1a\n", b"[" * 100_000])
def test_binary_or_absurd_json_names_the_file(tmp_path, raw):
    (tmp_path / "gt.json").write_bytes(raw)
    with pytest.raises(InputError, match=r"gt.json: not valid JSON"):
        read_coco_gt(tmp_path / "gt.json")
