"""nuScenes export, read back with the official nuscenes-devkit (the ``nuscenes`` extra).

The records are the hand-built ones (tests/exporters/synthetic_record.py): boxes at known poses in the ego frame, so
the devkit's boxes in each sensor frame have a closed form.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from exporters.base import ExportError, ExportOptions, get_exporter
from exporters.nuscenes_tables import VERSION, token
from exporters.splits import SplitSpec
from pipeline.core.geometry import R_CAMERA_FROM_BODY, rotation_z
from pipeline.core.record import RADAR_COLUMNS, RECORD_FILE, DatasetRecord, radar_path
from pipeline.core.tables import write_parquet
from tests.exporters.synthetic_record import CAMERA_MOUNT, LIDAR_MOUNT, OBJECTS, build_record, ego_boxes

pytest.importorskip("nuscenes")
from nuscenes.nuscenes import NuScenes
from nuscenes.utils.data_classes import LidarPointCloud, RadarPointCloud

RADAR_MOUNT = (2.0, 0.0, 0.5)


def add_radar(root: Path) -> Path:
    """Give a synthetic record a radar ``front_radar`` at :data:`RADAR_MOUNT`: per frame one detection at each
    object's box centre (radial velocity -3 m/s, compensated +1) and one clutter detection; radar label rows."""
    record = DatasetRecord(root)
    info = json.loads((root / RECORD_FILE).read_text())
    t = np.eye(4)
    t[:3, 3] = RADAR_MOUNT
    info["radars"] = [{"name": "front_radar", "range_min_m": 0.5, "range_max_m": 150.0, "azimuth_fov_deg": 90.0,
                       "elevation_fov_deg": 20.0, "range_resolution_m": 0.4, "azimuth_resolution_deg": 2.0,
                       "velocity_resolution_mps": 0.5, "max_detections": 100, "cycle_hz": 10.0,
                       "T_ego_sensor": t.tolist()}]
    labels = record.labels
    rows = []
    for frame in record.frames["frame"]:
        centres = ego_boxes(int(frame)).center - np.array(RADAR_MOUNT)
        xyz = np.vstack([centres, [[30.0, -8.0, -1.0]]])
        rng = np.linalg.norm(xyz, axis=1)
        scan = pd.DataFrame({
            "x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2], "range_m": rng,
            "azimuth_rad": np.arctan2(xyz[:, 1], xyz[:, 0]), "elevation_rad": np.arcsin(xyz[:, 2] / rng),
            "radial_velocity_mps": -3.0, "radial_velocity_comp_mps": 1.0, "rcs_dbsm": 10.0, "snr_db": 20.0,
            "instance_id": [o.track_id for o in OBJECTS] + [0], "semantic": 20}).astype(RADAR_COLUMNS)
        path = radar_path(root, "front_radar", int(frame))
        path.parent.mkdir(parents=True, exist_ok=True)
        write_parquet(scan, path)
        lidar_rows = labels[(labels["frame"] == frame) & (labels["sensor"] == "top")].copy()
        lidar_rows["sensor"], lidar_rows["sensor_type"] = "front_radar", "radar"
        rows.append(lidar_rows)
    labels = pd.concat([labels, *rows]).sort_values(["frame", "sensor", "track_id"], kind="stable")
    labels["radar_detections"] = np.where(labels["sensor_type"] == "radar", 1, 0).astype("int32")
    write_parquet(labels.reset_index(drop=True), root / "labels.parquet")
    (root / RECORD_FILE).write_text(json.dumps(info, sort_keys=True, indent=2))
    return root


@pytest.fixture(scope="module")
def radar_record(tmp_path_factory) -> Path:
    return add_radar(build_record(tmp_path_factory.mktemp("nus") / "radar-3-morning", scenario="radar", seed=3,
                                  frames=4))


@pytest.fixture(scope="module")
def export(tmp_path_factory, records, radar_record) -> Path:
    out = tmp_path_factory.mktemp("nuscenes") / "out"
    get_exporter("nuscenes").export([*records, radar_record], out,
                                    ExportOptions(splits=SplitSpec.parse("synval=urban:2,syntrain=*")))
    return out


