"""MCAP export with Foxglove protobuf schemas: one file that opens in Foxglove with everything visible.

Chunked, zstd (level 1) by default (``--compression lz4|none``); every message's log and publish time is
the simulation time of its frame (nanoseconds). Frames are read one or two ahead on a loader thread and
chunks are compressed and written on a writer thread, in order, so the file's bytes do not depend on
timing. Channels per record (names: :mod:`exporters.scene`):

=================================  ==========================  ==========================================
topic                              schema                      content
=================================  ==========================  ==========================================
``/tf``                            foxglove.FrameTransforms    world -> ego, ego -> every sensor
``/ego/pose``                      foxglove.PoseInFrame        ego box centre and yaw in ``world``
``/camera/<name>/image``           foxglove.CompressedImage    the record's RGB PNG, byte for byte
``/camera/<name>/calibration``     foxglove.CameraCalibration  K, P = [K|0], plumb_bob distortion
``/camera/<name>/annotations``     foxglove.ImageAnnotations   2D boxes (line loops) with class/track text
``/lidar/<name>/points``           foxglove.PointCloud         x, y, z, intensity, ring, class, instance
``/scene/objects``                 foxglove.SceneUpdate        a cube per object coloured by class
=================================  ==========================  ==========================================

Metadata records: ``roadsynth.export`` (options, records, split assignment, counts), one
``roadsynth.record.<stem>`` per record (its ``record.json`` and ``meta.json`` verbatim) and, when the
stage passes one, ``roadsynth.meta``. Image boxes follow ``--box`` and the object filter (ignore
regions are drawn translucent). Beside ``FILE.mcap`` goes ``FILE.layout.json``, the Foxglove layout of this
file (:mod:`exporters.foxglove_layout`): the camera with its boxes, a 3D view with points and cubes.
"""

from __future__ import annotations

import contextlib
import logging
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import mcap
import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.Point2_pb2 import Point2
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.TextAnnotation_pb2 import TextAnnotation
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.duration_pb2 import Duration
from google.protobuf.timestamp_pb2 import Timestamp
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import register_schema
from tqdm import tqdm

from exporters.base import Compression, Exporter, ExportOptions
from exporters.filters import HIDDEN, KEPT, FilterSummary
from exporters.foxglove_layout import RecordView, layout, layout_path
from exporters.io import ZSTD_LEVEL, OrderedCalls, dumps_json, ordered_calls
from exporters.scene import (
    CLASS_COLORS,
    DEFAULT_COLOR,
    POINT_FIELDS,
    POINT_STRIDE,
    FrameData,
    FrameRows,
    Naming,
    frames_with_data,
    nanoseconds,
    quat_from_matrix,
    quat_from_yaw,
    split_ns,
)
from exporters.source import ExportSource, FrameItem

log = logging.getLogger(__name__)

CHUNK_SIZE = 4 << 20  # bytes; a few camera frames per chunk
QUEUE_BYTES = 2 * CHUNK_SIZE  # messages waiting for the writer thread, at most
_COMPRESSION = {Compression.ZSTD: CompressionType.ZSTD, Compression.LZ4: CompressionType.LZ4,
                Compression.NONE: CompressionType.NONE}
_NUMERIC = {"<f4": PackedElementField.FLOAT32, "<u2": PackedElementField.UINT16, "u1": PackedElementField.UINT8,
            "<i4": PackedElementField.INT32}
_FIELDS = [PackedElementField(name=n, offset=o, type=_NUMERIC[t]) for n, o, t in POINT_FIELDS]


def _stamp(time_ns: int) -> Timestamp:
    sec, nsec = split_ns(time_ns)
    return Timestamp(seconds=sec, nanos=nsec)


def _color(cls: str, alpha: float | None = None) -> Color:
    r, g, b, a = CLASS_COLORS.get(cls, DEFAULT_COLOR)
    return Color(r=r, g=g, b=b, a=a if alpha is None else alpha)


def _pose(matrix: np.ndarray) -> Pose:
    x, y, z, w = quat_from_matrix(matrix[:3, :3])
    return Pose(position=Vector3(x=float(matrix[0, 3]), y=float(matrix[1, 3]), z=float(matrix[2, 3])),
                orientation=Quaternion(x=x, y=y, z=z, w=w))


