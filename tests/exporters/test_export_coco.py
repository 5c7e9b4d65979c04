"""COCO export read back with pycocotools: masks, boxes, attributes, categories, ignore regions, splits."""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO

from exporters.base import BoxMode, ExportOptions, get_exporter
from exporters.coco import instance_rles
from exporters.splits import SplitSpec
from pipeline.core.record import DatasetRecord

# pycocotools 2.0.x decodes masks through a NumPy-2-deprecated path; not ours to fix.
pytestmark = pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")

COCO_IDS = {"person": 1, "bicycle": 2, "car": 3, "motorcycle": 4, "bus": 6, "truck": 8}


def _record_of(image: dict, roots: list[Path]) -> Path:
    for root in roots:
        info = json.loads((root / "record.json").read_text())
        keys = ("scenario", "seed", "condition")
        if [info[k] for k in keys] == [image[k] for k in keys]:
            return root
    raise LookupError(image)


@pytest.fixture(scope="module")
def coco_out(tmp_path_factory, records) -> Path:
    out = tmp_path_factory.mktemp("coco") / "coco"
    get_exporter("coco").export(records, out)
    return out


def test_pycocotools_masks_equal_instance_image_and_bbox_equals_mask_bounds(coco_out, records):
    coco = COCO(str(coco_out / "annotations.json"))
    assert len(coco.getImgIds()) == 6 and len(coco.getAnnIds()) > 0
    for ann in coco.loadAnns(coco.getAnnIds()):
        image = coco.loadImgs(ann["image_id"])[0]
        root = _record_of(image, records)
        path = root / "cameras" / image["camera"] / "instance" / f"{image['frame']:06d}.png"
        ours = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) == ann["track_id"]
        mask = coco.annToMask(ann).astype(bool)
        assert mask.shape == (image["height"], image["width"])
        np.testing.assert_array_equal(mask, ours)
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        assert ann["bbox"] == [cols[0], rows[0], cols[-1] + 1 - cols[0], rows[-1] + 1 - rows[0]]
        assert ann["area"] == mask.sum() == ann["visible_px"]


def test_images_keep_origin_and_ids_start_at_one(coco_out, records):
    data = json.loads((coco_out / "annotations.json").read_text())
    assert sorted(i["id"] for i in data["images"]) == list(range(1, 7))
    assert sorted(a["id"] for a in data["annotations"]) == list(range(1, len(data["annotations"]) + 1))
    assert {(i["scenario"], i["seed"], i["condition"]) for i in data["images"]} == {
        ("highway", 1, "morning"), ("highway", 1, "night"), ("urban", 2, "morning")}
    for image in data["images"]:
        assert image["frame"] in (10, 11) and image["timestamp_s"] == pytest.approx(image["frame"] * 0.1)
        assert (coco_out / "images" / image["file_name"]).is_file()
        frames = DatasetRecord(_record_of(image, records)).frames
        assert frames.set_index("frame").loc[image["frame"], "time_s"] == image["timestamp_s"]
    assert {c["name"]: c["id"] for c in data["categories"]} == COCO_IDS
    assert all(c["supercategory"] for c in data["categories"])


def test_images_are_hard_links_of_the_record(coco_out, records):
    data = json.loads((coco_out / "annotations.json").read_text())
    image = data["images"][0]
    src = _record_of(image, records) / "cameras" / image["camera"] / "rgb" / f"{image['frame']:06d}.png"
    assert os.stat(coco_out / "images" / image["file_name"]).st_ino == os.stat(src).st_ino


def test_extra_fields_classes_and_filters(coco_out):
    data = json.loads((coco_out / "annotations.json").read_text())
    by_track = {}
    for ann in data["annotations"]:
        by_track.setdefault(ann["track_id"], []).append(ann)
    assert 7 not in by_track  # the car hidden behind car 3 has no visible pixel: not annotated
    van = by_track[4][0]
    assert van["category_id"] == 3 and van["subclass"] == "van" and van["iscrowd"] == 0
    assert 0.3 < van["occlusion"] < 0.6 and isinstance(van["occlusion"], float)
    truck = by_track[9][0]
    assert truck["category_id"] == 8 and truck["truncation"] > 0.4 and truck["bbox"][0] == 0.0
    assert truck["bbox_amodal"][0] < 0  # the amodal box is not clipped
    car = by_track[3][0]
    assert car["box3d_camera"]["size_m"] == [4.5, 1.8, 1.5]
    assert car["box3d_camera"]["rotation_y_rad"] == pytest.approx(-np.pi / 2, abs=1e-6)
    assert car["lidar_points"] == 120 and car["distance_m"] > 10
    pedestrian = by_track[12][0]  # 16 visible pixels < 20: an ignore region
    assert pedestrian["iscrowd"] == 1 and pedestrian["ignore_reason"] == "tiny" and pedestrian["category_id"] == 1
    summary = json.loads((coco_out / "export.json").read_text())["counts"]["objects"]["total"]
    assert summary == {"kept": 18, "hidden": 6, "tiny": 6, "occluded": 0, "no_category": 0, "in_cycle": 0}


