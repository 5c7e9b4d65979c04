"""A stroller (a pram pushed by a pedestrian, its own object: pipeline.world.prams) in every export, read back by the
format's own reader: COCO and YOLO have no category for it and leave it out, counted; KITTI writes it as Misc, MOT
as a non-motorized vehicle (6), nuScenes as human.pedestrian.stroller without attributes, Cityscapes as dynamic.

The record is the exporters' closed-form one (tests/exporters/synthetic_record.py) with car A (track 3, fully
visible) relabelled a stroller, as the render labels one: class ``stroller``, category id 0."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from exporters.base import ExportOptions, get_exporter
from exporters.cityscapes_labels import BY_NAME, LABEL_ID
from exporters.mot import MOT_CLASS
from exporters.nuscenes_tables import VERSION
from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.tables import read_parquet, write_parquet
from tests.exporters.synthetic_record import build_record

STROLLER_TRACK = 3


@pytest.fixture(scope="module")
def plain(tmp_path_factory) -> Path:
    return build_record(tmp_path_factory.mktemp("plain") / "urban-3-morning", scenario="urban", seed=3, frames=3)


@pytest.fixture(scope="module")
def with_stroller(tmp_path_factory, plain) -> Path:
    root = tmp_path_factory.mktemp("stroller") / "urban-3-morning"
    shutil.copytree(plain, root)
    labels = read_parquet(root / "labels.parquet")
    mine = labels["track_id"] == STROLLER_TRACK
    assert mine.sum() >= 6  # camera and LiDAR rows in each of the 3 frames
    labels.loc[mine, "cls"] = ObjectClass.STROLLER.value
    labels.loc[mine, "category_id"] = ObjectClass.STROLLER.coco_id
    write_parquet(labels, root / "labels.parquet")
    return root


def _export(fmt: str, record: Path, out: Path) -> dict:
    return get_exporter(fmt).export([record], out, ExportOptions())


def test_the_class_has_no_coco_category_and_its_own_semantic_value():
    assert ObjectClass.STROLLER.coco_id == 0
    assert ObjectClass.STROLLER.semantic is SemanticClass.STROLLER and SemanticClass.STROLLER.is_actor
    with pytest.raises(KeyError):
        ObjectClass.STROLLER.coco_name  # noqa: B018 -- COCO has no such category


def test_coco_leaves_the_stroller_out_and_counts_it(plain, with_stroller, tmp_path):
    before = _export("coco", plain, tmp_path / "a")
    after = _export("coco", with_stroller, tmp_path / "b")
    anns = {k: json.loads((tmp_path / k / "annotations.json").read_text())["annotations"] for k in "ab"}
    kept = [(a["image_id"], a["track_id"], a["bbox"]) for a in anns["a"] if a["track_id"] != STROLLER_TRACK]
    assert [(a["image_id"], a["track_id"], a["bbox"]) for a in anns["b"]] == kept
    assert len(kept) < len(anns["a"])  # car A was annotated in the plain record
    assert {a["category_id"] for a in anns["b"]} <= {c["id"] for c in
                                                     json.loads((tmp_path / "b" / "annotations.json").read_text())[
                                                         "categories"]}
    shown = before["counts"]["objects"]["by_class"]["car"]["kept"] - after["counts"]["objects"]["by_class"]["car"][
        "kept"]
    assert after["counts"]["objects"]["by_class"]["stroller"]["no_category"] == shown == 3
    assert after["counts"]["objects"]["total"]["no_category"] == 3
    assert before["counts"]["objects"]["total"]["no_category"] == 0


def test_yolo_writes_no_line_for_it(plain, with_stroller, tmp_path):
    _export("yolo", plain, tmp_path / "a")
    _export("yolo", with_stroller, tmp_path / "b")
    lines = {k: sorted(line for f in sorted((tmp_path / k).rglob("labels/**/*.txt")) for line in
                       f.read_text().splitlines()) for k in "ab"}
    assert len(lines["b"]) == len(lines["a"]) - 3
    assert set(lines["b"]) < set(lines["a"])


def test_kitti_writes_it_as_misc(with_stroller, tmp_path):
    _export("kitti", with_stroller, tmp_path / "k")
    rows = [line.split() for f in sorted((tmp_path / "k").rglob("label_2/*.txt"))
            for line in f.read_text().splitlines()]
    assert sum(r[0] == "Misc" for r in rows) == 3  # the synthetic record has no bus or motorcycle


def test_mot_writes_it_as_a_non_motorized_vehicle(with_stroller, tmp_path):
    _export("mot", with_stroller, tmp_path / "m")
    gt = [line.split(",") for f in sorted((tmp_path / "m").rglob("gt/gt.txt")) for line in f.read_text().splitlines()]
    mine = [r for r in gt if int(r[1]) == STROLLER_TRACK]
    assert len(mine) == 3 and {int(r[7]) for r in mine} == {MOT_CLASS["stroller"]} == {6}


def test_nuscenes_devkit_reads_it_as_a_stroller_without_attributes(with_stroller, tmp_path):
    pytest.importorskip("nuscenes")
    from nuscenes.nuscenes import NuScenes

    _export("nuscenes", with_stroller, tmp_path / "n")
    nusc = NuScenes(version=VERSION, dataroot=str(tmp_path / "n"), verbose=False)
    strollers = [a for a in nusc.sample_annotation if a["category_name"] == "human.pedestrian.stroller"]
    assert len(strollers) == 3
    assert all(a["attribute_tokens"] == [] for a in strollers)
    others = [a for a in nusc.sample_annotation if a["category_name"] != "human.pedestrian.stroller"]
    assert others and all(len(a["attribute_tokens"]) == 1 for a in others)
    size = np.array([s["size"] for s in strollers])  # width, length, height: car A's box, as relabelled
    np.testing.assert_allclose(size, [[1.8, 4.5, 1.5]] * 3)


def test_cityscapes_maps_it_to_dynamic():
    assert LABEL_ID[SemanticClass.STROLLER.value] == BY_NAME["dynamic"].id == 5
    assert LABEL_ID[SemanticClass.PEDESTRIAN.value] == BY_NAME["person"].id

