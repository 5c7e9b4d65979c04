"""The render stage: the shard plan, resuming with another shard size, the record's frame rate, and which objects
get LiDAR label rows when a condition shortens the LiDAR's range."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.core.config import ConditionConfig, load_config
from pipeline.core.geometry import Transform
from pipeline.core.record import DatasetRecord
from pipeline.sensors.conditions import Condition
from pipeline.sensors.lidar import Lidar
from pipeline.stages.render import plan_shards, record_rate_hz, render
from tests.conftest import tree_hashes
from tests.stages.conftest import EVERY_10TH, kill_render_after


def test_the_last_shards_shrink_so_workers_finish_together():
    sizes = [len(s) for s in plan_shards(list(range(100)), 5)]
    assert sizes == [5] * 18 + [3, 2, 2, 1, 1, 1]


@given(st.lists(st.integers(0, 10_000), unique=True, max_size=200).map(sorted), st.integers(1, 12))
def test_the_shard_plan_covers_every_frame_once_in_order(frames, shard_size):
    shards = plan_shards(frames, shard_size)
    assert [f for shard in shards for f in shard] == frames
    sizes = [len(s) for s in shards]
    assert all(0 < n <= shard_size for n in sizes)
    assert sizes == sorted(sizes, reverse=True)  # full shards first, then shrinking ones
    assert sum(n < shard_size for n in sizes) <= 2 * shard_size  # only the tail is cut up
    if frames:
        assert sizes[-1] == 1


@pytest.mark.parametrize(("first_size", "shards_before_kill", "second_size"), [(1, 2, 2), (2, 1, 1)])
def test_a_resume_with_another_shard_size_renders_every_frame(run_21_frames, small_rig, noon_condition, small_record,
                                                              tmp_path, monkeypatch, first_size, shards_before_kill,
                                                              second_size):
    out = tmp_path / "resumed"
    kill_render_after(monkeypatch, shards_before_kill)
    with pytest.raises(KeyboardInterrupt):
        render(run_21_frames, noon_condition, small_rig, out, frames=EVERY_10TH, workers=1, shard_size=first_size,
               progress=False)
    monkeypatch.undo()
    render(run_21_frames, noon_condition, small_rig, out, frames=EVERY_10TH, workers=1, shard_size=second_size,
           progress=False)
    assert DatasetRecord(out).frames["frame"].tolist() == [0, 10, 20]
    # the same bytes as a render that was never interrupted
    assert tree_hashes(out, skip=("meta.json",)) == tree_hashes(small_record, skip=("meta.json",))


@pytest.mark.parametrize("damage", ["truncated png", "missing sweep", "flipped parquet byte"])
def test_a_resume_renders_again_a_shard_whose_files_are_damaged(run_21_frames, small_rig, noon_condition, small_record,
                                                                 tmp_path, monkeypatch, caplog, damage):
    """A finished shard whose image was truncated, or whose LiDAR sweep is gone or damaged (a full disk, a copy cut
    short) is not reused: it is rendered again, and the record is the uninterrupted one, byte for byte."""
    out = tmp_path / "resumed"
    kill_render_after(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        render(run_21_frames, noon_condition, small_rig, out, frames=EVERY_10TH, workers=1, shard_size=1,
               progress=False)
    monkeypatch.undo()
    partial = tmp_path / ".resumed.partial" / "record"
    if damage == "truncated png":
        victim = next(partial.rglob("rgb/000000.png"))
        victim.write_bytes(victim.read_bytes()[: victim.stat().st_size // 2])
    elif damage == "missing sweep":
        victim = next(partial.rglob("lidars/*/000010.parquet"))
        victim.unlink()
    else:
        victim = next(partial.rglob("lidars/*/000000.parquet"))
        data = bytearray(victim.read_bytes())
        data[len(data) // 3] ^= 0xFF
        victim.write_bytes(bytes(data))
    caplog.set_level("WARNING", "pipeline.stages.render")
    render(run_21_frames, noon_condition, small_rig, out, frames=EVERY_10TH, workers=1, shard_size=1, progress=False)
    assert "rendering shard" in caplog.text and victim.name in caplog.text
    assert tree_hashes(out, skip=("meta.json",)) == tree_hashes(small_record, skip=("meta.json",))


def test_the_frame_rate_is_the_records_own(small_record):
    record = DatasetRecord(small_record)
    assert np.diff(record.frames["frame"]).tolist() == [10, 10]  # every 10th frame of a 10 Hz run
    assert np.diff(record.frames["time_s"]) == pytest.approx([1.0, 1.0])
    assert record.info.frame_rate_hz == pytest.approx(1.0, rel=1e-12)


def test_record_rate_of_uneven_and_single_frames():
    # 3 intervals over 29 simulation frames at 10 Hz: one frame per 2.9 s on average
    assert record_rate_hz([0, 10, 19, 29], 10.0) == pytest.approx(3 / 2.9)
    assert record_rate_hz(list(range(5)), 10.0) == pytest.approx(10.0)
    assert record_rate_hz([7], 10.0) == 10.0


def test_lidar_rows_in_fog_follow_the_shortened_range(dense_highway_run, small_rig, tmp_path):
    fog = load_config(ConditionConfig, "fog", "conditions")[0]
    rig_range = small_rig.lidars[0].range_m
    fog_range = Condition(fog).lidar(Lidar(small_rig.lidars[0])).range_m
    assert fog_range < rig_range
    out = tmp_path / "fog"
    render(dense_highway_run, fog, small_rig, out, frames=2, workers=1, progress=False)
    record = DatasetRecord(out)
    lidar = record.info.lidars[0]
    trajectories = pd.read_parquet(dense_highway_run / "trajectories.parquet")
    between = 0
    for f in record.frames.itertuples(index=False):
        ego = Transform.from_xyz_rpy((f.ego_x_m, f.ego_y_m, f.ego_z_m), (0.0, 0.0, f.ego_yaw_rad))
        world_to_lidar = (ego @ Transform.from_matrix(lidar.T_array)).inverse()
        actors = trajectories[(trajectories["frame"] == f.frame) & ~trajectories["is_ego"]]
        dist = np.linalg.norm(world_to_lidar.apply(actors[["x_m", "y_m", "z_m"]].to_numpy()), axis=1)
        ids = record.points(lidar.name, f.frame)["instance_id"]
        owners = ids[ids > 0].value_counts()
        assert owners.index.isin(actors["track_id"]).all()
        expected = set(actors["track_id"][dist <= fog_range]) | set(owners.index)
        labels = record.labels
        rows = labels[(labels["frame"] == f.frame) & (labels["sensor"] == lidar.name)]
        assert set(rows["track_id"]) == expected
        counts = rows.set_index("track_id")["lidar_points"]
        assert all(counts[t] == owners.get(t, 0) for t in counts.index)
        between += int(((dist > fog_range) & (dist <= rig_range)).sum())
    assert between > 0  # objects the rig's range would have labelled: fog's shorter range leaves them out


def test_an_object_owning_points_beyond_the_range_gets_a_row(small_rig):
    from pipeline.core.record_writers.lidar import lidar_label_rows
    from pipeline.sensors.lidar import LidarSweep
    from pipeline.stages.rig import build_sensors

    lidar = build_sensors(small_rig)[1][0]
    n = 3  # on the LiDAR's x axis at 30, 70 and 70 m (ego at the origin); only the second owns points
    z_m = lidar.mount.translation[2]
    cols = {"track_id": np.array([1, 2, 3], np.int32), "cls": np.array(["car", "truck", "car"], object),
            "x_m": np.array([30.0, 70.0, 70.0]), "y_m": np.zeros(n), "z_m": np.full(n, z_m),
            "length_m": np.full(n, 4.0), "width_m": np.full(n, 1.8), "height_m": np.full(n, 1.5),
            "yaw_rad": np.zeros(n), "model": np.array(["sedan", "box_truck", "sedan"], object),
            "person": np.full(n, "", object)}
    empty = np.zeros(0)
    sweep = LidarSweep(np.zeros((0, 3), np.float32), empty, empty, empty, empty, empty, empty,
                       points_per_actor=np.array([0, 5, 0]), range_max_m=60.0)
    rows = lidar_label_rows(4, "top", lidar.mount, sweep, cols, Transform.identity())
    assert rows["track_id"].tolist() == [1, 2]
    assert rows["lidar_points"].tolist() == [0, 5]
    assert rows["distance_m"] == pytest.approx([30.0, 70.0])


def test_an_exposure_the_camera_cannot_honour_is_refused_naming_the_field():
    from pipeline.core.config.loading import ConfigError, parse_config

    noon = load_config(ConditionConfig, "noon", "conditions")[0].model_dump(mode="json")
    for exposure in (1e-9, 100.0):
        with pytest.raises(ConfigError, match=r"lens\.exposure"):
            parse_config(ConditionConfig, {**noon, "lens": {**noon["lens"], "exposure": exposure}}, "cond.yaml")


def test_a_record_whose_frames_are_all_black_is_an_error_and_some_black_ones_a_warning(run_21_frames, small_rig,
                                                                                      tmp_path, caplog):
    """A condition without light at the lowest exposure: every frame black while its labels say objects are
    visible (they are, to the geometry): refused, nothing written. Frames of a record checked one by one: the
    black ones are counted and named."""
    import cv2

    from pipeline.stages.render import _blank_frames

    night = load_config(ConditionConfig, "night", "conditions")[0].model_dump(mode="json")
    dark = {**night, "headlights": None, "street_lamps": None, "vehicle_lights": {"glow": False},
            "sky": {**night["sky"], "ambient_rgb": [0.0, 0.0, 0.0], "zenith_rgb": [0.0, 0.0, 0.0],
                    "horizon_rgb": [0.0, 0.0, 0.0]},
            "lens": {**night["lens"], "exposure": 1 / 64}}
    condition = ConditionConfig.model_validate(dark)
    with pytest.raises(ValueError, match="every frame with visible objects came out black"):
        render(run_21_frames, condition, small_rig, tmp_path / "rec", frames=EVERY_10TH, workers=1, progress=False)
    assert not (tmp_path / "rec").exists()

    record = tmp_path / "made"
    folder = record / "cameras" / "front" / "rgb"
    folder.mkdir(parents=True)
    cv2.imwrite(str(folder / "000000.png"), np.zeros((8, 8), np.uint8))
    cv2.imwrite(str(folder / "000001.png"), np.full((8, 8), 120, np.uint8))
    cv2.imwrite(str(folder / "000002.png"), np.full((8, 8), 255, np.uint8))
    visible = pd.DataFrame({"sensor": ["front"] * 4, "frame": [0, 1, 2, 2]})
    caplog.set_level("WARNING", "pipeline.stages.render")
    assert _blank_frames(record, visible, ["front"], "noon") == {
        "front": {"black": 1, "white": 1, "with_visible_objects": 3}}
    assert "1 black and 1 white frames" in caplog.text
