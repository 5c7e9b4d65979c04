"""The realism gauge on hand-made cases with closed-form answers: class groups, height bins, recall per object,
distance bins and the transmittance; AP50 against pycocotools; the output folder with its contact sheets."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from evaluation.io_coco import detections_from_list, ground_truth_from_dict
from evaluation.realism import ap_101, group_categories, match_group, object_index, realism_metrics, transmittance
from evaluation.realism_report import evaluate_realism
from evaluation.validate import InputError

CATEGORIES = [{"id": 1, "name": "person"}, {"id": 2, "name": "bicycle"}, {"id": 3, "name": "car"},
              {"id": 4, "name": "motorcycle"}, {"id": 6, "name": "bus"}, {"id": 8, "name": "truck"}]
SEQ = {"scenario": "urban", "seed": 5, "camera": "front"}


def coco(annotations, n_images=3, condition="morning"):
    images = [{"id": i, "file_name": f"{i}.png", "width": 320, "height": 240, "condition": condition, "frame": i,
               **SEQ} for i in range(1, n_images + 1)]
    anns = [{"id": k + 1, "iscrowd": 0, "category_id": 3, "area": 100.0, **a} for k, a in enumerate(annotations)]
    return {"images": images, "annotations": anns, "categories": CATEGORIES}


def det(image_id, bbox, score, category_id=3):
    return {"image_id": image_id, "category_id": category_id, "bbox": bbox, "score": score}


def metrics_of(gt_data, results, score_threshold=0.3, **kw):
    g = ground_truth_from_dict(gt_data)
    return realism_metrics(g, detections_from_list(results, g), score_threshold=score_threshold, **kw)[0]


def row(metrics, class_group="vehicles", group="all", height="30+"):
    (r,) = [r for r in metrics["rows"]
            if (r["class_group"], r["group"], r["height_px"]) == (class_group, group, height)]
    return r


A, B = [10, 10, 20, 40], [100, 50, 40, 80]  # track 7: 40 px tall (30-60); track 9: 80 px (60+)


def two_tracks():
    """Tracks 7 and 9 in each of 3 frames; 7 found in frames 1 and 2, 9 only below the threshold (frame 3), and a
    false positive 40 px tall in frame 3."""
    anns = [{"image_id": i, "bbox": box, "track_id": t, "distance_m": d}
            for i in (1, 2, 3) for box, t, d in ((A, 7, 12.0), (B, 9, 45.0))]
    results = [det(1, A, 0.9), det(2, A, 0.9), det(3, [250, 150, 20, 40], 0.5), det(3, B, 0.1)]
    return coco(anns), results


def test_two_tracks_frames_and_objects():
    m = metrics_of(*two_tracks())
    r = row(m)
    assert (r["gt"], r["tp"], r["fp"], r["fn"]) == (6, 2, 1, 4)
    assert r["recall"] == pytest.approx(2 / 6) and r["precision"] == pytest.approx(2 / 3)
    assert (r["objects"], r["objects_found_any"], r["objects_found_most"]) == (2, 1, 1)  # 2 of 3 frames is most
    assert r["object_recall_any"] == 0.5 and r["object_mean_share"] == pytest.approx((2 / 3 + 0) / 2)
    # AP50 over every detection: TP 0.9, TP 0.9, FP 0.5, TP 0.1 of 6 objects; precision envelope 1, 1, .75, .75
    assert r["ap50"] == pytest.approx((17 + 17 + 17 * 0.75) / 101)


def test_height_bins_ignore_the_other_bins_objects():
    m = metrics_of(*two_tracks())
    low = row(m, height="30-60")  # track 7 only; the 0.1 box on track 9 matches an ignored object
    assert (low["gt"], low["tp"], low["fp"]) == (3, 2, 1) and low["objects"] == 1
    assert low["object_recall_most"] == 1.0 and low["object_mean_share"] == pytest.approx(2 / 3)
    high = row(m, height="60+")  # track 9 only: the 0.9 boxes hit ignored objects, the 40 px FP is outside the bin
    assert (high["gt"], high["tp"], high["fp"]) == (3, 0, 0)
    assert high["recall"] == 0.0 and high["precision"] is None and high["object_recall_any"] == 0.0
    assert high["ap50"] == pytest.approx(34 / 101)  # one TP at score 0.1: precision 1 up to recall 1/3


def test_a_box_exactly_60_px_is_in_60_plus_only():
    m = metrics_of(coco([{"image_id": 1, "bbox": [0, 0, 30, 60], "track_id": 1}], n_images=1), [])
    assert row(m, height="60+")["gt"] == 1 and row(m, height="30-60")["gt"] == 0


def test_class_groups_are_class_agnostic_and_other_groups_are_ignored():
    anns = [{"image_id": 1, "bbox": [0, 0, 60, 40], "track_id": 1, "category_id": 8},  # a truck
            {"image_id": 1, "bbox": [100, 0, 20, 50], "track_id": 2, "category_id": 4}]  # a motorcycle with rider
    results = [det(1, [0, 0, 60, 40], 0.8, category_id=3),  # boxed as a car: a vehicle found
               det(1, [100, 0, 20, 48], 0.7, category_id=1)]  # its rider boxed as a person: not a false person
    m = metrics_of(coco(anns, n_images=1), results)
    assert (row(m)["tp"], row(m)["fp"]) == (1, 0)
    people = row(m, "people")
    assert (people["gt"], people["tp"], people["fp"], people["precision"]) == (0, 0, 0, None)
    assert row(m, "two-wheelers")["fn"] == 1


def test_an_object_is_a_track_within_its_sequence():
    anns = [{"image_id": 1, "bbox": A, "track_id": 7}, {"image_id": 2, "bbox": A, "track_id": 7},
            {"image_id": 3, "bbox": A, "track_id": 7}, {"image_id": 1, "bbox": B}, {"image_id": 2, "bbox": B}]
    data = coco(anns)
    data["images"][2]["seed"] = 6  # frame 3 is another run: its track 7 is another object
    g = ground_truth_from_dict(data)
    objects = object_index(g)
    assert objects[0] == objects[1] != objects[2]
    assert len(set(objects[3:]) | set(objects[:3])) == 4  # without a track id each box is an object of its own


def test_distance_bins_and_the_fog_transmittance():
    anns = [{"image_id": 1, "bbox": [k * 40, 0, 20, 40], "track_id": k + 1, "distance_m": d}
            for k, d in enumerate((5.0, 10.0, 15.0, 95.0, 130.0))]
    results = [det(1, [0, 0, 20, 40], 0.9), det(1, [120, 0, 20, 40], 0.9)]  # found: 5 m and 95 m
    m = metrics_of(coco(anns, n_images=1, condition="fog"), results, visibility_m={"fog": 80.0})
    rows = {r["bin"]: r for r in m["distance"]["rows"] if r["group"] == "fog" and r["class_group"] == "vehicles"}
    assert (rows["0-10"]["gt"], rows["0-10"]["recall"]) == (1, 1.0)
    assert (rows["10-20"]["gt"], rows["10-20"]["recall"]) == (2, 0.0)  # 10 m is in 10-20
    assert (rows["80-120"]["gt"], rows["80-120"]["tp"], rows["120+"]["gt"]) == (1, 1, 1)
    assert rows["20-30"]["recall"] is None
    assert rows["0-10"]["transmittance"] == pytest.approx(np.exp(-3.912 * 5 / 80))
    assert rows["120+"]["transmittance"] == pytest.approx(transmittance(120.0, 80.0))
    assert transmittance(80.0, 80.0) == pytest.approx(0.02, rel=1e-3)  # visibility: 2 % contrast left
    other = [r for r in m["distance"]["rows"] if r["group"] == "all"]
    assert all(r["transmittance"] is None for r in other)


def test_objects_per_frame_count_30_px_and_taller():
    anns = [{"image_id": 1, "bbox": [0, 0, 10, 29], "category_id": 1}, {"image_id": 1, "bbox": [0, 0, 10, 30],
                                                                        "category_id": 1},
            {"image_id": 2, "bbox": [0, 0, 10, 90], "category_id": 1}, {"image_id": 2, "bbox": A}]
    m = metrics_of(coco(anns, n_images=2), [])
    assert m["objects_per_frame"]["by_group"]["morning"] == {"vehicles": 0.5, "people": 1.0, "two-wheelers": 0.0}


def test_people_by_who_they_are():
    """An adult (track 1, 40 px, found in 2 of 3 frames) and a child (track 2, 70 px, never found); a 40 px person
    without ``person`` (track 3) counts in the people rows but in no person row; a false person changes nothing."""
    people = [{"image_id": i, "bbox": box, "track_id": t, "category_id": 1, **({"person": who} if who else {})}
              for i in (1, 2, 3) for box, t, who in (([0, 0, 15, 40], 1, "adult"), ([100, 0, 30, 70], 2, "child"),
                                                     ([200, 0, 15, 40], 3, None))]
    results = [det(1, [0, 0, 15, 40], 0.9, 1), det(2, [0, 0, 15, 40], 0.8, 1), det(3, [0, 0, 15, 40], 0.1, 1),
               det(1, [250, 150, 15, 40], 0.9, 1)]
    m = metrics_of(coco(people), results)
    rows = {(r["group"], r["height_px"], r["person"]): r for r in m["people_by_person"]}
    adult, child = rows[("morning", "30+", "adult")], rows[("morning", "30+", "child")]
    assert (adult["gt"], adult["found"], adult["objects"], adult["objects_found_any"]) == (3, 2, 1, 1)
    assert adult["recall"] == pytest.approx(2 / 3) and adult["object_recall_most"] == 1.0
    assert (child["gt"], child["found"], child["recall"], child["object_recall_any"]) == (3, 0, 0.0, 0.0)
    assert ("morning", "30-60", "child") not in rows and rows[("morning", "60+", "child")]["gt"] == 3
    assert {k[2] for k in rows} == {"adult", "child"} and [k[2] for k in rows][:2] == ["adult", "child"]
    assert row(m, "people")["gt"] == 9
    from evaluation.realism_markdown import realism_markdown
    text = realism_markdown(m)
    assert "## People by who they are" in text and "| morning | 60+ | child | 3 |" in text
    assert metrics_of(coco([{k: v for k, v in a.items() if k != "person"} for a in people]), results)[
        "people_by_person"] == []
    on_bike = coco([{"image_id": 1, "bbox": [0, 0, 15, 40], "category_id": 1, "person": "adult", "subclass": "rider"}],
                   n_images=1)
    assert {r["person"] for r in metrics_of(on_bike, [])["people_by_person"]} == {"rider"}
    with pytest.raises(InputError, match="field 'person' is 3"):
        ground_truth_from_dict(coco([{"image_id": 1, "bbox": A, "person": 3}], n_images=1))


def test_crowd_regions_are_neither_objects_nor_false_positives():
    anns = [{"image_id": 1, "bbox": [0, 0, 40, 40], "iscrowd": 1}]
    m = metrics_of(coco(anns, n_images=1), [det(1, [5, 5, 30, 30], 0.9)])
    assert (row(m)["gt"], row(m)["fp"]) == (0, 0)


def test_ap50_equals_pycocotools_for_one_category():
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    rng = np.random.default_rng(3)
    anns, results = [], []
    for i in range(1, 21):
        for _ in range(rng.integers(0, 5)):
            x, y, w, h = rng.uniform(0, 200), rng.uniform(0, 150), rng.uniform(10, 80), rng.uniform(10, 80)
            anns.append({"image_id": i, "bbox": [x, y, w, h], "area": w * h})
            if rng.random() < 0.7:
                results.append(det(i, [x + rng.normal(0, 4), y + rng.normal(0, 4), w, h], float(rng.random())))
        for _ in range(rng.integers(0, 3)):
            results.append(det(i, [rng.uniform(0, 250), rng.uniform(0, 200), 30, 30], float(rng.random())))
    data = coco(anns, n_images=20)
    data["categories"] = [{"id": 3, "name": "car"}]
    cocogt = COCO()
    cocogt.dataset = data
    cocogt.createIndex()
    ev = COCOeval(cocogt, cocogt.loadRes(results), "bbox")
    ev.params.iouThrs = np.array([0.5])
    ev.params.maxDets = [100]
    ev.params.areaRng, ev.params.areaRngLbl = [[0, 1e10]], ["all"]
    ev.evaluate()
    ev.accumulate()
    reference = float(np.mean(ev.eval["precision"][0, :, 0, 0, 0]))
    # the bin "all" holds every object: AP50 over it is pycocotools' on the same file
    g = ground_truth_from_dict(data)
    d = detections_from_list(results, g)
    gm = match_group(g, d, group_categories(g, ("car",)), 0.0)
    a = gm.bins.index("all")
    ours = ap_101(gm.dt_tp[:, a], gm.dt_fp[:, a], d.score[gm.dt_index], int(gm.gt_counted[:, a].sum()))
    assert ours == pytest.approx(reference, abs=1e-12) and 0.2 < ours < 0.9


def test_bad_track_id_is_named():
    with pytest.raises(InputError, match=r"annotations\[0\].*track_id.*integer"):
        ground_truth_from_dict(coco([{"image_id": 1, "bbox": A, "track_id": 1.5}], n_images=1))


def test_output_folder_and_contact_sheets(tmp_path):
    data, results = two_tracks()
    (tmp_path / "images").mkdir()
    for i, shade in zip((1, 2, 3), (40, 120, 200), strict=True):
        cv2.imwrite(str(tmp_path / "images" / f"{i}.png"), np.full((240, 320, 3), shade, np.uint8))
    (tmp_path / "gt.json").write_text(json.dumps(data))
    (tmp_path / "dt.json").write_text(json.dumps(results))
    m = evaluate_realism(tmp_path / "gt.json", tmp_path / "dt.json", tmp_path / "out", score_threshold=0.3,
                         visibility_m={"fog": 80.0})
    out = tmp_path / "out"
    assert m["luma"]["morning"] == {"mean": pytest.approx(120.0), "images": 3}
    assert m["missed_objects"]["vehicles"] == {"missed": 1, "shown": 1, "sheet": "missed_vehicles.png"}
    sheet = cv2.imread(str(out / "missed_vehicles.png"))
    assert sheet is not None and sheet.shape[0] > 100
    assert m["missed_objects"]["people"]["sheet"] is None and not (out / "missed_people.png").exists()
    assert cv2.imread(str(out / "recall_by_distance.png")) is not None
    text = (out / "realism.md").read_text()
    assert "| morning |" in text and "missed_vehicles.png" in text
    assert json.loads((out / "metrics.json").read_text())["rows"] == json.loads(json.dumps(m["rows"]))


def test_image_groups_keep_the_order_of_their_images():
    data = coco([{"image_id": 1, "bbox": A}], n_images=3)
    for image, condition in zip(data["images"], ("noon", "night", "noon"), strict=True):
        image["condition"] = condition
    m = metrics_of(data, [])
    assert list(dict.fromkeys(r["group"] for r in m["rows"])) == ["all", "noon", "night"]


def test_a_road_user_boxed_under_two_names_of_its_group_is_found_once_not_a_false_positive():
    anns = [{"image_id": 1, "bbox": [0, 0, 60, 40], "track_id": 1}]
    twice = [det(1, [0, 0, 60, 40], 0.8, category_id=8), det(1, [2, 0, 60, 40], 0.6, category_id=3)]
    r = row(metrics_of(coco(anns, n_images=1), twice))
    assert (r["tp"], r["fp"], r["precision"]) == (1, 0, 1.0)
    same = [det(1, [0, 0, 60, 40], 0.8), det(1, [2, 0, 60, 40], 0.6)]  # a duplicate of one name: COCO's FP
    r = row(metrics_of(coco(anns, n_images=1), same))
    assert (r["tp"], r["fp"], r["precision"]) == (1, 1, 0.5)


def test_a_small_false_positive_counts_among_all_sizes_only():
    anns = [{"image_id": 1, "bbox": A, "track_id": 7}, {"image_id": 1, "bbox": [200, 0, 8, 12], "track_id": 8}]
    results = [det(1, A, 0.9), det(1, [100, 100, 10, 12], 0.8), det(1, [200, 0, 8, 12], 0.7)]
    m = metrics_of(coco(anns, n_images=1), results)
    assert (row(m)["tp"], row(m)["fp"], row(m)["gt"]) == (1, 0, 1)  # >= 30 px: the 12 px boxes are ignored
    every = row(m, height="all")
    assert (every["tp"], every["fp"], every["gt"], every["precision"]) == (2, 1, 2, pytest.approx(2 / 3))


def test_image_groups_in_a_given_order_then_as_their_images_come():
    data = coco([{"image_id": 1, "bbox": A}], n_images=3)
    for image, condition in zip(data["images"], ("dusk", "rain", "morning"), strict=True):
        image["condition"] = condition
    m = metrics_of(data, [], group_order=["morning", "night", "dusk"])
    assert list(dict.fromkeys(r["group"] for r in m["rows"])) == ["all", "morning", "dusk", "rain"]
