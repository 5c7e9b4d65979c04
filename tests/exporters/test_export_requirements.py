"""What each format needs from a record, refused by name when a record lacks it, never exported as nothing:
COCO and YOLO are camera images (a record without a camera is refused); KITTI needs a camera and a LiDAR; the
logs (MCAP, rosbag2) carry whatever sensors a record has, so a radar-only record is exported (and read back);
every format refuses a record without frames. Records are the synthetic ones, stripped of sensors on disk."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from exporters.base import ExportError, formats, get_exporter
from pipeline.core.record import FRAME_COLUMNS, RADAR_COLUMNS, RECORD_FILE, DatasetRecord, radar_path
from pipeline.core.tables import write_parquet
from pipeline.stages.cli import main as cli_main
from tests.exporters.synthetic_record import build_record

RADAR = {"name": "front_radar", "range_min_m": 0.5, "range_max_m": 150.0, "azimuth_fov_deg": 90.0,
         "elevation_fov_deg": 20.0, "range_resolution_m": 0.4, "azimuth_resolution_deg": 2.0,
         "velocity_resolution_mps": 0.5, "max_detections": 100, "cycle_hz": 10.0, "T_ego_sensor": np.eye(4).tolist()}


def cli(argv: list[str]) -> int:
    try:
        return cli_main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def strip(root: Path, *, cameras: bool = False, lidars: bool = False, radar: bool = False) -> Path:
    """Keep only the named sensors of a synthetic record (files, record.json entries, label rows); ``radar`` adds
    one radar with two detections a frame (label rows of its own)."""
    info = json.loads((root / RECORD_FILE).read_text())
    labels = DatasetRecord(root).labels
    frames = DatasetRecord(root).frames["frame"].tolist()
    keep = []
    for kind, folder, wanted in (("camera", "cameras", cameras), ("lidar", "lidars", lidars)):
        if wanted:
            keep.append(kind)
        else:
            info[folder] = []
            shutil.rmtree(root / folder)
    kept = labels[labels["sensor_type"].isin(keep)]
    if radar:
        info["radars"] = [RADAR]
        for frame in frames:
            path = radar_path(root, RADAR["name"], frame)
            path.parent.mkdir(parents=True, exist_ok=True)
            write_parquet(pd.DataFrame({
                "x_m": [10.0, 30.0], "y_m": [0.0, -8.0], "z_m": [0.0, -1.0], "range_m": [10.0, 31.1],
                "azimuth_rad": [0.0, -0.26], "elevation_rad": [0.0, -0.03], "radial_velocity_mps": -3.0,
                "radial_velocity_comp_mps": 1.0, "rcs_dbsm": 10.0, "snr_db": 20.0, "instance_id": [3, 0],
                "semantic": 20}).astype(RADAR_COLUMNS), path)
        rows = labels[labels["sensor_type"] == "lidar"].copy()
        rows["sensor"], rows["sensor_type"] = RADAR["name"], "radar"
        kept = pd.concat([kept, rows]).sort_values(["frame", "sensor", "track_id"], kind="stable")
        kept["radar_detections"] = np.where(kept["sensor_type"] == "radar", 1, 0).astype("int32")
    write_parquet(kept.reset_index(drop=True), root / "labels.parquet")
    (root / RECORD_FILE).write_text(json.dumps(info, sort_keys=True, indent=2))
    return root


@pytest.fixture(scope="module")
def radar_only(tmp_path_factory) -> Path:
    return strip(build_record(tmp_path_factory.mktemp("req") / "radar-5-noon", scenario="radar", seed=5,
                              condition="noon", ground_points=100), radar=True)


@pytest.fixture(scope="module")
def lidar_only(tmp_path_factory) -> Path:
    return strip(build_record(tmp_path_factory.mktemp("req") / "lidar-6-noon", scenario="lidar", seed=6,
                              condition="noon", ground_points=100), lidars=True)


@pytest.fixture(scope="module")
def camera_only(tmp_path_factory) -> Path:
    return strip(build_record(tmp_path_factory.mktemp("req") / "camera-7-noon", scenario="camera", seed=7,
                              condition="noon", ground_points=100), cameras=True)


@pytest.fixture(scope="module")
def no_frames(tmp_path_factory) -> Path:
    root = build_record(tmp_path_factory.mktemp("req") / "empty-8-noon", scenario="empty", seed=8, condition="noon",
                        ground_points=100)
    write_parquet(DatasetRecord(root).frames.iloc[:0].astype(FRAME_COLUMNS), root / "frames.parquet")
    write_parquet(DatasetRecord(root).labels.iloc[:0], root / "labels.parquet")
    return root


def out_path(tmp_path: Path, fmt: str) -> Path:
    return tmp_path / ("out.mcap" if get_exporter(fmt).writes_file else "out")


@pytest.mark.parametrize("fmt", ["coco", "yolo", "mot", "kitti-tracking", "kitti-depth", "cityscapes"])
def test_image_formats_refuse_a_record_without_a_camera_naming_it(tmp_path, radar_only, lidar_only, morning, fmt):
    for record, sensors in ((radar_only, r"cameras \[\], LiDARs \[\], radars \[front_radar\]"),
                            (lidar_only, r"cameras \[\], LiDARs \[top\], radars \[\]")):
        with pytest.raises(ExportError, match=rf"{record.name}: the record has no camera( \({sensors}\))?"):
            get_exporter(fmt).export([morning, record], out_path(tmp_path, fmt))
        assert not out_path(tmp_path, fmt).exists()  # the record with a camera is not exported alone either


@pytest.mark.parametrize(("record", "missing", "sensors"), [
    ("radar_only", "camera or LiDAR", r"cameras \[\], LiDARs \[\], radars \[front_radar\]"),
    ("lidar_only", "camera", r"cameras \[\], LiDARs \[top\], radars \[\]"),
    ("camera_only", "LiDAR", r"cameras \[front\], LiDARs \[\], radars \[\]"),
])
def test_kitti_refuses_a_record_without_camera_or_lidar_naming_it(tmp_path, request, record, missing, sensors):
    root = request.getfixturevalue(record)
    with pytest.raises(ExportError, match=rf"{root.name}: the record has no {missing} \({sensors}\); KITTI needs "
                                          r"a camera \(image_2\) and a LiDAR \(velodyne\)"):
        get_exporter("kitti").export([root], tmp_path / "kitti")
    assert not (tmp_path / "kitti").exists()


def test_coco_takes_a_camera_only_record(tmp_path, camera_only):
    from pycocotools.coco import COCO

    description = get_exporter("coco").export([camera_only], tmp_path / "coco")
    assert description["counts"]["images"] == 2
    assert len(COCO(str(tmp_path / "coco" / "annotations.json")).getImgIds()) == 2


def test_mcap_carries_a_radar_only_record(tmp_path, radar_only):
    from mcap.reader import make_reader

    get_exporter("mcap").export([radar_only], tmp_path / "r.mcap")
    with open(tmp_path / "r.mcap", "rb") as f:
        topics = [channel.topic for _, channel, _ in make_reader(f).iter_messages()]
    assert topics.count("/radar/front_radar/detections") == 2
    assert not any(t.startswith(("/camera/", "/lidar/")) for t in topics)


def test_rosbag2_carries_a_radar_only_record(tmp_path, radar_only):
    from rosbags.rosbag2 import Reader

    get_exporter("rosbag2").export([radar_only], tmp_path / "bag")
    with Reader(tmp_path / "bag") as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts["/radar/front_radar/scan"] == counts["/radar/front_radar/points"] == 2
    assert not any(t.startswith(("/camera/", "/lidar/")) for t in counts)


@pytest.mark.parametrize("fmt", formats())
def test_every_format_refuses_a_record_without_frames(tmp_path, morning, no_frames, fmt):
    with pytest.raises(ExportError, match=rf"{no_frames.name}: the record has no frames \(.*frames\.parquet has no "
                                          rf"rows\); a {fmt} export of it would be empty"):
        get_exporter(fmt).export([morning, no_frames], out_path(tmp_path, fmt))
    assert not out_path(tmp_path, fmt).exists()


def test_the_cli_refuses_a_coco_export_of_a_radar_only_record_in_one_line(tmp_path, radar_only, capsys):
    out = tmp_path / "coco"
    assert cli(["export", "--dataset", str(radar_only), "--format", "coco", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{radar_only}: the record has no camera" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_nuscenes_refuses_a_radar_only_record_naming_it(tmp_path, radar_only):
    with pytest.raises(ExportError, match=rf"{radar_only.name}: nuScenes needs a LiDAR"):
        get_exporter("nuscenes").export([radar_only], tmp_path / "nus")
    assert not (tmp_path / "nus").exists()
