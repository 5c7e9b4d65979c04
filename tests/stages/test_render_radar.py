"""The render stage's radar: scans a plain Parquet reader finds consistent, their counts in labels.parquet, and a
radar that changes nothing else in the record (and a rig without one that writes no trace of it)."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.core.record import RADAR_COLUMNS, DatasetRecord
from pipeline.stages.render import render
from tests.conftest import tree_hashes


@pytest.fixture(scope="module")
def radar_name(small_rig) -> str:
    assert len(small_rig.radars) == 1  # the default rig's front radar
    return small_rig.radars[0].name


def test_scans_are_consistent_to_an_independent_reader(small_record, radar_name):
    info = json.loads((small_record / "record.json").read_text())
    (radar,) = info["radars"]
    assert radar["name"] == radar_name and radar["range_max_m"] == 200.0
    labels = pq.read_table(small_record / "labels.parquet").to_pandas()
    frames = pq.read_table(small_record / "frames.parquet").column("frame").to_pylist()
    moving = 0
    for frame in frames:
        path = small_record / "radars" / radar_name / f"{frame:06d}.parquet"
        table = pq.read_table(path)
        assert table.schema.names == list(RADAR_COLUMNS)
        d = {c: table.column(c).to_numpy() for c in table.schema.names}
        assert 0 < len(d["x_m"]) <= radar["max_detections"]
        xyz = np.column_stack([d["x_m"], d["y_m"], d["z_m"]]).astype(np.float64)
        np.testing.assert_allclose(d["range_m"], np.linalg.norm(xyz, axis=1), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(d["azimuth_rad"], np.arctan2(xyz[:, 1], xyz[:, 0]), atol=1e-5)
        assert (d["range_m"] <= radar["range_max_m"] + 1.0).all()
        here = labels[labels["frame"] == frame]
        ids = d["instance_id"][d["instance_id"] > 0]
        assert set(ids) <= set(here["track_id"])  # every object detected is labelled
        rows = here[here["sensor"] == radar_name].set_index("track_id")["radar_detections"]
        counted = dict(zip(*np.unique(ids, return_counts=True), strict=True))
        assert {int(k): int(v) for k, v in rows.items() if v} == {int(k): int(v) for k, v in counted.items()}
        for _, row in here[here["sensor"] != radar_name].iterrows():  # the other rows carry the same counts
            assert row["radar_detections"] == counted.get(row["track_id"], 0)
        moving += int((np.abs(d["radial_velocity_comp_mps"][d["instance_id"] > 0]) > 1.0).sum())
        static = d["instance_id"] == 0
        assert np.abs(d["radial_velocity_comp_mps"][static]).max(initial=0) < 0.5  # the world stands still
    assert moving > 0  # Doppler from the traffic
    record = DatasetRecord(small_record)
    assert len(record.radar_detections(radar_name, frames[0])) > 0
    assert "radar_detections" in record.labels.columns


@pytest.mark.slow
def test_the_radar_changes_nothing_else_and_a_rig_without_it_leaves_no_trace(run_21_frames, small_rig,
                                                                             noon_condition, small_record,
                                                                             tmp_path):
    bare = small_rig.model_copy(update={"radars": []})
    out = tmp_path / "bare"
    render(run_21_frames, noon_condition, bare, out, frames=3, workers=1, shard_size=2, progress=False)
    with_radar, without = tree_hashes(small_record), tree_hashes(out)
    assert not (out / "radars").exists()
    assert "radars" not in json.loads((out / "record.json").read_text())
    assert "radars" not in json.loads((out / "meta.json").read_text())["config"]["rig"]
    for name, digest in without.items():
        if name.startswith(("cameras/", "lidars/")) or name == "frames.parquet":
            assert with_radar[name] == digest, name
    a = pq.read_table(out / "labels.parquet").to_pandas()
    b = pq.read_table(small_record / "labels.parquet").to_pandas()
    assert "radar_detections" not in a.columns
    b = b[b["sensor_type"] != "radar"][list(a.columns)].reset_index(drop=True)
    assert a.equals(b)


def test_exports_carry_the_radar(small_record, radar_name, tmp_path):
    """MCAP (mcap + protobuf decoder) and rosbag2 (rosbags reader, mcap-ros2 decoder): the radar's detections with
    every field at its offset, its transform, and the Foxglove layout drawing them by radial velocity."""
    from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
    from rosbags.rosbag2 import Reader

    from exporters.base import ExportOptions, get_exporter

    record = DatasetRecord(small_record)
    frame = int(record.frames["frame"].iloc[0])
    scan = record.radar_detections(radar_name, frame)
    t0 = round(float(record.frames["time_s"].iloc[0]) * 1e9)
    out = tmp_path / "run.mcap"
    get_exporter("mcap").export([small_record], out, ExportOptions(progress=False))
    with out.open("rb") as f:
        messages = [(c.topic, m.log_time, d) for _, c, m, d in
                    make_reader(f, decoder_factories=[ProtobufDecoderFactory()]).iter_decoded_messages()]
    clouds = [(t, d) for topic, t, d in messages if topic == f"/radar/{radar_name}/detections"]
    assert len(clouds) == len(record.frames)
    cloud = next(d for t, d in clouds if t == t0)
    assert cloud.frame_id == radar_name and len(cloud.data) == cloud.point_stride * len(scan)
    raw = np.frombuffer(cloud.data, np.uint8).reshape(-1, cloud.point_stride)
    types = {PackedElementField.UINT8: "u1", PackedElementField.FLOAT32: "<f4", PackedElementField.INT32: "<i4"}
    column = {"x": "x_m", "range": "range_m", "azimuth": "azimuth_rad", "radial_velocity": "radial_velocity_mps",
              "radial_velocity_comp": "radial_velocity_comp_mps", "rcs": "rcs_dbsm", "snr": "snr_db",
              "instance": "instance_id", "class": "semantic"}
    fields = {f.name: f for f in cloud.fields}
    for name, col in column.items():
        f = fields[name]
        size = np.dtype(types[f.type]).itemsize
        values = raw[:, f.offset:f.offset + size].copy().view(types[f.type])[:, 0]
        np.testing.assert_array_equal(values, scan[col].to_numpy())
    tf = next(d for topic, t, d in messages if topic == "/tf" and t == t0)
    (mount,) = [x for x in tf.transforms if x.child_frame_id == radar_name]
    assert mount.translation.x == pytest.approx(record.info.radars[0].T_array[0, 3])
    layout = json.loads((tmp_path / "run.layout.json").read_text())
    (scene,) = [c for k, c in layout["configById"].items() if k.startswith("3D")]
    radar_topic = scene["topics"][f"/radar/{radar_name}/detections"]
    assert radar_topic["visible"] and radar_topic["colorField"] == "radial_velocity"

    bag = tmp_path / "bag"
    get_exporter("rosbag2").export([small_record], bag, ExportOptions(progress=False))
    with Reader(bag) as reader:
        types_by_topic = {c.topic: c.msgtype for c in reader.connections}
    assert types_by_topic[f"/radar/{radar_name}/points"] == "sensor_msgs/msg/PointCloud2"
    assert types_by_topic[f"/radar/{radar_name}/scan"] == "radar_msgs/msg/RadarScan"
    decoded = {}
    with next(bag.glob("*.mcap")).open("rb") as f:
        reader = make_reader(f, decoder_factories=[Ros2DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages():
            if message.log_time == t0:
                decoded[channel.topic] = msg
    ros_scan = decoded[f"/radar/{radar_name}/scan"]
    assert len(ros_scan.returns) == len(scan) and ros_scan.header.frame_id == radar_name
    np.testing.assert_array_equal([r.doppler_velocity for r in ros_scan.returns],
                                  scan["radial_velocity_mps"].to_numpy())
    np.testing.assert_array_equal([r.azimuth for r in ros_scan.returns], scan["azimuth_rad"].to_numpy())
    cloud2 = decoded[f"/radar/{radar_name}/points"]
    assert cloud2.point_step == 48 and cloud2.width == len(scan)
    data = np.frombuffer(bytes(cloud2.data), np.uint8).reshape(-1, cloud2.point_step)
    ros_types = {2: "u1", 5: "<i4", 7: "<f4"}  # sensor_msgs/PointField UINT8, INT32, FLOAT32
    for f in cloud2.fields:
        if f.name in column:
            size = np.dtype(ros_types[f.datatype]).itemsize
            values = data[:, f.offset:f.offset + size].copy().view(ros_types[f.datatype])[:, 0]
            np.testing.assert_array_equal(values, scan[column[f.name]].to_numpy())


def test_preview_colours_radial_velocity_red_approaching_blue_receding():
    import cv2

    from pipeline.stages.preview import RADAR_VELOCITY_RANGE_MPS, radial_velocity_colours

    low, high = RADAR_VELOCITY_RANGE_MPS
    colours = radial_velocity_colours(np.array([low - 5.0, low, high, high + 5.0]))
    turbo = cv2.applyColorMap(np.array([[255], [0]], np.uint8), cv2.COLORMAP_TURBO)[:, 0]
    np.testing.assert_array_equal(colours, [turbo[0], turbo[0], turbo[1], turbo[1]])  # clipped at the ends
    b, _, r = colours[0].astype(int)
    assert r > b  # approaching: red end
    b, _, r = colours[2].astype(int)
    assert b > r  # receding: blue end


def test_preview_draws_the_radar_detections_where_they_are(small_record):
    from pipeline.stages.preview import BEV_PX, _bev_panel, _to_bev, radial_velocity_colours

    record = DatasetRecord(small_record)
    lidar, radar = record.info.lidars[0], record.info.radars[0]
    frame = int(record.frames["frame"].iloc[0])
    none = record.labels.iloc[:0]
    plain = _bev_panel(record, lidar, frame, none, BEV_PX)
    drawn = _bev_panel(record, lidar, frame, none, BEV_PX, radar=radar)
    scan = record.radar_detections(radar.name, frame)
    lidar_from_radar = np.linalg.inv(lidar.T_array) @ radar.T_array
    xy = (scan[["x_m", "y_m", "z_m"]].to_numpy(np.float64) @ lidar_from_radar[:3, :3].T + lidar_from_radar[:3, 3])
    uv = np.round(_to_bev(xy[:, :2])).astype(int)
    inside = ((uv >= 0) & (uv < BEV_PX)).all(axis=1)
    assert inside.sum() > 10
    # The last disc drawn keeps its colour at its centre (unless the caption covers it).
    u, v = uv[inside][-1]
    assert (drawn[v, u] == radial_velocity_colours(scan["radial_velocity_mps"].to_numpy()[inside][-1:])[0]).all()
    changed = np.argwhere((drawn != plain).any(axis=2))
    near = np.min(np.abs(changed[:, None, ::-1] - uv[inside][None]).max(axis=2), axis=1) <= 6  # within a ringed disc
    assert near[changed[:, 0] > 45].all()  # below the captions, every changed pixel belongs to a detection's disc
