"""YOLO export read per the Ultralytics dataset format: data.yaml, images/<split>, labels/<split> pairs."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml

from exporters.base import get_exporter
from pipeline.core.record import DatasetRecord


def test_ultralytics_layout_and_normalised_boxes(tmp_path, morning):
    out = tmp_path / "yolo"
    get_exporter("yolo").export([morning], out)
    data = yaml.safe_load((out / "data.yaml").read_text())
    assert "path" not in data and data["train"] == data["val"] == "images/train"
    # COCO-trained YOLO models' class indices (bus 5, truck 7), so they score the export without remapping
    assert data["names"] == {0: "person", 1: "bicycle", 2: "car", 3: "motorcycle", 4: "airplane", 5: "bus",
                             6: "train", 7: "truck"}
    assert data["nc"] == 8
    images = sorted(p.stem for p in (out / "images" / "train").iterdir())
    labels = sorted(p.stem for p in (out / "labels" / "train").iterdir())
    assert images == labels == ["highway_s1_morning_front_000010", "highway_s1_morning_front_000011"]
    record = DatasetRecord(morning).labels
    rows = record[(record.frame == 10) & (record.sensor == "front") & (record.visible_px >= 20)].sort_values("track_id")
    lines = np.loadtxt(out / "labels" / "train" / "highway_s1_morning_front_000010.txt", ndmin=2)
    assert lines[:, 0].tolist() == [2, 2, 7]  # car, van (as car), truck; the 16-pixel pedestrian is dropped
    x1, y1, x2, y2 = (rows[c].to_numpy(dtype=float) for c in ("x1", "y1", "x2", "y2"))
    expected = np.stack([(x1 + x2) / 1600, (y1 + y2) / 1200, (x2 - x1) / 800, (y2 - y1) / 600], axis=1)
    np.testing.assert_allclose(lines[:, 1:], expected, atol=1e-6)
    assert np.all((lines[:, 1:] >= 0) & (lines[:, 1:] <= 1))
    frames = pd.read_csv(out / "images.csv")
    assert frames.to_dict("records") == [
        {"image": f"images/train/highway_s1_morning_front_{f:06d}.png", "split": "train", "scenario": "highway",
         "seed": 1, "condition": "morning", "camera": "front", "frame": f, "timestamp_s": t}
        for f, t in ((10, 1.0), (11, 1.1))]
    assert all((out / p).is_file() for p in frames["image"])


def test_splits_become_folders(tmp_path, records):
    from exporters.base import ExportOptions
    from exporters.splits import SplitSpec

    out = tmp_path / "yolo"
    get_exporter("yolo").export(records, out, ExportOptions(splits=SplitSpec.parse("train=highway:1,test=urban:2")))
    data = yaml.safe_load((out / "data.yaml").read_text())
    assert (data["train"], data["test"], data["val"]) == ("images/train", "images/test", "images/train")
    assert len(list((out / "images" / "train").iterdir())) == 4
    assert len(list((out / "labels" / "test").iterdir())) == 2


@pytest.mark.parametrize("fmt", ["coco", "yolo"])
def test_copy_when_links_are_off(tmp_path, morning, fmt):
    from exporters.base import ExportOptions

    desc = get_exporter(fmt).export([morning], tmp_path / "out", ExportOptions(link_images=False))
    assert desc["counts"]["images_copied"] == 2 and desc["counts"]["images_linked"] == 0