def test_filter_thresholds_are_options(tmp_path, morning):
    from exporters.filters import ObjectFilter

    out = tmp_path / "coco"
    get_exporter("coco").export([morning], out, ExportOptions(filter=ObjectFilter(min_visible_px=1, max_occlusion=0.3)))
    anns = json.loads((out / "annotations.json").read_text())["annotations"]
    reasons = {a["track_id"]: a.get("ignore_reason") for a in anns}
    assert reasons == {3: None, 4: "occluded", 9: None, 12: None}


def test_amodal_boxes(tmp_path, morning):
    out = tmp_path / "coco"
    get_exporter("coco").export([morning], out, ExportOptions(box=BoxMode.AMODAL))
    anns = json.loads((out / "annotations.json").read_text())["annotations"]
    labels = DatasetRecord(morning).labels
    for ann in anns:
        image_frame = 10 if ann["image_id"] == 1 else 11
        row = labels[(labels.frame == image_frame) & (labels.sensor == "front") & (labels.track_id == ann["track_id"])]
        x1, y1, x2, y2 = (float(row[f"amodal_clip_{k}"].iloc[0]) for k in ("x1", "y1", "x2", "y2"))
        np.testing.assert_allclose(ann["bbox"], [x1, y1, x2 - x1, y2 - y1], atol=1e-3)


def test_one_annotation_file_per_split_and_runs_stay_whole(tmp_path, records):
    out = tmp_path / "coco"
    spec = SplitSpec.parse("train=highway:1,val=urban:2")
    get_exporter("coco").export(records, out, ExportOptions(splits=spec))
    train = COCO(str(out / "annotations_train.json"))
    val = COCO(str(out / "annotations_val.json"))
    assert {(i["scenario"], i["condition"]) for i in train.dataset["images"]} == {("highway", "morning"),
                                                                                  ("highway", "night")}
    assert {i["scenario"] for i in val.dataset["images"]} == {"urban"}
    assert not set(train.getImgIds()) & set(val.getImgIds())
    assert not (out / "annotations.json").exists()
    recorded = json.loads((out / "export.json").read_text())["splits"]
    assert recorded["runs"] == {"highway:1": "train", "urban:2": "val"}


def _encode(mask: np.ndarray) -> dict:
    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(s) for s in rle["size"]], "counts": rle["counts"].decode("ascii")}


@pytest.mark.parametrize("seed", range(6))
def test_instance_rles_equal_pycocotools_encode_of_each_mask(seed):
    """One pass over the instance image gives, per id, the bytes pycocotools' encode gives for that id's mask:
    blobs of random ids and sizes, ids touching the first and last pixel, one covering every pixel but one,
    and an id that is absent."""
    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 40, 2)
    image = np.zeros((h, w), np.int32)
    for k in range(1, 9):
        y, x = rng.integers(0, h), rng.integers(0, w)
        image[y: y + rng.integers(1, h + 1), x: x + rng.integers(1, w + 1)] = k
    if seed == 1:
        image[0, 0], image[-1, -1] = 11, 12  # column-major first and last pixel
    if seed == 2:
        image[:] = 5
        image[h // 2, w // 2] = 0
    ids = np.array([1, 5, 8, 11, 12, 99])
    for k, (rle, area) in zip(ids, instance_rles(image, ids), strict=True):
        assert rle == _encode(image == k), k
        assert area == int((image == k).sum())
        np.testing.assert_array_equal(mask_utils.decode({"size": rle["size"], "counts": rle["counts"].encode()}),
                                      (image == k).astype(np.uint8))
