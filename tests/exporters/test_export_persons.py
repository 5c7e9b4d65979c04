"""Who a pedestrian is (labels.parquet ``person``) in the exports: nuScenes' finer person categories, read back by
the devkit (a child human.pedestrian.child with a pedestrian's attribute, a wheelchair user human.pedestrian.wheelchair
without one, as its strollers; the devkit's detection evaluation counts the child a pedestrian and leaves the
wheelchair out), KITTI's Person_sitting for a wheelchair user, COCO's extra fields, and a clear error for a value
outside the vocabulary.

The record is the exporters' closed-form one (tests/exporters/synthetic_record.py) with the far pedestrian P
(track 12) a child and car A (track 3) relabelled a pedestrian in a wheelchair."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from exporters.base import ExportError, ExportOptions, get_exporter
from exporters.nuscenes_tables import VERSION
from pipeline.core.classes import ObjectClass, Person
from pipeline.core.tables import read_parquet, write_parquet
from tests.exporters.synthetic_record import build_record

CHILD, WHEELCHAIR = 12, 3


@pytest.fixture(scope="module")
def record(tmp_path_factory) -> Path:
    root = build_record(tmp_path_factory.mktemp("persons") / "urban-3-morning", scenario="urban", seed=3, frames=3)
    labels = read_parquet(root / "labels.parquet")
    labels.loc[labels["track_id"] == CHILD, "person"] = Person.CHILD.value
    mine = labels["track_id"] == WHEELCHAIR
    labels.loc[mine, ["cls", "category_id", "person"]] = [ObjectClass.PEDESTRIAN.value, ObjectClass.PEDESTRIAN.coco_id,
                                                          Person.WHEELCHAIR_USER.value]
    write_parquet(labels, root / "labels.parquet")
    return root


def _export(fmt: str, record: Path, out: Path) -> dict:
    return get_exporter(fmt).export([record], out, ExportOptions())


def test_nuscenes_devkit_reads_a_child_and_a_wheelchair(record, tmp_path):
    pytest.importorskip("nuscenes")
    from nuscenes.eval.detection.utils import category_to_detection_name
    from nuscenes.nuscenes import NuScenes

    report = _export("nuscenes", record, tmp_path / "n")
    nusc = NuScenes(version=VERSION, dataroot=str(tmp_path / "n"), verbose=False)
    by_track = {}
    for inst in nusc.instance:
        ann = nusc.get("sample_annotation", inst["first_annotation_token"])
        by_track.setdefault(ann["category_name"], []).append(inst["nbr_annotations"])
    anns = {name: [a for a in nusc.sample_annotation if a["category_name"] == name] for name in by_track}
    assert len(anns["human.pedestrian.child"]) == 3 and len(anns["human.pedestrian.wheelchair"]) == 3
    assert "human.pedestrian.adult" not in anns  # the record's only pedestrians are these two
    attrs = {nusc.get("attribute", t)["name"] for a in anns["human.pedestrian.child"] for t in a["attribute_tokens"]}
    assert attrs <= {"pedestrian.moving", "pedestrian.standing"} and all(
        len(a["attribute_tokens"]) == 1 for a in anns["human.pedestrian.child"])
    assert all(a["attribute_tokens"] == [] for a in anns["human.pedestrian.wheelchair"])
    assert category_to_detection_name("human.pedestrian.child") == "pedestrian"
    assert category_to_detection_name("human.pedestrian.wheelchair") is None  # left out of detection, as in nuScenes
    names = {c["name"] for c in nusc.category}
    assert {"human.pedestrian.child", "human.pedestrian.wheelchair", "human.pedestrian.adult"} <= names
    by_class = report["counts"]["annotations_by_class"]
    assert by_class["human.pedestrian.child"] == 3 and by_class["human.pedestrian.wheelchair"] == 3


def test_coco_annotations_carry_model_and_person(record, tmp_path):
    _export("coco", record, tmp_path / "c")
    anns = json.loads((tmp_path / "c" / "annotations.json").read_text())["annotations"]
    person = {a["track_id"]: a["person"] for a in anns}
    assert person[WHEELCHAIR] == "wheelchair_user" and person[4] == "" and person[9] == ""
    assert all(a["model"] == "box" for a in anns)
    assert {a["category_id"] for a in anns if a["track_id"] == WHEELCHAIR} == {1}


def test_a_person_outside_the_vocabulary_fails_naming_the_field(record, tmp_path):
    bad = tmp_path / "urban-3-morning"
    shutil.copytree(record, bad)
    labels = read_parquet(bad / "labels.parquet")
    labels.loc[labels["track_id"] == CHILD, "person"] = "toddler"
    write_parquet(labels, bad / "labels.parquet")
    with pytest.raises(ExportError, match=r"field person has values \['toddler'\]"):
        _export("nuscenes", bad, tmp_path / "n")
    assert not (tmp_path / "n").exists()


def test_kitti_writes_a_wheelchair_user_as_a_person_sitting(record, tmp_path):
    _export("kitti-tracking", record, tmp_path / "t")
    rows = [line.split() for f in sorted((tmp_path / "t").rglob("label_02/*.txt"))
            for line in f.read_text().splitlines()]
    kinds = {int(r[1]): r[2] for r in rows if r[2] != "DontCare"}
    assert kinds[WHEELCHAIR] == "Person_sitting" and sum(int(r[1]) == WHEELCHAIR for r in rows) == 3
    assert kinds.get(CHILD, "Pedestrian") == "Pedestrian"  # a child stays a pedestrian
    _export("kitti", record, tmp_path / "k")
    objects = [line.split()[0] for f in sorted((tmp_path / "k").rglob("label_2/*.txt")) for line in
               f.read_text().splitlines()]
    assert objects.count("Person_sitting") == 3