@pytest.fixture(scope="module")
def nusc(export) -> NuScenes:
    return NuScenes(version=VERSION, dataroot=str(export), verbose=False)


def _sample(nusc: NuScenes, scene: str, index: int) -> dict:
    rec = next(s for s in nusc.scene if s["name"] == scene)
    sample = nusc.get("sample", rec["first_sample_token"])
    for _ in range(index):
        sample = nusc.get("sample", sample["next"])
    return sample


def test_devkit_loads_scenes_samples_and_splits(nusc, export):
    assert sorted(s["name"] for s in nusc.scene) == ["highway_s1_morning", "highway_s1_night", "radar_s3_morning",
                                                      "urban_s2_morning"]
    assert len(nusc.sample) == 2 + 2 + 2 + 4
    assert {s["channel"] for s in nusc.sensor} == {"CAM_FRONT", "LIDAR_TOP", "RADAR_FRONT"}
    sample = _sample(nusc, "radar_s3_morning", 1)
    assert set(sample["data"]) == {"CAM_FRONT", "LIDAR_TOP", "RADAR_FRONT"}
    assert len(sample["anns"]) == len(OBJECTS)
    splits = json.loads((export / VERSION / "splits.json").read_text())
    assert splits == {"all": sorted(s["name"] for s in nusc.scene), "synval": ["urban_s2_morning"],
                      "syntrain": ["highway_s1_morning", "highway_s1_night", "radar_s3_morning"]}
    ann = nusc.get("sample_annotation", sample["anns"][0])
    assert ann["category_name"] == "vehicle.car"
    assert nusc.get("attribute", ann["attribute_tokens"][0])["name"] == "vehicle.moving"


def test_boxes_in_the_sensor_frames_closed_form(nusc):
    sample = _sample(nusc, "radar_s3_morning", 2)
    boxes_ego = ego_boxes(12)  # the record's third frame
    tracks = {token("instance", "radar_s3_morning", o.track_id): i for i, o in enumerate(OBJECTS)}
    _, lidar_boxes, _ = nusc.get_sample_data(sample["data"]["LIDAR_TOP"])
    assert len(lidar_boxes) == len(OBJECTS)
    for box in lidar_boxes:
        i = tracks[nusc.get("sample_annotation", box.token)["instance_token"]]
        length, width, height = OBJECTS[i].size_m
        np.testing.assert_allclose(box.center, boxes_ego.center[i] - np.array(LIDAR_MOUNT), atol=1e-9)
        np.testing.assert_allclose(box.wlh, [width, length, height], atol=1e-12)
        np.testing.assert_allclose(box.rotation_matrix, rotation_z(OBJECTS[i].yaw_rel_rad), atol=1e-9)
    _, cam_boxes, intrinsic = nusc.get_sample_data(sample["data"]["CAM_FRONT"])
    np.testing.assert_allclose(intrinsic, [[400, 0, 400], [0, 400, 300], [0, 0, 1]])
    assert len(cam_boxes) >= 3  # those with a corner in the image (the devkit's BoxVisibility.ANY)
    for box in cam_boxes:
        i = tracks[nusc.get("sample_annotation", box.token)["instance_token"]]
        np.testing.assert_allclose(box.center, R_CAMERA_FROM_BODY @ (boxes_ego.center[i] - np.array(CAMERA_MOUNT)),
                                   atol=1e-9)
        np.testing.assert_allclose(box.rotation_matrix, R_CAMERA_FROM_BODY @ rotation_z(OBJECTS[i].yaw_rel_rad),
                                   atol=1e-9)


def test_velocities_from_the_tracks(nusc):
    sample = _sample(nusc, "radar_s3_morning", 1)
    ego_velocity = 10.0 * np.array([np.cos(0.6), np.sin(0.6)])  # seed 3: yaw 0.6, 10 m/s (synthetic_record)
    for ann_token in sample["anns"]:
        ann = nusc.get("sample_annotation", ann_token)
        i = next(i for i, o in enumerate(OBJECTS) if token("instance", "radar_s3_morning", o.track_id)
                 == ann["instance_token"])
        expected = ego_velocity * (1 + OBJECTS[i].speed_rel_mps / 10.0)  # relative speed along the ego's heading
        np.testing.assert_allclose(nusc.box_velocity(ann_token)[:2], expected, atol=1e-9)
        assert ann["num_radar_pts"] == 1


