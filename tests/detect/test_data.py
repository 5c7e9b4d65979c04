"""Reading COCO exports: which file, crowd regions, condition filter, augmentation keeps boxes on objects."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.core.config import AugmentConfig
from pipeline.detect.data import annotation_file, augment, load_coco, read_rgb


def test_annotation_file_rule(tmp_path):
    (tmp_path / "annotations_train.json").write_text("{}")
    (tmp_path / "annotations_test.json").write_text("{}")
    assert annotation_file(tmp_path, "train").name == "annotations_train.json"
    assert annotation_file(tmp_path, "test").name == "annotations_test.json"
    with pytest.raises(FileNotFoundError, match="annotations_test.json.*--split"):
        annotation_file(tmp_path, None)
    with pytest.raises(FileNotFoundError, match="annotations_val.json"):
        annotation_file(tmp_path, "val")
    (tmp_path / "annotations.json").write_text("{}")
    assert annotation_file(tmp_path, None).name == "annotations.json"


def test_unsplit_export_serves_train(tmp_path):
    (tmp_path / "annotations.json").write_text("{}")
    assert annotation_file(tmp_path, "train").name == "annotations.json"


def test_crowd_regions_are_ignore_boxes_and_conditions_filter(tiny_coco):
    raw = json.loads((tiny_coco / "annotations.json").read_text())
    data = load_coco(tiny_coco / "annotations.json", ("truck", "car"), ("morning",))
    assert [im.attributes["condition"] for im in data.images] == ["morning"] * 4
    assert data.category_ids == [8, 3]
    im = data.images[0]
    anns = [a for a in raw["annotations"] if a["image_id"] == im.id]
    assert len(im.boxes) == sum(not a["iscrowd"] for a in anns)
    assert im.ignore.tolist() == [[0.0, 0.0, 6.0, 5.0]]
    truck = [a for a in anns if a["category_id"] == 8 and not a["iscrowd"]]
    assert (im.labels == 0).sum() == len(truck)
    assert data.skipped["condition"] == 4


def test_bad_file_names_the_file(tmp_path):
    path = tmp_path / "a.json"
    path.write_text(json.dumps({"images": []}))
    with pytest.raises(ValueError, match="a.json: missing list 'annotations'"):
        load_coco(path, ("car",))


def test_flip_and_zoom_move_boxes_with_the_pixels(tiny_coco):
    data = load_coco(tiny_coco / "annotations.json", ("car", "truck"))
    im = data.images[0]
    rgb = read_rgb(im.path)
    cfg = AugmentConfig(hflip=1.0, scale=(1.3, 1.3), brightness=0, contrast=0, saturation=0, dark=0)
    img, boxes, _labels, _ = augment(rgb, im, (256, 192), cfg, np.random.default_rng(0))
    assert len(boxes) >= 1
    for box in boxes:
        x1, y1, x2, y2 = (round(v) for v in box)
        inner = img[y1 + 2:y2 - 2, x1 + 2:x2 - 2]
        if inner.size:  # the rectangles are saturated red or blue, the road grey
            assert np.abs(inner[..., 0] - inner[..., 2]).mean() > 0.3
