"""The render stage on a small real run: a complete canonical record whose labels agree with its images."""

from __future__ import annotations

import gc
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pandas as pd
import pytest

from pipeline.core.classes import RIDER, RIDER_TRACK_OFFSET, SemanticClass
from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.core.geometry import Boxes3D, Transform
from pipeline.core.record import SCHEMA_VERSION, DatasetRecord, RecordError
from pipeline.stages import render_frames
from pipeline.stages.render import render, worker_context
from tests.conftest import tree_hashes
from tests.stages.conftest import kill_render_after

FRAMES = 3


@pytest.fixture(scope="module")
def rig() -> RigConfig:
    return load_config(RigConfig, "default", "rigs")[0]


@pytest.fixture(scope="module")
def noon() -> ConditionConfig:
    return load_config(ConditionConfig, "noon", "conditions")[0]


@pytest.fixture(scope="module")
def record_dir(dense_highway_run, rig, noon, tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "highway-7-noon"
    render(dense_highway_run, noon, rig, out, frames=FRAMES, workers=1, shard_size=2, progress=False)
    return out


def test_record_is_complete_and_readable(record_dir):
    record = DatasetRecord(record_dir)
    assert record.info.scenario == "highway" and record.info.seed == 3 and record.info.condition == "noon"
    frames = record.frames
    assert len(frames) == FRAMES
    assert frames["frame"].tolist() == sorted(frames["frame"])
    for frame in frames["frame"]:
        assert record.rgb("front", frame).shape == (600, 800, 3)
        assert len(record.points("top", frame)) > 10000
    assert not list(record_dir.parent.glob(".*partial"))


def test_tight_boxes_and_pixel_counts_come_from_the_instance_image(record_dir):
    record = DatasetRecord(record_dir)
    labels = record.labels
    cams = labels[labels["sensor_type"] == "camera"]
    assert cams["visible"].any()
    for frame, rows in cams.groupby("frame"):
        inst = record.instance("front", frame)
        rider = record.semantic("front", frame) == SemanticClass.RIDER
        for r in rows.itertuples(index=False):
            # A rider's pixels are its cycle's that show it (semantic RIDER); its cycle's hold both.
            own = (inst == r.track_id - RIDER_TRACK_OFFSET) & rider if r.cls == RIDER else inst == r.track_id
            ys, xs = np.nonzero(own)
            assert bool(r.visible) == (len(xs) > 0)
            if not r.visible:
                assert r.x1 is pd.NA  # no visible pixel: no tight box
                continue
            assert r.visible_px == len(xs)
            assert (r.x1, r.y1, r.x2, r.y2) == (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)
            assert 0.0 <= r.occlusion <= 1.0 and r.unoccluded_px >= r.visible_px


def test_lidar_points_of_an_object_lie_in_its_box(record_dir):
    record = DatasetRecord(record_dir)
    labels = record.labels
    lidar = record.info.lidars[0]
    checked = 0
    for frame, rows in labels[labels["sensor"] == "top"].groupby("frame"):
        pts = record.points("top", frame)
        for r in rows[rows["lidar_points"] > 0].itertuples(index=False):
            own = pts[pts["instance_id"] == r.track_id][["x_m", "y_m", "z_m"]].to_numpy()
            assert len(own) == r.lidar_points
            box = Boxes3D([[r.sensor_x_m, r.sensor_y_m, r.sensor_z_m]], [[r.length_m, r.width_m, r.height_m]],
                          [r.sensor_yaw_rad])
            # range noise is 2 cm (std) along the beam; allow 4 std
            assert box.contains(own, margin_m=0.08).all()
            checked += 1
    assert checked > 0
    assert np.allclose(np.asarray(lidar.T_ego_sensor)[:3, 3], [0.0, 0.0, 1.05])


def test_world_and_sensor_boxes_agree(record_dir):
    record = DatasetRecord(record_dir)
    frames = record.frames.set_index("frame")
    cam = record.info.camera("front")
    labels = record.labels
    rows = labels[labels["sensor"] == "front"]
    for r in rows.head(20).itertuples(index=False):
        f = frames.loc[r.frame]
        ego = Transform.from_xyz_rpy((f.ego_x_m, f.ego_y_m, f.ego_z_m), (0.0, 0.0, f.ego_yaw_rad))
        world_to_cam = (ego @ Transform.from_matrix(cam.T_array)).inverse()
        np.testing.assert_allclose(world_to_cam.apply([r.x_m, r.y_m, r.z_m]),
                                   [r.sensor_x_m, r.sensor_y_m, r.sensor_z_m], atol=1e-6)


def test_two_workers_give_the_same_bytes(dense_highway_run, rig, noon, record_dir, tmp_path):
    # This process has cast rays (record_dir), so the workers fork from a server process, not from here.
    assert worker_context().get_start_method() == ("forkserver" if sys.platform.startswith("linux") else "spawn")
    again = tmp_path / "again"
    opencv_threads = cv2.getNumThreads()
    render(dense_highway_run, noon, rig, again, frames=FRAMES, workers=2, shard_size=2, progress=False)
    assert tree_hashes(again, skip=("meta.json",)) == tree_hashes(record_dir, skip=("meta.json",))
    # What the render sets for itself in this process comes back: OpenCV's threads, the collector's reach; the
    # static world it built (which its shards here took without unpickling) is forgotten.
    assert cv2.getNumThreads() == opencv_threads and gc.get_freeze_count() == 0
    assert not render_frames._WORLDS


_FRESH_RENDER = """
import sys
from pathlib import Path
from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.stages.render import render, worker_context
method = worker_context().get_start_method()
if method != "fork":
    sys.exit(f"a process that has not cast rays should fork its workers, not {method}")
render(Path(sys.argv[1]), load_config(ConditionConfig, "noon", "conditions")[0],
       load_config(RigConfig, "default", "rigs")[0], Path(sys.argv[2]), frames=int(sys.argv[3]), workers=2,
       shard_size=2, progress=False)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="workers fork from the render process on Linux only")
def test_workers_forked_from_a_fresh_render_process_give_the_same_bytes(dense_highway_run, record_dir, tmp_path):
    out = tmp_path / "forked"
    proc = subprocess.run([sys.executable, "-c", _FRESH_RENDER, str(dense_highway_run), str(out), str(FRAMES)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert tree_hashes(out, skip=("meta.json",)) == tree_hashes(record_dir, skip=("meta.json",))


def test_an_interrupted_render_resumes_with_the_shards_done(dense_highway_run, rig, noon, record_dir, tmp_path,
                                                            monkeypatch):
    out = tmp_path / "resumed"
    kill_render_after(monkeypatch, 1)
    with pytest.raises(KeyboardInterrupt):
        render(dense_highway_run, noon, rig, out, frames=FRAMES, workers=1, shard_size=2, progress=False)
    assert not out.exists()  # nothing half-written where DVC looks
    assert (tmp_path / ".resumed.partial" / "shards" / "done-00000").is_file()
    monkeypatch.undo()
    summary = render(dense_highway_run, noon, rig, out, frames=FRAMES, workers=1, shard_size=2, progress=False)
    assert summary["shards_resumed"] == 1
    assert tree_hashes(out, skip=("meta.json",)) == tree_hashes(record_dir, skip=("meta.json",))
    assert not (tmp_path / ".resumed.partial").exists()


def test_missing_or_foreign_inputs_fail_clearly(tmp_path, rig, noon, record_dir):
    with pytest.raises(FileNotFoundError, match="not a simulate output .trajectories.parquet is missing"):
        render(tmp_path, noon, rig, tmp_path / "out", progress=False)
    foreign = tmp_path / "foreign"
    shutil.copytree(record_dir, foreign)
    text = (foreign / "record.json").read_text().replace(f'"schema_version": {SCHEMA_VERSION}', '"schema_version": 99')
    (foreign / "record.json").write_text(text)
    with pytest.raises(RecordError, match="schema_version 99 is not supported"):
        DatasetRecord(foreign)


def test_a_rig_with_two_cameras_and_two_lidars(dense_highway_run, noon, tmp_path):
    import yaml

    from tests.conftest import REPO

    data = yaml.safe_load((REPO / "configs" / "rigs" / "default.yaml").read_text())
    rear = dict(data["cameras"][0], name="rear", width_px=320, height_px=240,
                mount={"xyz_m": [-2.0, 0.0, 0.6], "rpy_rad": [0.0, 0.0, 3.141592653589793]})
    low = dict(data["lidars"][0], name="low", channels=16, mount={"xyz_m": [2.0, 0.0, 0.0], "rpy_rad": [0, 0, 0]})
    data.update(name="two_by_two", cameras=[data["cameras"][0], rear], lidars=[data["lidars"][0], low])
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    rig, _ = load_config(RigConfig, path, "rigs")
    out = tmp_path / "record"
    render(dense_highway_run, noon, rig, out, frames=1, workers=1, progress=False)
    record = DatasetRecord(out)
    assert [c.name for c in record.info.cameras] == ["front", "rear"]
    assert [lidar.name for lidar in record.info.lidars] == ["top", "low"]
    frame = int(record.frames["frame"].iloc[0])
    assert record.rgb("rear", frame).shape == (240, 320, 3)
    assert record.points("low", frame)["ring"].max() == 15
    # The rear camera looks backwards: its optical axis is the ego's -x.
    np.testing.assert_allclose(record.info.camera("rear").T_array[:3, 2], [-1.0, 0.0, 0.0], atol=1e-9)
    labels = record.labels
    assert set(labels["sensor"]) <= {"front", "rear", "top", "low", *(radar.name for radar in rig.radars)}
