"""The Cityscapes export read back with cityscapesscripts (its label table, file-name parser, instance reader and
pixel-level evaluation) and Pillow, against the records' own semantic and instance images (the hand-built records of
conftest.py: road below the horizon, sky above, cars A and C, van B, truck D, pedestrian P)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from exporters.base import ExportError, ExportOptions, get_exporter
from exporters.cityscapes_labels import CITYSCAPES_OF, LABELS
from exporters.splits import SplitSpec
from pipeline.core.classes import SemanticClass
from pipeline.core.png import write_png
from pipeline.core.record import DatasetRecord, camera_path
from tests.exporters.synthetic_record import build_record

cs_labels = pytest.importorskip("cityscapesscripts.helpers.labels")
SPLITS = SplitSpec.parse("val=urban:2,train=*")


@pytest.fixture(scope="module")
def cs_out(tmp_path_factory, records) -> Path:
    out = tmp_path_factory.mktemp("cityscapes") / "cityscapes"
    get_exporter("cityscapes").export(records, out, ExportOptions(splits=SPLITS))
    return out


def _png(path: Path) -> tuple[np.ndarray, str]:
    with Image.open(path) as image:
        return np.array(image), image.mode


def test_label_table_is_cityscapesscripts():
    theirs = [tuple(label) for label in cs_labels.labels if label.id >= 0]
    ours = [(x.name, x.id, x.train_id, x.category, x.category_id, x.has_instances, x.ignore_in_eval, x.color)
            for x in LABELS]
    assert ours == theirs
    assert set(CITYSCAPES_OF) == set(SemanticClass)  # every class the renderer can write has a label


def test_layout_and_file_names_parse(cs_out, records):
    from cityscapesscripts.helpers.csHelpers import getCoreImageFileName, getCsFileInfo

    cities = {"train": ["highway-s1-morning", "highway-s1-night"], "val": ["urban-s2-morning"]}
    for split, names in cities.items():
        assert sorted(p.name for p in (cs_out / "gtFine" / split).iterdir()) == names
        assert sorted(p.name for p in (cs_out / "leftImg8bit" / split).iterdir()) == names
    images = sorted((cs_out / "leftImg8bit").rglob("*.png"))
    assert len(images) == 6  # 3 records x 2 frames
    for image in images:
        info = getCsFileInfo(str(image))
        assert (info.city, info.sequenceNb, info.type, info.type2, info.ext) == (
            image.parent.name, "000000", "leftImg8bit", "", "png")
        assert info.frameNb in ("000010", "000011")  # the record's frame numbers
        gt = cs_out / "gtFine" / image.parent.parent.name / image.parent.name
        for kind in ("labelIds", "instanceIds", "color"):
            name = gt / f"{getCoreImageFileName(str(image))}_gtFine_{kind}.png"
            assert getCsFileInfo(str(name))[3:] == ("gtFine", kind, "png")
    record = DatasetRecord(records[0])
    first = cs_out / "leftImg8bit" / "train" / "highway-s1-morning" / "highway-s1-morning_000000_000010_leftImg8bit.png"
    assert first.read_bytes() == record.image_path("front", "rgb", 10).read_bytes()
    mapping = (cs_out / "mapping.txt").read_text().splitlines()
    assert mapping[0] == "train highway-s1-morning_000000_000010 highway 1 morning 10 1.000000"
    assert len(mapping) == 6


def test_label_ids_and_colours_closed_form(cs_out, morning):
    record = DatasetRecord(morning)
    gt = cs_out / "gtFine" / "train" / "highway-s1-morning"
    for frame in (10, 11):
        semantic = record.semantic("front", frame)
        ids, mode = _png(gt / f"highway-s1-morning_000000_{frame:06d}_gtFine_labelIds.png")
        assert mode == "L" and ids.shape == semantic.shape
        expected = {SemanticClass.NONE: 23, SemanticClass.ROAD: 7, SemanticClass.CAR: 26, SemanticClass.VAN: 26,
                    SemanticClass.TRUCK: 27, SemanticClass.PEDESTRIAN: 24}  # sky, road, car, car, truck, person
        assert set(np.unique(semantic)) == {c.value for c in expected}
        for cls, label_id in expected.items():
            assert np.all(ids[semantic == cls.value] == label_id), cls
        color, mode = _png(gt / f"highway-s1-morning_000000_{frame:06d}_gtFine_color.png")
        assert mode == "RGBA" and np.all(color[..., 3] == 255)
        for label_id in np.unique(ids):
            assert np.all(color[ids == label_id, :3] == cs_labels.id2label[int(label_id)].color)


def test_instance_ids_round_trip_to_the_record(cs_out, morning):
    from cityscapesscripts.evaluation.instances2dict import instances2dict

    record = DatasetRecord(morning)
    gt = cs_out / "gtFine" / "train" / "highway-s1-morning"
    table = [line.split() for line in (cs_out / "instances.txt").read_text().splitlines()]
    for frame in (10, 11):
        name = f"highway-s1-morning_000000_{frame:06d}"
        path = gt / f"{name}_gtFine_instanceIds.png"
        inst, mode = _png(path)
        labels, _ = _png(gt / f"{name}_gtFine_labelIds.png")
        tracks = record.instance("front", frame)
        theirs = next(iter(instances2dict([str(path)]).values()))
        assert mode == "I;16"
        # cars A (track 3) and van B (4) are car 0 and car 1 in track order; truck D (9) and pedestrian P (12)
        assert [(i["instID"], i["pixelCount"]) for i in theirs["car"]] == [
            (26000, int((tracks == 3).sum())), (26001, int((tracks == 4).sum()))]
        assert [i["instID"] for i in theirs["truck"]] == [27000] and [i["instID"] for i in theirs["person"]] == [24000]
        rows = {int(code): (int(track), cls) for split, image, code, track, cls in table if image == name}
        assert rows == {24000: (12, "pedestrian"), 26000: (3, "car"), 26001: (4, "van"), 27000: (9, "truck")}
        for code, (track, _) in rows.items():
            np.testing.assert_array_equal(inst == code, tracks == track)
        stuff = tracks == 0
        np.testing.assert_array_equal(inst[stuff], labels[stuff])  # no instance: the label id


def test_ground_truth_as_prediction_scores_one(cs_out, tmp_path):
    from evaluation.segmentation import evaluate_segmentation

    pred = tmp_path / "pred"
    pred.mkdir()
    for gt in (cs_out / "gtFine").rglob("*_gtFine_labelIds.png"):
        shutil.copy(gt, pred / gt.name.replace("_gtFine_labelIds", "_pred"))
    metrics = evaluate_segmentation(cs_out, pred)
    assert metrics["images"] == 6 and metrics["mIoU"] == metrics["iIoU"] == 1.0
    present = {name for name, c in metrics["classes"].items() if c["IoU"] is not None}
    assert present == {"road", "sky", "car", "truck", "person"}
    assert all(metrics["classes"][n]["IoU"] == 1.0 for n in present)


def test_unmapped_semantic_value_is_refused_naming_the_file(tmp_path, morning):
    root = tmp_path / "bad"
    shutil.copytree(morning, root)
    path = camera_path(root, "front", "semantic", 11)
    semantic = DatasetRecord(root).semantic("front", 11)
    semantic[0, :3] = 15  # not a SemanticClass
    write_png(path, semantic)
    with pytest.raises(ExportError, match=rf"{path} \(frame 11, camera front\): semantic value\(s\) \[15\]"):
        get_exporter("cityscapes").export([root], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_records_whose_cities_collide_are_refused(tmp_path):
    a = build_record(tmp_path / "a", scenario="high_way", seed=1)
    b = build_record(tmp_path / "b", scenario="high.way", seed=1)
    with pytest.raises(ExportError, match="both Cityscapes city 'high-way-s1-morning'"):
        get_exporter("cityscapes").export([a, b], tmp_path / "out")


def test_cli_refuses_the_object_filter(tmp_path, morning, capsys):
    from pipeline.stages.cli import main

    assert main(["export", "--dataset", str(morning), "--format", "cityscapes", "--min-visible-px", "5", "--out",
                 str(tmp_path / "out")]) == 2
    assert "--min-visible-px applies to --format" in capsys.readouterr().err
    assert main(["export", "--dataset", str(morning), "--format", "cityscapes", "--camera", "front", "--no-progress",
                 "--out", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "meta.json").is_file()
