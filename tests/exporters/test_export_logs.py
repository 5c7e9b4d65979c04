"""MCAP (Foxglove protobuf) and rosbag2 exports read back by independent readers.

MCAP: the mcap reader with mcap-protobuf-support's decoder. rosbag2: rosbags' reader for every
message, and the mcap-ros2-support decoder (which parses the message definitions stored in the bag,
vision_msgs included) for their content.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory

from exporters.base import Compression, ExportOptions, get_exporter
from pipeline.core.record import DatasetRecord

MCAP_TOPICS = {
    "/tf": "foxglove.FrameTransforms", "/ego/pose": "foxglove.PoseInFrame",
    "/camera/front/image": "foxglove.CompressedImage", "/camera/front/calibration": "foxglove.CameraCalibration",
    "/camera/front/annotations": "foxglove.ImageAnnotations", "/lidar/top/points": "foxglove.PointCloud",
    "/scene/objects": "foxglove.SceneUpdate",
}


def _read_mcap(path: Path):
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[ProtobufDecoderFactory()])
        decoded = reader.iter_decoded_messages(log_time_order=True)
        messages = [(s.name, c.topic, m.log_time, d) for s, c, m, d in decoded]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        chunks = {c.compression for c in reader.get_summary().chunk_indexes}
    return messages, metadata, chunks


@pytest.mark.parametrize("compression", [Compression.ZSTD, Compression.LZ4, Compression.NONE])
def test_mcap_protobuf_round_trip(tmp_path, morning, compression):
    out = tmp_path / "run.mcap"
    get_exporter("mcap").export([morning], out, ExportOptions(compression=compression), meta={"stage": "export"})
    messages, metadata, chunks = _read_mcap(out)
    assert chunks == {{"zstd": "zstd", "lz4": "lz4", "none": ""}[compression.value]}
    assert Counter(t for _, t, _, _ in messages) == dict.fromkeys(MCAP_TOPICS, 2)
    assert all(MCAP_TOPICS[topic] == schema for schema, topic, _, _ in messages)
    assert {t for _, _, t, _ in messages} == {1_000_000_000, 1_100_000_000}  # simulation time, ns
    assert (morning / "meta.json").read_text() == metadata["roadsynth.record.highway_s1_morning"]["meta.json"]
    assert json.loads(metadata["roadsynth.meta"]["meta.json"]) == {"stage": "export"}
    assert json.loads(metadata["roadsynth.export"]["export.json"])["counts"]["frames"] == 2
    if compression is not Compression.ZSTD:
        return
    record = DatasetRecord(morning)
    first = {topic: msg for _, topic, t, msg in messages if t == 1_000_000_000}
    assert first["/camera/front/image"].data == (morning / "cameras/front/rgb/000010.png").read_bytes()
    cloud = first["/lidar/top/points"]
    raw = np.frombuffer(cloud.data, dtype=np.uint8).reshape(-1, cloud.point_stride)
    offsets = {f.name: f.offset for f in cloud.fields}
    points = record.points("top", 10)
    np.testing.assert_array_equal(raw[:, offsets["x"]:offsets["x"] + 4].copy().view("<f4")[:, 0], points["x_m"])
    np.testing.assert_array_equal(raw[:, offsets["instance"]:offsets["instance"] + 4].copy().view("<i4")[:, 0],
                                  points["instance_id"])
    # 3 kept objects + 1 ignore region (the tiny pedestrian); the hidden car has no box.
    assert len(first["/camera/front/annotations"].points) == 4
    assert {e.id for e in first["/scene/objects"].entities} == {f"track-{i}" for i in (3, 4, 7, 9, 12)}
    tf = first["/tf"].transforms
    assert [(x.parent_frame_id, x.child_frame_id) for x in tf] == [("world", "ego"), ("ego", "front"), ("ego", "top")]
    assert first["/camera/front/calibration"].K[0] == 400.0


def test_mcap_of_many_chunks_keeps_every_message_in_order(tmp_path, morning, night, monkeypatch):
    """With small chunks the export spans many, compressed on the pool while the next fill: every message comes
    back once, CRCs valid, each channel's sequence numbers in log order, and the file is the same with one
    compression worker as with three."""
    import exporters.mcap as mcap_exporter

    monkeypatch.setattr(mcap_exporter, "CHUNK_SIZE", 32 << 10)
    outputs = []
    for workers in (3, 1):
        monkeypatch.setattr(mcap_exporter, "COMPRESS_WORKERS", workers)
        out = tmp_path / f"w{workers}.mcap"
        get_exporter("mcap").export([night, morning], out)
        outputs.append(out.read_bytes())
    assert outputs[0] == outputs[1]
    with (tmp_path / "w1.mcap").open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert len(reader.get_summary().chunk_indexes) > 4  # more than may wait with 3 workers: the queue filled
        read = [(channel.topic, message.sequence, message.log_time)
                for _, channel, message in reader.iter_messages(log_time_order=False)]
    assert Counter(topic for topic, _, _ in read) == {f"/highway_s1_{c}{t}": 2 for c in ("morning", "night")
                                                       for t in MCAP_TOPICS}
    for topic in {topic for topic, _, _ in read}:
        mine = [(sequence, time_ns) for t, sequence, time_ns in read if t == topic]
        assert [sequence for sequence, _ in mine] == [0, 1]
        assert mine[0][1] < mine[1][1]


def test_mcap_merges_records_under_prefixes(tmp_path, morning, night):
    out = tmp_path / "both.mcap"
    get_exporter("mcap").export([night, morning], out)
    messages, _, _ = _read_mcap(out)
    topics = Counter(t for _, t, _, _ in messages)
    assert topics == {f"/highway_s1_{c}{t}": 2 for c in ("morning", "night") for t in MCAP_TOPICS}


def test_rosbag2_rosbags_reader_and_mcap_ros2_decoder(tmp_path, morning):
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory
    from rosbags.interfaces import QosDurability
    from rosbags.rosbag2 import Reader

    out = tmp_path / "bag"
    get_exporter("rosbag2").export([morning], out)
    expected = {
        "/tf_static": ("tf2_msgs/msg/TFMessage", 1), "/tf": ("tf2_msgs/msg/TFMessage", 2),
        "/ego/pose": ("geometry_msgs/msg/PoseStamped", 2),
        "/camera/front/image/compressed": ("sensor_msgs/msg/CompressedImage", 2),
        "/camera/front/camera_info": ("sensor_msgs/msg/CameraInfo", 2),
        "/camera/front/detections": ("vision_msgs/msg/Detection2DArray", 2),
        "/lidar/top/points": ("sensor_msgs/msg/PointCloud2", 2),
        "/lidar/top/detections": ("vision_msgs/msg/Detection3DArray", 2),
        "/scene/markers": ("visualization_msgs/msg/MarkerArray", 2),
    }
    with Reader(out) as reader:
        assert {c.topic: (c.msgtype, c.msgcount) for c in reader.connections} == expected
        raw = Counter(c.topic for c, _, _ in reader.messages())
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert raw == {k: n for k, (_, n) in expected.items()}
    assert qos["/tf_static"][0].durability == QosDurability.TRANSIENT_LOCAL
    assert qos["/tf"][0].durability == QosDurability.VOLATILE
    bag = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert bag["storage_identifier"] == "mcap" and bag["message_count"] == 17
    # Format 8: QoS as a YAML string with rmw's integer enums, which Humble's rosbag2 parses (format 9's names not)
    assert bag["version"] == 8
    topics = {t["topic_metadata"]["name"]: t["topic_metadata"] for t in bag["topics_with_message_count"]}
    (latched,) = yaml.safe_load(topics["/tf_static"]["offered_qos_profiles"])
    assert (latched["durability"], latched["history"], latched["depth"]) == (1, 1, 1)  # TRANSIENT_LOCAL, KEEP_LAST

    decoded = {}
    with (out / "bag.mcap").open("rb") as f:
        reader = make_reader(f, decoder_factories=[Ros2DecoderFactory()])
        for _, channel, message, msg in reader.iter_decoded_messages():
            decoded.setdefault(channel.topic, []).append((message.log_time, msg))
    assert {k: len(v) for k, v in decoded.items()} == {k: n for k, (_, n) in expected.items()}
    (_, dets), = [d for d in decoded["/camera/front/detections"] if d[0] == 1_000_000_000]
    labels = DatasetRecord(morning).labels
    car = labels[(labels.frame == 10) & (labels.sensor == "front") & (labels.track_id == 3)].iloc[0]
    by_id = {d.id: d for d in dets.detections}
    assert sorted(by_id) == ["3", "4", "9"]  # kept objects only
    assert by_id["3"].bbox.size_x == pytest.approx(car.x2 - car.x1)
    assert by_id["3"].bbox.center.position.x == pytest.approx((car.x1 + car.x2) / 2)
    assert by_id["3"].results[0].hypothesis.class_id == "car"
    dets3d = decoded["/lidar/top/detections"][0][1]
    assert len(dets3d.detections) == 5 and dets3d.header.frame_id == "top"
    cloud = decoded["/lidar/top/points"][0][1]
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "intensity", "ring", "class", "instance"]
    assert cloud.width == len(DatasetRecord(morning).points("top", 10))
    static = decoded["/tf_static"][0][1]
    assert [x.child_frame_id for x in static.transforms] == ["front", "top"]
    assert static.transforms[1].transform.translation.z == pytest.approx(1.8)
    image = decoded["/camera/front/image/compressed"][0][1]
    assert bytes(image.data) == (morning / "cameras/front/rgb/000010.png").read_bytes()


def test_rosbag2_refuses_lz4(tmp_path, morning):
    from exporters.base import ExportError

    with pytest.raises(ExportError, match="lz4"):
        get_exporter("rosbag2").export([morning], tmp_path / "bag", ExportOptions(compression=Compression.LZ4))
    assert not (tmp_path / "bag").exists()


def _panels(node) -> list[str]:
    return [node] if isinstance(node, str) else _panels(node["first"]) + _panels(node["second"])


def _check_layout(layout: dict, messages: list) -> list[dict]:
    """Every panel of ``layout`` names only topics and frames of the MCAP ``messages``, with what Foxglove needs to
    draw them; returns one {kind: config} per record view (a tab each, or the whole layout)."""
    configs = layout["configById"]
    topics = {t for _, t, _, _ in messages}
    frames = {x.parent_frame_id for _, _, _, m in messages if hasattr(m, "transforms") for x in m.transforms} | {
        x.child_frame_id for _, _, _, m in messages if hasattr(m, "transforms") for x in m.transforms}
    root = layout["layout"]
    if isinstance(root, str) and root.startswith("Tab!"):
        views = [tab["layout"] for tab in configs[root]["tabs"]]
        assert sorted(p for v in views for p in _panels(v)) == sorted(set(configs) - {root})
    else:
        views = [root]
        assert sorted(_panels(root)) == sorted(configs)
    result = []
    for view in views:
        config = {panel.split("!")[0]: configs[panel] for panel in _panels(view)}
        image = config["Image"]["imageMode"]
        assert image["imageTopic"].endswith("/camera/front/image")
        assert {image["imageTopic"], image["calibrationTopic"], *image["annotations"]} <= topics
        assert all(a["visible"] for a in image["annotations"].values())
        scene = config["3D"]
        # the 3D panel subscribes only to topics marked visible; transforms (/tf) are always read
        visible = {t for t, s in scene["topics"].items() if s["visible"]}
        (points,) = [t for t in visible if t.endswith("/lidar/top/points")]
        assert len(visible) == 2 and any(t.endswith("/scene/objects") for t in visible)
        cloud = next(m for _, t, _, m in messages if t == points)
        assert all(s["colorField"] in {f.name for f in cloud.fields} for t, s in scene["topics"].items()
                   if t.endswith("/points"))
        assert set(scene["topics"]) | {config["RawMessages"]["topicPath"]} <= topics
        assert scene["followTf"] in frames and {k.removeprefix("frame:") for k in scene["transforms"]} <= frames
        assert all(key == layer["instanceId"] and layer["frameId"] in frames for key, layer in scene["layers"].items())
        assert config["RawMessages"]["expansion"] in ("all", "none")  # Foxglove's NodeExpansion (or a per-key dict)
        result.append(config)
    return result


def test_foxglove_layout_shows_what_a_single_record_mcap_holds(tmp_path, morning):
    """docs/foxglove_layout.json is the layout the exporter writes beside a single-record MCAP, and names only its
    topics and frames."""
    shipped = json.loads((Path(__file__).resolve().parents[2] / "docs" / "foxglove_layout.json").read_text())
    out = tmp_path / "run.mcap"
    get_exporter("mcap").export([morning], out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.layout.json", "run.mcap"]
    assert json.loads((tmp_path / "run.layout.json").read_text()) == shipped
    messages, _, _ = _read_mcap(out)
    (config,) = _check_layout(shipped, messages)
    image = config["Image"]["imageMode"]
    assert (image["imageTopic"], image["calibrationTopic"]) == ("/camera/front/image", "/camera/front/calibration")
    assert config["3D"]["followTf"] == "ego"


def test_foxglove_layout_of_a_merged_mcap_has_a_tab_per_record(tmp_path, morning, night):
    out = tmp_path / "both.mcap"
    get_exporter("mcap").export([night, morning], out)
    layout = json.loads((tmp_path / "both.layout.json").read_text())
    messages, _, _ = _read_mcap(out)
    configs = _check_layout(layout, messages)
    assert [t["title"] for t in layout["configById"][layout["layout"]]["tabs"]] == [
        "highway_s1_morning", "highway_s1_night"]
    assert [c["3D"]["followTf"] for c in configs] == ["highway_s1_morning/ego", "highway_s1_night/ego"]
    assert [c["Image"]["imageMode"]["imageTopic"] for c in configs] == [
        "/highway_s1_morning/camera/front/image", "/highway_s1_night/camera/front/image"]


@pytest.mark.parametrize("size", [0, 1, 127, 128, 300_000])
def test_bytes_field_on_the_wire_equals_protobuf_serialisation(size):
    """Sweeps and images go on the wire spliced into the rest of their message (no protobuf copies): the same
    bytes as protobuf's, for a last field (PointCloud.data) and one between others (CompressedImage.data)."""
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from google.protobuf.timestamp_pb2 import Timestamp

    from exporters.mcap import _FIELDS, serialized_parts

    def serialize_with_bytes(message, name, payload):
        parts = serialized_parts(message, name, payload)
        assert any(part is payload for part in parts) or not payload  # handed on, not copied
        return b"".join(parts)

    payload = np.random.default_rng(size).bytes(size)
    stamp = Timestamp(seconds=3, nanos=500)
    for message in (PointCloud(timestamp=stamp, frame_id="top", point_stride=24, fields=_FIELDS),
                    CompressedImage(timestamp=stamp, frame_id="front", format="png"),
                    CompressedImage(frame_id="front"), CompressedImage(timestamp=stamp), CompressedImage()):
        whole = type(message)()
        whole.CopyFrom(message)
        whole.data = payload
        assert serialize_with_bytes(message, "data", payload) == whole.SerializeToString(deterministic=True)
    with pytest.raises(ValueError, match="PointCloud.frame_id is not a singular bytes field"):
        serialize_with_bytes(PointCloud(), "frame_id", payload)
    with pytest.raises(ValueError, match="CompressedImage.data is already set"):
        serialize_with_bytes(CompressedImage(data=b"x"), "data", payload)