def test_lidar_and_radar_files(nusc, radar_record):
    sample = _sample(nusc, "radar_s3_morning", 0)
    path, _, _ = nusc.get_sample_data(sample["data"]["LIDAR_TOP"])
    assert path.endswith(".pcd.bin")
    raw = np.fromfile(path, dtype=np.float32).reshape(-1, 5)
    cloud = DatasetRecord(radar_record).points("top", 10)
    np.testing.assert_array_equal(raw[:, :3], cloud[["x_m", "y_m", "z_m"]].to_numpy(np.float32))
    np.testing.assert_allclose(raw[:, 3], cloud["intensity"].to_numpy() * 255, rtol=1e-6)
    np.testing.assert_array_equal(raw[:, 4], cloud["ring"].to_numpy())
    assert LidarPointCloud.from_file(path).points.shape == (4, len(cloud))
    path, _, _ = nusc.get_sample_data(sample["data"]["RADAR_FRONT"])
    radar = RadarPointCloud.from_file(path).points  # (18, N), the devkit's default filters
    assert radar.shape == (18, len(OBJECTS) + 1)
    centres = ego_boxes(10).center - np.array(RADAR_MOUNT)
    np.testing.assert_allclose(radar[:3, :len(OBJECTS)].T, centres, rtol=1e-6)
    direction = centres[:, :2] / np.linalg.norm(centres, axis=1)[:, None]
    np.testing.assert_allclose(radar[6:8, :len(OBJECTS)].T, -3.0 * direction, rtol=1e-5, atol=1e-6)  # vx, vy
    np.testing.assert_allclose(radar[8:10, :len(OBJECTS)].T, 1.0 * direction, rtol=1e-5, atol=1e-6)  # compensated
    np.testing.assert_array_equal(radar[3], 0)  # dyn_prop moving: |1 m/s| > the 0.5 m/s resolution
    np.testing.assert_array_equal(radar[5], 10.0)  # rcs