def _yaw_pose(x: float, y: float, z: float, yaw: float) -> Pose:
    qx, qy, qz, qw = quat_from_yaw(yaw)
    return Pose(position=Vector3(x=float(x), y=float(y), z=float(z)), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _varint(value: int) -> bytes:
    out = bytearray()
    while value > 0x7F:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _append_bytes_field(serialized: bytes, message: Any, name: str, payload: bytes) -> bytes:
    """``serialized`` (``message`` without field ``name``) followed by that bytes field holding ``payload``.

    When ``name`` is the message's highest-numbered field this is byte for byte what
    ``SerializeToString(deterministic=True)`` gives with the field set (fields go out in number order; an
    empty proto3 bytes field is not written), without the two copies protobuf makes of the payload
    (setting, then serialising): ~6 ms of a 2.4 MB LiDAR sweep's ~6.5 ms.
    """
    field = message.DESCRIPTOR.fields_by_name[name]
    if field.type != field.TYPE_BYTES or field.number != max(f.number for f in message.DESCRIPTOR.fields):
        raise ValueError(f"{message.DESCRIPTOR.full_name}.{name} is not the message's last field of type bytes")
    if not payload:
        return serialized
    return b"".join((serialized, _varint(field.number << 3 | 2), _varint(len(payload)), payload))


class _Log:
    """Registers one schema per message type and one channel per topic on first use.

    Messages are serialised here and held in ``calls`` (the writer's thread) until the caller flushes it, once
    per frame (:meth:`OrderedCalls.add`). A registration waits for that thread to catch up, as the Writer is
    never used from two threads at once; the writer's calls are the same, in the same order, as writing each
    message directly.
    """

    def __init__(self, writer: Writer, calls: OrderedCalls) -> None:
        self.writer = writer
        self.calls = calls
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}

    def write(self, topic: str, message: Any, time_ns: int, last_bytes: tuple[str, bytes] | None = None) -> None:
        """Log ``message`` on ``topic``; ``last_bytes`` = (field, payload) sets a large bytes field on the wire
        instead (see :func:`_append_bytes_field`)."""
        if topic not in self.channels:
            self.calls.drain()
            name = type(message).DESCRIPTOR.full_name
            if name not in self.schemas:
                self.schemas[name] = register_schema(self.writer, type(message))
            self.channels[topic] = self.writer.register_channel(topic, "protobuf", self.schemas[name])
            self.counts[topic] = 0
        data = message.SerializeToString(deterministic=True)
        if last_bytes is not None:
            data = _append_bytes_field(data, message, *last_bytes)
        self.calls.add(len(data), self.writer.add_message, self.channels[topic], log_time=time_ns,
                       publish_time=time_ns, data=data, sequence=self.counts[topic])
        self.counts[topic] += 1


@contextlib.contextmanager
def _zstd_level(level: int) -> Iterator[None]:
    """Make mcap's Writer compress chunks at ``level``.

    The mcap library calls ``zstandard.compress`` (level 3) and offers no option. On the benchmark record
    level 1 takes half the CPU time of level 3 (8 vs 16 ms per frame) for a file of the same size (within
    2%). It runs single-threaded: chunks are compressed on the writer thread (:class:`_Log`), which already
    overlaps the message building, and zstd's own workers only added CPU time on two cores. The output
    for a fixed level is deterministic. The swap is scoped to one export.
    """
    import mcap.writer as mcap_writer
    import zstandard

    original = getattr(mcap_writer, "zstandard", None)
    if getattr(original, "compress", None) is None:  # an mcap release that compresses otherwise: its own level
        log.warning("mcap %s: cannot set the zstd level; chunks use the library's default", mcap.__version__)
        yield
        return
    compressor = zstandard.ZstdCompressor(level=level)
    mcap_writer.zstandard = types.SimpleNamespace(compress=compressor.compress)
    try:
        yield
    finally:
        mcap_writer.zstandard = original


