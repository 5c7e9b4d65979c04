"""MCAP export with Foxglove protobuf schemas: one file that opens in Foxglove with everything visible.

Chunked, zstd (level 1) by default (``--compression lz4|none``); every message's log and publish time is
the simulation time of its frame (nanoseconds). Frames are read one or two ahead on a loader thread, and
full chunks are compressed on worker threads while the next fill (:mod:`exporters.mcap_writer`: mcap's
records, written in order, so the file's bytes do not depend on timing). Channels per record (names:
:mod:`exporters.log_common`):

=================================  ==========================  ==========================================
topic                              schema                      content
=================================  ==========================  ==========================================
``/tf``                            foxglove.FrameTransforms    world -> ego, ego -> every sensor
``/ego/pose``                      foxglove.PoseInFrame        ego box centre and yaw in ``world``
``/camera/<name>/image``           foxglove.CompressedImage    the record's RGB PNG, byte for byte
``/camera/<name>/calibration``     foxglove.CameraCalibration  K, P = [K|0], plumb_bob distortion
``/camera/<name>/annotations``     foxglove.ImageAnnotations   2D boxes (line loops) with class/track text
``/lidar/<name>/points``           foxglove.PointCloud         x, y, z, intensity, ring, class, instance
``/radar/<name>/detections``       foxglove.PointCloud         x, y, z, range, azimuth, elevation,
                                                               radial_velocity(_comp), rcs, snr, instance,
                                                               class (record units; negative velocity =
                                                               approaching)
``/scene/objects``                 foxglove.SceneUpdate        a cube per object coloured by class
=================================  ==========================  ==========================================

Metadata records: ``roadsynth.export`` (options, records, split assignment, counts), one
``roadsynth.record.<stem>`` per record (its ``record.json`` and ``meta.json`` verbatim) and, when the
stage passes one, ``roadsynth.meta``. Image boxes follow ``--box`` and the object filter (ignore
regions are drawn translucent). Beside ``FILE.mcap`` goes ``FILE.layout.json``, the Foxglove layout of this
file (:mod:`exporters.foxglove_layout`): the camera with its boxes, a 3D view with points, radar detections
(coloured by radial velocity) and cubes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import mcap
import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.duration_pb2 import Duration
from google.protobuf.timestamp_pb2 import Timestamp
from mcap_protobuf.schema import register_schema
from tqdm import tqdm

from exporters.base import Exporter, ExportOptions
from exporters.filters import HIDDEN, KEPT, FilterSummary
from exporters.foxglove_layout import RecordView, layout, layout_path
from exporters.log_common import (
    CLASS_COLORS,
    DEFAULT_COLOR,
    POINT_FIELDS,
    POINT_STRIDE,
    RADAR_FIELDS,
    RADAR_STRIDE,
    FrameData,
    FrameRows,
    Naming,
    frames_with_data,
    nanoseconds,
    quat_from_matrix,
    quat_from_yaw,
    split_ns,
)
from exporters.mcap_writer import PipelinedWriter, payload_size
from exporters.source import ExportSource, FrameItem, RecordSource
from exporters.writing import dumps_json

# A chunk is sealed once it exceeds this: about one frame of the default rig (0.75 MB PNG + 2.4 MB sweep) per
# chunk: faster than two frames per chunk (4 MB) for the same file size (docs/performance.md).
CHUNK_SIZE = 2 << 20
COMPRESS_WORKERS = 2  # threads compressing chunks while the next fill (each chunk by one thread)
_NUMERIC = {"<f4": PackedElementField.FLOAT32, "<u2": PackedElementField.UINT16, "u1": PackedElementField.UINT8,
            "<i4": PackedElementField.INT32}
_FIELDS = [PackedElementField(name=n, offset=o, type=_NUMERIC[t]) for n, o, t in POINT_FIELDS]
_RADAR_FIELDS = [PackedElementField(name=n, offset=o, type=_NUMERIC[t]) for n, o, t in RADAR_FIELDS]


def _stamp(time_ns: int) -> Timestamp:
    sec, nsec = split_ns(time_ns)
    return Timestamp(seconds=sec, nanos=nsec)


_WHITE = Color(r=1, g=1, b=1, a=1)


def _color(cls: str, alpha: float | None = None) -> Color:
    r, g, b, a = CLASS_COLORS.get(cls, DEFAULT_COLOR)
    return Color(r=r, g=g, b=b, a=a if alpha is None else alpha)


def _pose(matrix: np.ndarray) -> Pose:
    x, y, z, w = quat_from_matrix(matrix[:3, :3])
    return Pose(position=Vector3(x=float(matrix[0, 3]), y=float(matrix[1, 3]), z=float(matrix[2, 3])),
                orientation=Quaternion(x=x, y=y, z=z, w=w))


def _yaw_pose(x: float, y: float, z: float, yaw: float) -> Pose:
    pose = Pose()
    _set_yaw_pose(pose, x, y, z, yaw)
    return pose


def _set_yaw_pose(pose: Pose, x: float, y: float, z: float, yaw: float) -> None:
    pose.position.x, pose.position.y, pose.position.z = float(x), float(y), float(z)
    pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = quat_from_yaw(yaw)


def _varint(value: int) -> bytes:
    out = bytearray()
    while value > 0x7F:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def serialized_parts(message: Any, name: str, payload: bytes | memoryview) -> list[bytes | memoryview]:
    """``message`` serialised with its bytes field ``name`` (unset in ``message``) holding ``payload``, as parts
    whose join is byte for byte what ``SerializeToString(deterministic=True)`` gives with the field set;
    ``payload`` is one of them, uncopied.

    Fields go out in number order, so the field is spliced in after those numbered below it; an empty proto3
    bytes field is not written. Protobuf would copy the payload twice (setting, then serialising); the MCAP
    writer joins the parts into its chunk, the one copy left.
    """
    field = message.DESCRIPTOR.fields_by_name[name]
    value = getattr(message, name)
    if field.type != field.TYPE_BYTES or not isinstance(value, bytes):  # a repeated field is a container
        raise ValueError(f"{message.DESCRIPTOR.full_name}.{name} is not a singular bytes field")
    if value:
        raise ValueError(f"{message.DESCRIPTOR.full_name}.{name} is already set")
    whole = message.SerializeToString(deterministic=True)
    if not payload:
        return [whole]
    head = len(whole)
    later = [f.name for f, _ in message.ListFields() if f.number > field.number]
    if later:
        first = type(message)()
        first.CopyFrom(message)
        for other in later:
            first.ClearField(other)
        head = first.ByteSize()
    return [whole[:head] + _varint(field.number << 3 | 2) + _varint(payload_size(payload)), payload, whole[head:]]


class _Log:
    """Registers one schema per message type and one channel per topic on first use, and counts messages."""

    def __init__(self, writer: PipelinedWriter) -> None:
        self.writer = writer
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}

    def write(self, topic: str, message: Any, time_ns: int,
              big_bytes: tuple[str, bytes | memoryview] | None = None) -> None:
        """Log ``message`` on ``topic``; ``big_bytes`` = (field, payload) sets a large bytes field on the wire
        instead (see :func:`serialized_parts`)."""
        if topic not in self.channels:
            name = type(message).DESCRIPTOR.full_name
            if name not in self.schemas:
                self.schemas[name] = register_schema(self.writer, type(message))
            self.channels[topic] = self.writer.register_channel(topic, "protobuf", self.schemas[name])
            self.counts[topic] = 0
        if big_bytes is None:
            data: bytes | list[bytes | memoryview] = message.SerializeToString(deterministic=True)
        else:
            data = serialized_parts(message, *big_bytes)
        self.writer.add_message(self.channels[topic], log_time=time_ns, publish_time=time_ns, data=data,
                                sequence=self.counts[topic])
        self.counts[topic] += 1


class McapExporter(Exporter):
    name = "mcap"
    writes_file = True

    def companions(self, source: ExportSource, out: Path) -> dict[Path, str]:
        """The Foxglove layout of this file (:mod:`exporters.foxglove_layout`), beside it."""
        views = []
        for src in source.records:
            names, info = Naming(src, source), src.info
            views.append(RecordView(src.stem, names.prefix, info.cameras[0].name if info.cameras else None,
                                    tuple(lidar.name for lidar in info.lidars),
                                    tuple(radar.name for radar in info.radars)))
        return {layout_path(out): dumps_json(layout(views))}

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        summary = FilterSummary()
        with tmp.open("wb") as stream, PipelinedWriter(stream, chunk_size=CHUNK_SIZE, compression=options.compression,
                                                       workers=COMPRESS_WORKERS) as writer:
            writer.start(profile="", library=f"roadsynth exporters; mcap {mcap.__version__}")
            records = {id(s): _RecordMessages(s, Naming(s, source), FrameRows(s, options, summary))
                       for s in source.records}
            out = _Log(writer)
            for item, data in tqdm(frames_with_data(source), total=source.n_frames(), desc="mcap", unit="frame",
                                   disable=not options.progress):
                records[id(item.source)].frame(out, item, data)
            counts = {"frames": source.n_frames(), "messages": dict(sorted(out.counts.items())),
                      "objects": summary.to_dict()}
            for src in source.records:
                files = {"record.json": src.info.to_json()}
                if src.meta_text is not None:
                    files["meta.json"] = src.meta_text
                writer.add_metadata(f"roadsynth.record.{src.stem}", files)
            writer.add_metadata("roadsynth.export", {"export.json": dumps_json({**description, "counts": counts})})
            if meta is not None:
                writer.add_metadata("roadsynth.meta", {"meta.json": dumps_json(meta)})
            writer.finish()
        return counts


class _RecordMessages:
    """Builds the messages of one record's frames.

    What does not change from frame to frame (sensor mounts, calibrations, point layouts, frame ids) is built
    once, as messages whose time stamp is set before each use; a frame's messages are serialised as soon as
    they are built (:meth:`_Log.write`), so reusing them is safe. Objects are added in place
    (``repeated.add``) rather than built and then copied into their parent.
    """

    def __init__(self, source: RecordSource, names: Naming, rows: FrameRows) -> None:
        info = source.info
        self.source, self.rows = source, rows
        self.world, self.ego = names.frame("world"), names.frame("ego")
        self.topics = {key: names.topic(key) for key in ("/tf", "/ego/pose", "/scene/objects")}
        self.mounts = [(names.frame(s.name), _pose(s.T_array)) for s in [*info.cameras, *info.lidars, *info.radars]]
        self.cameras = []
        for cam in info.cameras:
            k = cam.K_array
            calibration = CameraCalibration(
                frame_id=names.frame(cam.name), width=cam.width_px, height=cam.height_px, distortion_model="plumb_bob",
                D=[float(v) for v in cam.distortion], K=k.reshape(-1).tolist(), R=np.eye(3).reshape(-1).tolist(),
                P=np.hstack([k, np.zeros((3, 1))]).reshape(-1).tolist())
            self.cameras.append((cam.name, names.frame(cam.name), names.topic(f"/camera/{cam.name}/image"),
                                 names.topic(f"/camera/{cam.name}/calibration"), calibration,
                                 names.topic(f"/camera/{cam.name}/annotations")))
        self.lidars = [(lidar.name, names.topic(f"/lidar/{lidar.name}/points"),
                        PointCloud(frame_id=names.frame(lidar.name), pose=_yaw_pose(0, 0, 0, 0),
                                   point_stride=POINT_STRIDE, fields=_FIELDS)) for lidar in info.lidars]
        self.radars = [(radar.name, names.topic(f"/radar/{radar.name}/detections"),
                        PointCloud(frame_id=names.frame(radar.name), pose=_yaw_pose(0, 0, 0, 0),
                                   point_stride=RADAR_STRIDE, fields=_RADAR_FIELDS)) for radar in info.radars]

    def frame(self, out: _Log, item: FrameItem, data: FrameData) -> None:
        t = nanoseconds(item.time_s)
        stamp = _stamp(t)
        row = item.row
        world_ego = _yaw_pose(row.ego_x_m, row.ego_y_m, row.ego_z_m, row.ego_yaw_rad)
        tf = FrameTransforms()
        tf.transforms.add(timestamp=stamp, parent_frame_id=self.world, child_frame_id=self.ego,
                          translation=world_ego.position, rotation=world_ego.orientation)
        for child, pose in self.mounts:
            tf.transforms.add(timestamp=stamp, parent_frame_id=self.ego, child_frame_id=child,
                              translation=pose.position, rotation=pose.orientation)
        out.write(self.topics["/tf"], tf, t)
        out.write(self.topics["/ego/pose"], PoseInFrame(timestamp=stamp, frame_id=self.world, pose=world_ego), t)
        for name, frame_id, image_topic, calibration_topic, calibration, annotations_topic in self.cameras:
            out.write(image_topic, CompressedImage(timestamp=stamp, frame_id=frame_id, format="png"), t,
                      big_bytes=("data", data.images[name]))
            calibration.timestamp.CopyFrom(stamp)
            out.write(calibration_topic, calibration, t)
            out.write(annotations_topic, _annotations(self.rows.sensor(item.frame, name), stamp), t)
        for name, topic, cloud in self.lidars:
            cloud.timestamp.CopyFrom(stamp)
            out.write(topic, cloud, t, big_bytes=("data", data.points[name]))
        for name, topic, cloud in self.radars:
            cloud.timestamp.CopyFrom(stamp)
            out.write(topic, cloud, t, big_bytes=("data", data.radars[name]))
        out.write(self.topics["/scene/objects"], _scene(self.rows.objects(item.frame), stamp, self.world,
                                                        self.source.hold_ns(item.frame)), t)


def _annotations(rows: list[dict], stamp: Timestamp) -> ImageAnnotations:
    msg = ImageAnnotations()
    for row in rows:
        reason, cls, track = row["reason"], row["cls"], row["track_id"]
        if reason == HIDDEN or not row["box_finite"]:
            continue
        x1, y1, x2, y2 = row["box"].tolist()
        alpha = 1.0 if reason == KEPT else 0.35
        loop = msg.points.add(timestamp=stamp, type=PointsAnnotation.LINE_LOOP, thickness=2.0)
        for x, y in ((x1, y1), (x2, y1), (x2, y2), (x1, y2)):
            loop.points.add(x=x, y=y)
        loop.outline_color.CopyFrom(_color(cls, alpha))
        text = f"{cls} {track}" + ("" if reason == KEPT else f" ({reason})")
        label = msg.texts.add(timestamp=stamp, text=text, font_size=12.0)
        label.position.x, label.position.y = x1, max(y1 - 2.0, 0.0)
        label.text_color.CopyFrom(_WHITE)
        label.background_color.CopyFrom(_color(cls, 0.7 * alpha))
    return msg


def _scene(objects: list[dict], stamp: Timestamp, world: str, lifetime_ns: int) -> SceneUpdate:
    update = SceneUpdate()
    lifetime = Duration(seconds=lifetime_ns // 1_000_000_000, nanos=lifetime_ns % 1_000_000_000)
    for o in objects:
        track, cls = int(o["track_id"]), o["cls"]
        x, y, z, height = float(o["x_m"]), float(o["y_m"]), float(o["z_m"]), float(o["height_m"])
        entity = update.entities.add(timestamp=stamp, frame_id=world, id=f"track-{track}", lifetime=lifetime)
        entity.metadata.add(key="track_id", value=str(track))
        entity.metadata.add(key="class", value=cls)
        cube = entity.cubes.add()
        _set_yaw_pose(cube.pose, x, y, z, o["yaw_rad"])
        cube.size.x, cube.size.y, cube.size.z = float(o["length_m"]), float(o["width_m"]), height
        cube.color.CopyFrom(_color(cls))
        label = entity.texts.add(billboard=True, font_size=14.0, scale_invariant=True, text=f"{cls} {track}")
        _set_yaw_pose(label.pose, x, y, z + height / 2 + 0.5, 0.0)
        label.color.CopyFrom(_WHITE)
    return update


EXPORTER = McapExporter()