def test_render_sample_data_writes_an_image(nusc, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    sample = _sample(nusc, "highway_s1_morning", 0)
    out = tmp_path / "cam.png"
    nusc.render_sample_data(sample["data"]["CAM_FRONT"], out_path=str(out), verbose=False)
    lidar = tmp_path / "lidar.png"
    nusc.render_sample_data(sample["data"]["LIDAR_TOP"], out_path=str(lidar), underlay_map=False, verbose=False)
    assert out.stat().st_size > 10_000 and lidar.stat().st_size > 10_000


def test_same_bytes_whatever_the_order(records, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    get_exporter("nuscenes").export(records, a)
    get_exporter("nuscenes").export(list(reversed(records)), b)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for rel in files:
        if rel.name != "meta.json":
            assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel


def test_bad_class_fails_naming_the_file_and_nothing_is_written(tmp_path):
    root = build_record(tmp_path / "rec")
    labels = DatasetRecord(root).labels
    labels.loc[0, "cls"] = "tram"
    write_parquet(labels, root / "labels.parquet")
    out = tmp_path / "out"
    with pytest.raises(ExportError, match=r"rec: labels.parquet field cls has classes \['tram'\]"):
        get_exporter("nuscenes").export([root], out)
    assert not out.exists() and not list(tmp_path.glob(".out*"))


def test_reserved_split_name(records, tmp_path):
    with pytest.raises(ExportError, match="split name 'all' is reserved"):
        get_exporter("nuscenes").export(records, tmp_path / "out", ExportOptions(splits=SplitSpec.parse("all=1")))


def test_devkit_detection_eval_of_the_ground_truth_scores_one(nusc, export, tmp_path):
    """The devkit's DetectionEval on a custom split of splits.json, the ground truth (the devkit's own loader) as
    predictions: attributes, velocities and point counts meet its filters, so mAP and NDS are 1 on the classes with
    ground truth in range (the devkit counts a class without any as AP 0)."""
    from nuscenes.eval.common.config import config_factory
    from nuscenes.eval.common.loaders import get_samples_of_custom_split, load_gt_of_sample_tokens
    from nuscenes.eval.detection.data_classes import DetectionBox
    from nuscenes.eval.detection.evaluate import DetectionEval

    tokens = get_samples_of_custom_split("syntrain", nusc)
    assert len(tokens) == 2 + 2 + 4
    gt = load_gt_of_sample_tokens(nusc, tokens, DetectionBox)
    results = {t: [{"sample_token": t, "translation": list(b.translation), "size": list(b.size),
                    "rotation": list(b.rotation), "velocity": np.nan_to_num(b.velocity).tolist(),
                    "detection_name": b.detection_name, "detection_score": 1.0, "attribute_name": b.attribute_name}
                   for b in gt[t]] for t in tokens}
    path = tmp_path / "results.json"
    path.write_text(json.dumps({"meta": {"use_lidar": True}, "results": results}))
    evaluator = DetectionEval(nusc, config_factory("detection_cvpr_2019"), str(path), "syntrain",
                              output_dir=str(tmp_path / "eval"), verbose=False)
    evaluator.cfg.class_names = sorted({b.detection_name for b in evaluator.gt_boxes.all})
    assert evaluator.cfg.class_names == ["car", "truck"]
    metrics, _ = evaluator.evaluate()
    assert metrics.mean_ap == pytest.approx(1.0)
    assert metrics.nd_score == pytest.approx(1.0)


def test_radar_columns_are_the_radar_detections(radar_record):
    record = DatasetRecord(radar_record)
    columns = record.radar_columns("front_radar", 11)
    table = record.radar_detections("front_radar", 11)
    assert list(columns) == list(table.columns)
    for name, values in columns.items():
        np.testing.assert_array_equal(values, table[name].to_numpy())
        assert values.dtype == table[name].dtype
    with pytest.raises(KeyError, match="no radar 'rear'; radars: front_radar"):
        record.radar_columns("rear", 11)


def test_cli_export_copies_images_on_request(morning, tmp_path):
    from pipeline.stages.cli import main

    out = tmp_path / "nus"
    assert main(["export", "--dataset", str(morning), "--format", "nuscenes", "--out", str(out), "--copy-images",
                 "--no-progress"]) == 0
    counts = json.loads((out / "export.json").read_text())["counts"]
    assert counts["images_copied"] == 2 and counts["images_linked"] == 0
    assert main(["export", "--dataset", str(morning), "--format", "nuscenes", "--out", str(tmp_path / "x"),
                 "--lidar", "top"]) == 2


def test_points_and_visibility_from_the_label_rows(nusc, radar_record):
    labels = DatasetRecord(radar_record).labels
    sample = _sample(nusc, "radar_s3_morning", 0)
    by_track = {token("instance", "radar_s3_morning", o.track_id): o.track_id for o in OBJECTS}
    levels = {v["token"]: v["level"] for v in nusc.visibility}
    for ann_token in sample["anns"]:
        ann = nusc.get("sample_annotation", ann_token)
        rows = labels[(labels["frame"] == 10) & (labels["track_id"] == by_track[ann["instance_token"]])]
        lidar, cam = rows[rows["sensor_type"] == "lidar"], rows[rows["sensor_type"] == "camera"]
        assert ann["num_lidar_pts"] == int(lidar["lidar_points"].sum()) > 0
        share = 0.0 if cam.empty else float((1 - cam["occlusion"].iloc[0]) * (1 - cam["truncation"].iloc[0]))
        low, high = {"v0-40": (0, 0.4), "v40-60": (0.4, 0.6), "v60-80": (0.6, 0.8), "v80-100": (0.8, 1.01)}[
            levels[ann["visibility_token"]]]
        assert low <= share < high, (by_track[ann["instance_token"]], share, levels[ann["visibility_token"]])
        if by_track[ann["instance_token"]] == 7:  # C, hidden behind A
            assert levels[ann["visibility_token"]] == "v0-40"