class McapExporter(Exporter):
    name = "mcap"
    writes_file = True

    def companions(self, source: ExportSource, out: Path) -> dict[Path, str]:
        """The Foxglove layout of this file (:mod:`exporters.foxglove_layout`), beside it."""
        views = []
        for src in source.records:
            names, info = Naming(src, source), src.info
            views.append(RecordView(src.stem, names.prefix, info.cameras[0].name if info.cameras else None,
                                    tuple(lidar.name for lidar in info.lidars)))
        return {layout_path(out): dumps_json(layout(views))}

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        summary = FilterSummary()
        with tmp.open("wb") as stream, _zstd_level(ZSTD_LEVEL):
            writer = Writer(stream, chunk_size=CHUNK_SIZE, compression=_COMPRESSION[options.compression])
            writer.start(profile="", library=f"roadsynth exporters; mcap {mcap.__version__}")
            rows = {id(s): FrameRows(s, options, summary) for s in source.records}
            with ordered_calls(QUEUE_BYTES, "mcap-writer") as calls:
                out = _Log(writer, calls)
                for item, data in tqdm(frames_with_data(source), total=source.n_frames(), desc="mcap",
                                       unit="frame", disable=not options.progress):
                    self._frame(out, item, data, Naming(item.source, source), rows[id(item.source)])
                    calls.flush()
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

    def _frame(self, out: _Log, item: FrameItem, data: FrameData, names: Naming, rows: FrameRows) -> None:
        t = nanoseconds(item.time_s)
        stamp = _stamp(t)
        info, row = item.source.info, item.row
        world_ego = _yaw_pose(row.ego_x_m, row.ego_y_m, row.ego_z_m, row.ego_yaw_rad)
        transforms = [FrameTransform(timestamp=stamp, parent_frame_id=names.frame("world"),
                                     child_frame_id=names.frame("ego"), translation=world_ego.position,
                                     rotation=world_ego.orientation)]
        for sensor in [*info.cameras, *info.lidars]:
            pose = _pose(sensor.T_array)
            transforms.append(FrameTransform(timestamp=stamp, parent_frame_id=names.frame("ego"),
                                             child_frame_id=names.frame(sensor.name), translation=pose.position,
                                             rotation=pose.orientation))
        out.write(names.topic("/tf"), FrameTransforms(transforms=transforms), t)
        out.write(names.topic("/ego/pose"),
                  PoseInFrame(timestamp=stamp, frame_id=names.frame("world"), pose=world_ego), t)
        for cam in info.cameras:
            frame_id = names.frame(cam.name)
            out.write(names.topic(f"/camera/{cam.name}/image"),
                      CompressedImage(timestamp=stamp, frame_id=frame_id, data=data.images[cam.name], format="png"), t)
            k = cam.K_array
            p = np.hstack([k, np.zeros((3, 1))])
            out.write(names.topic(f"/camera/{cam.name}/calibration"), CameraCalibration(
                timestamp=stamp, frame_id=frame_id, width=cam.width_px, height=cam.height_px,
                distortion_model="plumb_bob", D=[float(v) for v in cam.distortion], K=k.reshape(-1).tolist(),
                R=np.eye(3).reshape(-1).tolist(), P=p.reshape(-1).tolist()), t)
            out.write(names.topic(f"/camera/{cam.name}/annotations"),
                      self._annotations(rows.sensor(item.frame, cam.name), stamp), t)
        for lidar in info.lidars:
            out.write(names.topic(f"/lidar/{lidar.name}/points"), PointCloud(
                timestamp=stamp, frame_id=names.frame(lidar.name), pose=_yaw_pose(0, 0, 0, 0),
                point_stride=POINT_STRIDE, fields=_FIELDS), t, last_bytes=("data", data.points[lidar.name]))
        out.write(names.topic("/scene/objects"), self._scene(rows.objects(item.frame), stamp, names,
                                                             item.source.hold_ns(item.frame)), t)

    @staticmethod
    def _annotations(rows: list[dict], stamp: Timestamp) -> ImageAnnotations:
        msg = ImageAnnotations()
        for row in rows:
            reason, cls, track = row["reason"], row["cls"], row["track_id"]
            if reason == HIDDEN or not np.all(np.isfinite(row["box"])):
                continue
            x1, y1, x2, y2 = (float(v) for v in row["box"])
            alpha = 1.0 if reason == KEPT else 0.35
            corners = [Point2(x=x1, y=y1), Point2(x=x2, y=y1), Point2(x=x2, y=y2), Point2(x=x1, y=y2)]
            msg.points.append(PointsAnnotation(timestamp=stamp, type=PointsAnnotation.LINE_LOOP, points=corners,
                                               outline_color=_color(cls, alpha), thickness=2.0))
            text = f"{cls} {track}" + ("" if reason == KEPT else f" ({reason})")
            msg.texts.append(TextAnnotation(timestamp=stamp, position=Point2(x=x1, y=max(y1 - 2.0, 0.0)), text=text,
                                            font_size=12.0, text_color=Color(r=1, g=1, b=1, a=1),
                                            background_color=_color(cls, 0.7 * alpha)))
        return msg

    @staticmethod
    def _scene(objects: list[dict], stamp: Timestamp, names: Naming, lifetime_ns: int) -> SceneUpdate:
        update = SceneUpdate()
        for o in objects:
            track, cls = int(o["track_id"]), o["cls"]
            pose = _yaw_pose(o["x_m"], o["y_m"], o["z_m"], o["yaw_rad"])
            label_pose = _yaw_pose(o["x_m"], o["y_m"], o["z_m"] + o["height_m"] / 2 + 0.5, 0.0)
            update.entities.append(SceneEntity(
                timestamp=stamp, frame_id=names.frame("world"), id=f"track-{track}",
                lifetime=Duration(seconds=lifetime_ns // 1_000_000_000, nanos=lifetime_ns % 1_000_000_000),
                metadata=[KeyValuePair(key="track_id", value=str(track)), KeyValuePair(key="class", value=cls)],
                cubes=[CubePrimitive(pose=pose, size=Vector3(x=o["length_m"], y=o["width_m"], z=o["height_m"]),
                                     color=_color(cls))],
                texts=[TextPrimitive(pose=label_pose, billboard=True, font_size=14.0, scale_invariant=True,
                                     color=Color(r=1, g=1, b=1, a=1), text=f"{cls} {track}")]))
        return update


EXPORTER = McapExporter()
