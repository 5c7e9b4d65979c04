"""Exports of a real rendered record (``rendered`` in conftest.py: small SUMO run, 2 frames, default rig) read back by
independent readers."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest
from pycocotools.coco import COCO

from exporters.base import get_exporter
from pipeline.core.record import DatasetRecord
from tests.exporters.test_export_kitti import box_contains, parse_calib, parse_label

pytestmark = [pytest.mark.slow, pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")]


def test_coco_masks_of_a_rendered_record(rendered, tmp_path):
    out = tmp_path / "coco"
    get_exporter("coco").export([rendered], out)
    coco = COCO(str(out / "annotations.json"))
    record = DatasetRecord(rendered)
    assert len(coco.getImgIds()) == 2
    for ann in coco.loadAnns(coco.getAnnIds()):
        image = coco.loadImgs(ann["image_id"])[0]
        ours = record.instance(image["camera"], image["frame"]) == ann["track_id"]
        mask = coco.annToMask(ann).astype(bool)
        np.testing.assert_array_equal(mask, ours)
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        assert ann["bbox"] == [cols[0], rows[0], cols[-1] + 1 - cols[0], rows[-1] + 1 - rows[0]]


def test_kitti_boxes_hold_their_lidar_points(rendered, tmp_path):
    out = tmp_path / "kitti"
    get_exporter("kitti").export([rendered], out)
    record = DatasetRecord(rendered)
    mapping = [line.split() for line in (out / "mapping.txt").read_text().splitlines()]
    checked = 0
    for stem, *_, frame, _, _ in mapping:
        calib = parse_calib(out / "training" / "calib" / f"{stem}.txt")
        velo = np.fromfile(out / "training" / "velodyne" / f"{stem}.bin", dtype=np.float32).reshape(-1, 4)
        ids = record.points("top", int(frame))["instance_id"].to_numpy()
        cam = (calib["R0_rect"] @ calib["Tr_velo_to_cam"] @ np.hstack([velo[:, :3], np.ones((len(velo), 1))]).T).T
        for obj in parse_label(out / "training" / "label_2" / f"{stem}.txt"):
            if obj.type == "DontCare":
                continue
            inside = box_contains(obj, cam, margin=0.1)  # range noise 2 cm, 2-decimal labels
            hits = Counter(ids[inside & (ids > 0)])
            if not hits:
                continue  # no LiDAR return on this object
            track, n = hits.most_common(1)[0]
            assert n == (ids == track).sum(), (stem, obj)  # all the object's points are in its box
            checked += 1
    assert checked > 0


@pytest.mark.parametrize("fmt", ["yolo", "mcap", "rosbag2"])
def test_other_formats_export_a_rendered_record(rendered, tmp_path, fmt):
    out = tmp_path / ("x.mcap" if fmt == "mcap" else "x")
    description = get_exporter(fmt).export([rendered], out)
    assert description["counts"]["objects"]["total"]["kept"] > 0
    assert json.loads(json.dumps(description))["records"][0]["frames"] == 2


def test_cityscapes_of_a_rendered_record(rendered, tmp_path):
    """Every semantic class the renderer writes has its Cityscapes label; instances are the record's tracks; the
    ground truth scores IoU 1 in cityscapesscripts' evaluation."""
    pytest.importorskip("cityscapesscripts")
    from PIL import Image

    from evaluation.segmentation import evaluate_segmentation
    from exporters.cityscapes_labels import BY_NAME, CITYSCAPES_OF
    from pipeline.core.classes import SemanticClass

    out = tmp_path / "cityscapes"
    get_exporter("cityscapes").export([rendered], out)
    record = DatasetRecord(rendered)
    camera = record.info.cameras[0].name
    tracks = {(line.split()[1], int(line.split()[2])): int(line.split()[3])
              for line in (out / "instances.txt").read_text().splitlines()}
    seen = set()
    for labels_png in sorted(out.rglob("*_gtFine_labelIds.png")):
        frame = int(labels_png.name.split("_")[2])
        semantic, instance = record.semantic(camera, frame), record.instance(camera, frame)
        labels = np.array(Image.open(labels_png))
        codes = np.array(Image.open(str(labels_png).replace("labelIds", "instanceIds")))
        for value in np.unique(semantic):
            cls = SemanticClass(int(value))
            seen.add(cls)
            assert np.all(labels[semantic == value] == BY_NAME[CITYSCAPES_OF[cls]].id), cls
        stem = labels_png.name[: -len("_gtFine_labelIds.png")]
        for code in np.unique(codes[codes >= 1000]):
            np.testing.assert_array_equal(codes == code, instance == tracks[(stem, int(code))])
    assert {SemanticClass.ROAD, SemanticClass.CAR} <= seen
    pred = tmp_path / "pred"
    pred.mkdir()
    for labels_png in out.rglob("*_gtFine_labelIds.png"):
        (pred / labels_png.name.replace("_gtFine_labelIds", "_pred")).write_bytes(labels_png.read_bytes())
    metrics = evaluate_segmentation(out, pred)
    assert metrics["mIoU"] == 1.0 and metrics["iIoU"] == 1.0
