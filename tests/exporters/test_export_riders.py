"""A rider (the person on a bicycle or motorcycle: a camera label row of class ``rider``, its pixels those of its
cycle whose semantic class is RIDER) in every export, read back by the format's own reader: COCO and YOLO write a
person (its mask the cycle's pixels that show the rider) and the cycle alone (its box and mask without the rider, as
COCO's annotators box a bicycle), MOT a person on a vehicle (2) beside the bicycle alone, Cityscapes a ``rider``
instance apart from the bicycle; KITTI and nuScenes, whose cycle box holds its rider, leave its row out and count it.

The record is the exporters' closed-form one (tests/exporters/synthetic_record.py) with car A (track 3, fully
visible) relabelled a bicycle whose upper half of pixels is its rider's, as the render labels one: the cycle's row
gives its boxes without the rider (``cycle_*``: the lower half's pixels, and the amodal box's part below the split)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from exporters.base import BoxMode, ExportOptions, get_exporter
from exporters.cityscapes_labels import BY_NAME
from exporters.mot import MOT_CLASS
from exporters.nuscenes_tables import VERSION
from pipeline.core.classes import RIDER, RIDER_TRACK_OFFSET, ObjectClass, SemanticClass
from pipeline.core.png import write_png
from pipeline.core.record import DatasetRecord, camera_path
from pipeline.core.tables import read_parquet, write_parquet
from tests.exporters.synthetic_record import build_record

CYCLE = 3
RIDER_TRACK = CYCLE + RIDER_TRACK_OFFSET


@pytest.fixture(scope="module")
def record(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("riders") / "urban-3-morning"
    build_record(root, scenario="urban", seed=3, frames=3)
    rec = DatasetRecord(root)
    labels = read_parquet(root / "labels.parquet")
    mine = labels["track_id"] == CYCLE
    labels.loc[mine, ["cls", "category_id", "model"]] = [ObjectClass.BICYCLE.value, ObjectClass.BICYCLE.coco_id,
                                                         "bicycle_city"]
    riders = []
    for frame in sorted(set(labels["frame"])):
        instance = rec.instance("front", frame)
        semantic = rec.semantic("front", frame)
        own = instance == CYCLE
        rows = np.nonzero(own)[0]
        split = (rows.min() + rows.max() + 1) // 2
        upper = own & (np.arange(own.shape[0])[:, None] < split)
        semantic = np.where(own, SemanticClass.BICYCLE, semantic)
        semantic[upper] = SemanticClass.RIDER
        write_png(camera_path(root, "front", "semantic", frame), semantic.astype(np.uint8))
        at = mine & (labels["frame"] == frame) & (labels["sensor"] == "front")
        ys, xs = np.nonzero(own & ~upper)
        labels.loc[at, ["cycle_x1", "cycle_y1", "cycle_x2", "cycle_y2"]] = [xs.min(), ys.min(), xs.max() + 1,
                                                                            ys.max() + 1]
        amodal = labels.loc[at, ["amodal_x1", "amodal_y1", "amodal_x2", "amodal_y2"]].to_numpy(float)[0]
        labels.loc[at, ["cycle_amodal_x1", "cycle_amodal_y1", "cycle_amodal_x2", "cycle_amodal_y2"]] = [
            amodal[0], float(split), amodal[2], amodal[3]]
        row = labels[at].copy()
        row[[f"cycle_{k}" for k in ("x1", "y1", "x2", "y2")]] = np.nan
        row[[f"cycle_amodal_{k}" for k in ("x1", "y1", "x2", "y2")]] = np.nan
        ys, xs = np.nonzero(upper)
        row[["track_id", "cls", "category_id", "person"]] = [RIDER_TRACK, RIDER, 1, "adult"]
        row[["x1", "y1", "x2", "y2"]] = [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]
        row[["visible_px", "unoccluded_px"]] = int(upper.sum())
        riders.append(row)
    import pandas as pd

    labels = pd.concat([labels, *riders]).sort_values(["frame", "sensor", "track_id"], kind="stable")
    write_parquet(labels.astype(labels.dtypes.to_dict()), root / "labels.parquet")
    return root


def _export(fmt: str, record: Path, out: Path) -> dict:
    return get_exporter(fmt).export([record], out, ExportOptions())


def test_coco_writes_the_rider_as_a_person_with_its_own_mask(record, tmp_path):
    from pycocotools import mask as mask_utils

    report = _export("coco", record, tmp_path / "c")
    data = json.loads((tmp_path / "c" / "annotations.json").read_text())
    riders = [a for a in data["annotations"] if a["track_id"] == RIDER_TRACK]
    cycles = [a for a in data["annotations"] if a["track_id"] == CYCLE]
    assert len(riders) == len(cycles) == 3
    rec = DatasetRecord(record)
    frames = {im["id"]: int(im["frame"]) for im in data["images"]}
    for rider, cycle in zip(riders, cycles, strict=True):
        assert (rider["category_id"], rider["subclass"], rider["person"]) == (1, "rider", "adult")
        assert cycle["category_id"] == 2 and cycle["model"] == rider["model"] == "bicycle_city"
        frame = frames[rider["image_id"]]
        upper = (rec.instance("front", frame) == CYCLE) & (rec.semantic("front", frame) == SemanticClass.RIDER)
        np.testing.assert_array_equal(mask_utils.decode(rider["segmentation"]).astype(bool), upper)
        lower = (rec.instance("front", frame) == CYCLE) & ~upper
        np.testing.assert_array_equal(mask_utils.decode(cycle["segmentation"]).astype(bool), lower)
        assert rider["area"] == upper.sum() and cycle["area"] == lower.sum()
        for ann, mask in ((rider, upper), (cycle, lower)):
            ys, xs = np.nonzero(mask)
            assert ann["bbox"] == [float(xs.min()), float(ys.min()), float(xs.max() + 1 - xs.min()),
                                   float(ys.max() + 1 - ys.min())]
        row = rec.labels[(rec.labels["track_id"] == CYCLE) & (rec.labels["frame"] == frame)].iloc[0]
        assert cycle["bbox_amodal"][1] == float(row["cycle_amodal_y1"]) > float(row["amodal_y1"])
    assert report["counts"]["objects"]["by_class"]["rider"]["kept"] == 3
    assert report["counts"]["objects"]["by_class"]["bicycle"]["kept"] == 3


def test_coco_amodal_boxes_the_cycle_without_its_rider(record, tmp_path):
    get_exporter("coco").export([record], tmp_path / "c", ExportOptions(box=BoxMode.AMODAL))
    data = json.loads((tmp_path / "c" / "annotations.json").read_text())
    labels = DatasetRecord(record).labels
    for cycle in (a for a in data["annotations"] if a["track_id"] == CYCLE):
        row = labels[(labels["track_id"] == CYCLE) & (labels["sensor"] == "front")
                     & (labels["frame"] == data["images"][cycle["image_id"] - 1]["frame"])].iloc[0]
        x1, y1, x2, y2 = np.clip([float(row[f"cycle_amodal_{k}"]) for k in ("x1", "y1", "x2", "y2")], 0,
                                 [800, 600, 800, 600])
        assert cycle["bbox"] == [round(x1, 4), round(y1, 4), round(x2 - x1, 4), round(y2 - y1, 4)]
        assert y1 > float(row["amodal_clip_y1"])


def test_coco_hides_a_cycle_of_which_only_its_rider_shows(record, tmp_path):
    root = tmp_path / "urban-3-morning"
    import shutil

    shutil.copytree(record, root)
    labels = read_parquet(root / "labels.parquet")
    labels.loc[labels["track_id"] == CYCLE, ["cycle_x1", "cycle_y1", "cycle_x2", "cycle_y2"]] = np.nan
    write_parquet(labels, root / "labels.parquet")
    report = _export("coco", root, tmp_path / "c")
    data = json.loads((tmp_path / "c" / "annotations.json").read_text())
    assert not [a for a in data["annotations"] if a["track_id"] == CYCLE]
    assert report["counts"]["objects"]["by_class"]["bicycle"]["hidden"] == 3
    kitti = _export("kitti", root, tmp_path / "k")  # KITTI's Cyclist holds its rider: still there
    assert kitti["counts"]["objects"]["by_class"]["bicycle"]["kept"] == 3


def test_yolo_writes_a_person_line(record, tmp_path):
    _export("yolo", record, tmp_path / "y")
    names = (tmp_path / "y" / "data.yaml").read_text()
    assert "person" in names
    lines = [line.split() for f in sorted((tmp_path / "y").rglob("labels/**/*.txt")) for line in
             f.read_text().splitlines()]
    person = np.array([[float(v) for v in r[1:5]] for r in lines if r[0] == "0"])  # COCO's person: class 0 here
    labels = DatasetRecord(record).labels
    riders = labels[labels["track_id"] == RIDER_TRACK][["x1", "y1", "x2", "y2"]].to_numpy(float) / [800, 600, 800, 600]
    centre = np.column_stack([(riders[:, 0] + riders[:, 2]) / 2, (riders[:, 1] + riders[:, 3]) / 2])
    for c in centre:  # each rider's box is a person line
        assert np.abs(person[:, :2] - c).max(axis=1).min() < 1e-5
    bicycle = np.array([[float(v) for v in r[1:5]] for r in lines if r[0] == "1"])  # COCO's bicycle: class 1
    alone = labels[labels["track_id"] == CYCLE][["cycle_x1", "cycle_y1", "cycle_x2", "cycle_y2"]].to_numpy(float)
    alone = alone[np.isfinite(alone).all(axis=1)] / [800, 600, 800, 600]
    expected = np.column_stack([(alone[:, 0] + alone[:, 2]) / 2, (alone[:, 1] + alone[:, 3]) / 2,
                                alone[:, 2] - alone[:, 0], alone[:, 3] - alone[:, 1]])
    assert len(bicycle) == len(expected) == 3
    np.testing.assert_allclose(np.sort(bicycle, axis=0), np.sort(expected, axis=0), atol=1e-5)


def test_kitti_leaves_the_rider_in_its_cyclist_and_counts_it(record, tmp_path):
    report = _export("kitti", record, tmp_path / "k")
    rows = [line.split() for f in sorted((tmp_path / "k").rglob("label_2/*.txt"))
            for line in f.read_text().splitlines()]
    assert sum(r[0] == "Cyclist" for r in rows) == 3 and sum(r[0] == "Pedestrian" for r in rows) <= 3
    labels = DatasetRecord(record).labels
    whole = labels[(labels["track_id"] == CYCLE) & (labels["sensor"] == "front")][["x1", "y1", "x2", "y2"]]
    boxes = np.array([[float(v) for v in r[4:8]] for r in rows if r[0] == "Cyclist"])
    np.testing.assert_allclose(np.sort(boxes, axis=0), np.sort(whole.to_numpy(float), axis=0), atol=0.01)
    assert report["counts"]["objects"]["by_class"]["rider"]["in_cycle"] == 3
    assert report["counts"]["objects"]["total"]["in_cycle"] == 3


def test_mot_writes_a_person_on_a_vehicle(record, tmp_path):
    _export("mot", record, tmp_path / "m")
    gt = [line.split(",") for f in sorted((tmp_path / "m").rglob("gt/gt.txt")) for line in f.read_text().splitlines()]
    mine = [r for r in gt if int(r[1]) == RIDER_TRACK]
    assert len(mine) == 3 and {int(r[7]) for r in mine} == {MOT_CLASS["rider"]} == {2}
    assert {int(r[7]) for r in gt if int(r[1]) == CYCLE} == {4}
    labels = DatasetRecord(record).labels
    alone = labels[(labels["track_id"] == CYCLE) & (labels["sensor"] == "front")]
    expected = np.column_stack([alone["cycle_x1"], alone["cycle_y1"], alone["cycle_x2"] - alone["cycle_x1"],
                                alone["cycle_y2"] - alone["cycle_y1"]]).astype(float)
    got = np.array([[float(v) for v in r[2:6]] for r in gt if int(r[1]) == CYCLE])
    np.testing.assert_allclose(np.sort(got, axis=0), np.sort(expected, axis=0), atol=0.01)


def test_nuscenes_boxes_the_rider_with_its_cycle(record, tmp_path):
    pytest.importorskip("nuscenes")
    from nuscenes.nuscenes import NuScenes

    report = _export("nuscenes", record, tmp_path / "n")
    nusc = NuScenes(version=VERSION, dataroot=str(tmp_path / "n"), verbose=False)
    cycles = [a for a in nusc.sample_annotation if a["category_name"] == "vehicle.bicycle"]
    assert len(cycles) == 3
    assert {nusc.get("attribute", a["attribute_tokens"][0])["name"] for a in cycles} == {"cycle.with_rider"}
    assert not any(a["category_name"].startswith("human") and a["size"] == [1.8, 4.5, 1.5]
                   for a in nusc.sample_annotation)
    assert report["counts"]["objects"]["total"]["riders_in_cycle_boxes"] == 3


def test_cityscapes_gives_the_rider_an_instance_of_its_own(record, tmp_path):
    import cv2

    _export("cityscapes", record, tmp_path / "s")
    label_files = sorted((tmp_path / "s").rglob("*_gtFine_labelIds.png"))
    instance_files = sorted((tmp_path / "s").rglob("*_gtFine_instanceIds.png"))
    assert len(label_files) == 3
    rec = DatasetRecord(record)
    for k, (lab_f, ins_f) in enumerate(zip(label_files, instance_files, strict=True)):
        frame = sorted(set(rec.labels["frame"]))[k]
        upper = (rec.instance("front", frame) == CYCLE) & (rec.semantic("front", frame) == SemanticClass.RIDER)
        labels = cv2.imread(str(lab_f), cv2.IMREAD_UNCHANGED)
        instances = cv2.imread(str(ins_f), cv2.IMREAD_UNCHANGED)
        assert (labels[upper] == BY_NAME["rider"].id).all()
        assert len(set(instances[upper].tolist())) == 1 and instances[upper][0] // 1000 == BY_NAME["rider"].id
        lower = (rec.instance("front", frame) == CYCLE) & ~upper
        assert (labels[lower] == BY_NAME["bicycle"].id).all() and instances[lower][0] // 1000 == BY_NAME["bicycle"].id
