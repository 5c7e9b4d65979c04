"""The tracking exports (mot, kitti-tracking) read back by TrackEval's own dataset readers, and round trips: the
ground truth given as the tracker's result scores HOTA = MOTA = IDF1 = 1.

TrackEval's ``MotChallenge2DBox`` evaluates MOT's pedestrian class only; the synthetic records' one pedestrian is
an ignore region (tiny), so the TrackEval round trip points the reader's evaluated class id at MOT's car (3),
leaving its reading and preprocessing as they are. ``Kitti2DBox`` evaluates KITTI's Car class as it is.
"""

from __future__ import annotations

import configparser
from pathlib import Path

import numpy as np
import pytest

from evaluation.tracking import evaluate_tracking
from exporters.base import ExportError, ExportOptions, get_exporter
from exporters.splits import SplitSpec
from pipeline.core.record import DatasetRecord
from tests.exporters.synthetic_record import build_record

trackeval = pytest.importorskip("trackeval")

EVAL_CONFIG = {"USE_PARALLEL": False, "PRINT_RESULTS": False, "PRINT_CONFIG": False, "TIME_PROGRESS": False,
               "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False}
SPLITS = SplitSpec.parse("val=urban:2,train=*")


@pytest.fixture(scope="module")
def long_record(tmp_path_factory) -> Path:
    """12 frames: the objects move (and cycle every 20 frames), so tracks span frames."""
    return build_record(tmp_path_factory.mktemp("long") / "highway-5-morning", scenario="highway", seed=5, frames=12)


@pytest.fixture(scope="module")
def mot_out(tmp_path_factory, records, long_record) -> Path:
    out = tmp_path_factory.mktemp("mot") / "mot"
    get_exporter("mot").export([*records, long_record], out, ExportOptions(splits=SPLITS))
    return out


@pytest.fixture(scope="module")
def kitti_out(tmp_path_factory, records, long_record) -> Path:
    out = tmp_path_factory.mktemp("kt") / "kitti_tracking"
    get_exporter("kitti-tracking").export([*records, long_record], out, ExportOptions(splits=SPLITS))
    return out


def _metrics():
    return [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
            trackeval.metrics.Identity({"PRINT_CONFIG": False})]


def _mot_dataset(out: Path, split: str, trackers: Path, car: bool = True):
    dataset = trackeval.datasets.MotChallenge2DBox({
        "GT_FOLDER": str(out / split), "TRACKERS_FOLDER": str(trackers), "SKIP_SPLIT_FOL": True,
        "SEQMAP_FILE": str(out / "seqmaps" / f"{split}.txt"), "BENCHMARK": "MOT17", "PRINT_CONFIG": False,
        "OUTPUT_FOLDER": str(trackers.parent / "out")})
    if car:
        dataset.class_name_to_class_id["pedestrian"] = 3  # evaluate MOT's car class with MOT's rules
    return dataset


def _gt_as_results(out: Path, split: str, trackers: Path) -> Path:
    """Tracker 'gt': every ground-truth box of every sequence (ignore regions included) in MOT results format."""
    data = trackers / "gt" / "data"
    data.mkdir(parents=True)
    for seq in (out / split).iterdir():
        lines = [line.split(",") for line in (seq / "gt" / "gt.txt").read_text().splitlines()]
        (data / f"{seq.name}.txt").write_text("".join(",".join([*f[:6], "1", "-1", "-1", "-1"]) + "\n" for f in lines))
    return data


def test_mot_layout_and_trackeval_reader(mot_out, records, long_record, tmp_path):
    assert sorted(p.name for p in mot_out.iterdir()) == ["export.json", "mapping.txt", "seqmaps", "train", "val"]
    train = sorted(p.name for p in (mot_out / "train").iterdir())
    assert train == ["highway_s1_morning_front", "highway_s1_night_front", "highway_s5_morning_front"]
    assert (mot_out / "seqmaps" / "val.txt").read_text() == "name\nurban_s2_morning_front\n"
    _gt_as_results(mot_out, "train", tmp_path / "trackers")
    dataset = _mot_dataset(mot_out, "train", tmp_path / "trackers", car=False)
    assert dataset.seq_list == train
    seq = "highway_s5_morning_front"
    ini = configparser.ConfigParser()
    ini.read(mot_out / "train" / seq / "seqinfo.ini")
    assert dict(ini["Sequence"]) == {"name": seq, "imdir": "img1", "framerate": "10", "seqlength": "12",
                                     "imwidth": "800", "imheight": "600", "imext": ".png"}
    assert len(list((mot_out / "train" / seq / "img1").iterdir())) == 12
    raw = dataset.get_raw_seq_data("gt", seq)  # TrackEval's own reader of gt.txt and the results file
    record = DatasetRecord(long_record)
    labels = record.labels[(record.labels["sensor"] == "front") & record.labels["visible"]]
    for t, frame in enumerate(sorted(record.frames["frame"])):
        rows = labels[labels["frame"] == frame].sort_values("track_id")
        np.testing.assert_array_equal(raw["gt_ids"][t], rows["track_id"].to_numpy())
        xywh = np.stack([rows["x1"], rows["y1"], rows["x2"] - rows["x1"], rows["y2"] - rows["y1"]], 1).astype(float)
        np.testing.assert_allclose(raw["gt_dets"][t], xywh, atol=0.005)
        ignore = rows["track_id"].to_numpy() == 12  # the tiny pedestrian
        np.testing.assert_array_equal(raw["gt_classes"][t], np.where(ignore, 8, [3 if c != "pedestrian" else 1
                                                                                  for c in rows["cls"]]))
        np.testing.assert_array_equal(raw["gt_extras"][t]["zero_marked"], (~ignore).astype(int))
    gt_txt = (mot_out / "train" / seq / "gt" / "gt.txt").read_text().splitlines()
    vis = {(int(f[0]), int(f[1])): float(f[8]) for f in (line.split(",") for line in gt_txt)}
    first = labels[labels["frame"] == labels["frame"].min()].set_index("track_id")
    for tid in (3, 4, 9):
        assert vis[(1, tid)] == pytest.approx(1 - first.loc[tid, "occlusion"], abs=5e-5)
    assert (1, 7) not in vis  # hidden car: not in the image, not written


def test_mot_round_trip_trackeval_and_ours(mot_out, tmp_path):
    trackers = tmp_path / "trackers"
    data = _gt_as_results(mot_out, "train", trackers)
    res, msg = trackeval.Evaluator(EVAL_CONFIG).evaluate([_mot_dataset(mot_out, "train", trackers)], _metrics())
    assert msg["MotChallenge2DBox"]["gt"] == "Success"
    combined = res["MotChallenge2DBox"]["gt"]["COMBINED_SEQ"]["pedestrian"]
    assert combined["CLEAR"]["CLR_TP"] == 3 * (2 + 2 + 12)  # cars A, B (van), D (truck) in the frames of 3 records
    for metric, field in (("HOTA", "HOTA"), ("CLEAR", "MOTA"), ("Identity", "IDF1")):
        assert np.all(np.asarray(combined[metric][field]) == pytest.approx(1.0)), field
    ours = evaluate_tracking(mot_out / "train", data)["combined"]
    assert ours["HOTA"] == ours["MOTA"] == ours["IDF1"] == pytest.approx(1.0)
    assert ours["CLR_TP"] == combined["CLEAR"]["CLR_TP"]


def test_mot_errors_leave_nothing(tmp_path, morning):
    out = tmp_path / "mot"
    with pytest.raises(ExportError, match=f"{morning}: .*nope"):
        get_exporter("mot").export([morning], out, ExportOptions(camera="nope"))
    assert not out.exists() and list(tmp_path.iterdir()) == []


def _parse_calib(path: Path) -> dict[str, np.ndarray]:
    out = {}
    for line in path.read_text().splitlines():
        key, *values = line.split()
        out[key.rstrip(":")] = np.array([float(v) for v in values])
    return out


def test_kitti_tracking_layout_matches_kitti_export(kitti_out, morning, tmp_path):
    training = kitti_out / "training"
    assert sorted(p.name for p in training.iterdir()) == [
        "calib", "evaluate_tracking.seqmap.train", "evaluate_tracking.seqmap.val", "image_02", "label_02", "oxts",
        "velodyne"]
    assert (training / "evaluate_tracking.seqmap.val").read_text() == "0003 empty 000000 000002\n"
    assert (training / "evaluate_tracking.seqmap.train").read_text().splitlines()[-1] == "0002 empty 000000 000012"
    assert sorted(p.name for p in (training / "image_02" / "0002").iterdir())[-1] == "000011.png"
    # sequence 0000 is highway seed 1 morning: the same labels, calib and points as the KITTI object export's
    kitti = tmp_path / "kitti"
    get_exporter("kitti").export([morning], kitti)
    ours = [line.split() for line in (training / "label_02" / "0000.txt").read_text().splitlines()]
    for index in range(2):
        label_2 = kitti / "training" / "label_2" / f"{index:06d}.txt"
        theirs = [line.split() for line in label_2.read_text().splitlines()]
        mine = [f for f in ours if f[0] == str(index)]
        assert [f[2] for f in mine] == [f[0] for f in theirs]
        assert [f[4:] for f in mine] == [f[2:] for f in theirs]
        for m, t in zip(mine, theirs, strict=True):
            if m[2] != "DontCare":
                assert int(m[3]) == int(np.searchsorted([0.1, 0.5], float(t[1]), side="right"))
            else:
                assert m[1] == "-1" and m[3] == "-1"
        velo = (training / "velodyne" / "0000" / f"{index:06d}.bin").read_bytes()
        assert velo == (kitti / "training" / "velodyne" / f"{index:06d}.bin").read_bytes()
    assert {f[1] for f in ours if f[2] != "DontCare"} == {"3", "4", "9"}
    mine = _parse_calib(training / "calib" / "0000.txt")
    theirs = _parse_calib(kitti / "training" / "calib" / "000000.txt")
    names = (("P2", "P2"), ("R_rect", "R0_rect"), ("Tr_velo_cam", "Tr_velo_to_cam"), ("Tr_imu_velo", "Tr_imu_to_velo"))
    for a, b in names:
        np.testing.assert_array_equal(mine[a], theirs[b])


def test_kitti_tracking_oxts_gives_back_the_ego_poses(kitti_out, long_record):
    oxts = np.array([[float(v) for v in line.split()] for line in
                     (kitti_out / "training" / "oxts" / "0002.txt").read_text().splitlines()])
    assert oxts.shape == (12, 30)
    frames = DatasetRecord(long_record).frames.sort_values("frame")
    er = 6378137.0  # the devkit's convertOxtsToPose with scale 1 (latitude 0)
    x = oxts[:, 1] * np.pi * er / 180
    y = er * np.log(np.tan((90 + oxts[:, 0]) * np.pi / 360))
    np.testing.assert_allclose(x, frames["ego_x_m"], atol=1e-6)
    np.testing.assert_allclose(y, frames["ego_y_m"], atol=1e-6)
    np.testing.assert_allclose(oxts[:, 2], frames["ego_z_m"], atol=1e-9)
    np.testing.assert_allclose(oxts[:, 5], frames["ego_yaw_rad"], atol=1e-9)
    np.testing.assert_allclose(np.hypot(oxts[:, 6], oxts[:, 7]), frames["ego_speed_mps"], atol=1e-9)
    assert np.isnan(oxts[:, 11:23]).all() and (oxts[:, 25:] == -1).all()


def test_kitti_tracking_round_trip_trackeval(kitti_out, tmp_path):
    data = tmp_path / "trackers" / "gt" / "data"
    data.mkdir(parents=True)
    for label in (kitti_out / "training" / "label_02").iterdir():
        lines = [line for line in label.read_text().splitlines() if " DontCare " not in line]
        (data / label.name).write_text("".join(f"{line} 1.0\n" for line in lines))
    dataset = trackeval.datasets.Kitti2DBox({
        "GT_FOLDER": str(kitti_out / "training"), "TRACKERS_FOLDER": str(tmp_path / "trackers"),
        "SPLIT_TO_EVAL": "train", "CLASSES_TO_EVAL": ["car"], "PRINT_CONFIG": False,
        "OUTPUT_FOLDER": str(tmp_path / "out")})
    assert dataset.seq_list == ["0000", "0001", "0002"] and dataset.seq_lengths["0002"] == 12
    raw = dataset.get_raw_seq_data("gt", "0002")
    assert [list(ids) for ids in raw["gt_ids"][:2]] == [[3, 4, 9], [3, 4, 9]]  # Car, Van, Truck read by TrackEval
    res, msg = trackeval.Evaluator(EVAL_CONFIG).evaluate([dataset], _metrics())
    assert msg["Kitti2DBox"]["gt"] == "Success"
    combined = res["Kitti2DBox"]["gt"]["COMBINED_SEQ"]["car"]
    assert combined["CLEAR"]["CLR_TP"] == 2 + 2 + 12  # car A in every frame
    for metric, field in (("HOTA", "HOTA"), ("CLEAR", "MOTA"), ("Identity", "IDF1")):
        assert np.all(np.asarray(combined[metric][field]) == pytest.approx(1.0)), field


def test_kitti_tracking_errors_leave_nothing(tmp_path, morning):
    out = tmp_path / "kt"
    with pytest.raises(ExportError, match=f"{morning}: no LiDAR 'nope'"):
        get_exporter("kitti-tracking").export([morning], out, ExportOptions(lidar="nope"))
    assert list(tmp_path.iterdir()) == []


def test_cli_export_and_evaluate_tracking(tmp_path, morning, capsys):
    from pipeline.stages.cli import main

    out = tmp_path / "mot"
    assert main(["export", "--dataset", str(morning), "--format", "mot", "--camera", "front", "--copy-images",
                 "--no-progress", "--out", str(out)]) == 0
    assert (out / "meta.json").is_file() and (out / "train" / "highway_s1_morning_front" / "gt" / "gt.txt").is_file()
    assert main(["export", "--dataset", str(morning), "--format", "mot", "--lidar", "top", "--out",
                 str(tmp_path / "x")]) == 2
    assert "--lidar applies to --format kitti, kitti-tracking, kitti-depth only, not mot" in capsys.readouterr().err
    results = tmp_path / "results"
    results.mkdir()
    gt = (out / "train" / "highway_s1_morning_front" / "gt" / "gt.txt").read_text().splitlines()
    (results / "highway_s1_morning_front.txt").write_text("".join(
        ",".join([*line.split(",")[:6], "1", "-1", "-1", "-1"]) + "\n" for line in gt))
    assert main(["evaluate", "--task", "tracking", "--gt", str(out / "train"), "--detections", str(results),
                 "--out", str(tmp_path / "eval")]) == 0
    import json

    combined = json.loads((tmp_path / "eval" / "metrics.json").read_text())["combined"]
    assert combined["HOTA"] == combined["MOTA"] == combined["IDF1"] == pytest.approx(1.0)