def test_3d_boxes_live_until_the_next_frame(tmp_path, morning):
    """Cubes and markers hold until the record's next frame, also when frames are unevenly spaced (--frames)."""
    import shutil

    import pandas as pd
    from rosbags.rosbag2 import Reader

    from exporters.ros_types import typestore
    from exporters.source import ExportSource

    copy = tmp_path / "rec"
    shutil.copytree(morning, copy)
    frames = pd.read_parquet(copy / "frames.parquet")
    frames.loc[frames.frame == 11, "time_s"] = 1.35  # frames 10 and 11 now 0.35 s apart
    frames.to_parquet(copy / "frames.parquet", index=False)
    (src,) = ExportSource([copy]).records
    assert [src.hold_ns(f) for f in (10, 11)] == [350_000_000, 350_000_000]  # the last holds as the one before
    get_exporter("mcap").export([copy], tmp_path / "run.mcap")
    messages, _, _ = _read_mcap(tmp_path / "run.mcap")
    lifetimes = {e.lifetime.ToNanoseconds() for _, t, _, m in messages if t == "/scene/objects" for e in m.entities}
    assert lifetimes == {350_000_000}
    get_exporter("rosbag2").export([copy], tmp_path / "bag")
    store = typestore()
    with Reader(tmp_path / "bag") as reader:
        markers = [store.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()
                   if c.topic == "/scene/markers"]
    assert {(m.lifetime.sec, m.lifetime.nanosec) for a in markers for m in a.markers} == {(0, 350_000_000)}
