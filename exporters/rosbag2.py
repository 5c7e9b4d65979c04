"""rosbag2 export (rosbags writer, MCAP storage, CDR messages): ``DIR/metadata.yaml`` + ``DIR/<name>.mcap``.

Topics per record (names and frame ids as in :mod:`exporters.log_common`); stamps are simulation time:

======================================  ======================================  =================================
topic                                   type                                    content
======================================  ======================================  =================================
``/tf_static``                          tf2_msgs/msg/TFMessage                  ego -> sensors, once; QoS
                                                                                transient-local (latched on play)
``/tf``                                 tf2_msgs/msg/TFMessage                  world -> ego per frame
``/ego/pose``                           geometry_msgs/msg/PoseStamped           ego pose in ``world``
``/camera/<name>/image/compressed``     sensor_msgs/msg/CompressedImage         the record's PNG, byte for byte
``/camera/<name>/camera_info``          sensor_msgs/msg/CameraInfo              K, P = [K|0], plumb_bob
``/camera/<name>/detections``           vision_msgs/msg/Detection2DArray        2D boxes (``--box``), class id =
                                                                                our class, id = track id
``/lidar/<name>/points``                sensor_msgs/msg/PointCloud2             x, y, z, intensity, ring,
                                                                                class, instance (24-byte points)
``/lidar/<name>/detections``            vision_msgs/msg/Detection3DArray        3D boxes in the LiDAR frame
``/radar/<name>/points``                sensor_msgs/msg/PointCloud2             the scan's detections, every
                                                                                record column (48-byte points)
``/radar/<name>/scan``                  radar_msgs/msg/RadarScan                range, azimuth, elevation,
                                                                                doppler_velocity (radial,
                                                                                negative = approaching),
                                                                                amplitude (= SNR, dB)
``/scene/markers``                      visualization_msgs/msg/MarkerArray      a cube per object (``world``)
======================================  ======================================  =================================

Chunk compression zstd (level 1) by default, or none (rosbags' MCAP storage has no lz4); chunks are
compressed and written on a worker thread while the next messages are built, in order, so the bag's
bytes do not depend on timing. ``custom_data`` in metadata.yaml holds the export description.
vision_msgs and radar_msgs come from :mod:`exporters.ros_types`.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from tqdm import tqdm

from exporters.base import Compression, Exporter, ExportError, ExportOptions
from exporters.log_common import FrameData, FrameRows, Naming, frames_with_data, nanoseconds
from exporters.ros_messages import RosMessages
from exporters.source import ExportSource, FrameItem
from exporters.writing import OrderedCalls, dumps_json, ordered_calls, zstd_compressor

log = logging.getLogger(__name__)

BAG_VERSION = 8
QUEUE_BYTES = 2 << 20  # messages waiting for the writer thread, at most (rosbags' chunks are 1 MiB)


def _qos(transient_local: bool):
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    zero = QosTime(0, 0)
    return Qos(QosHistory.KEEP_LAST, 1 if transient_local else 10, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE, zero, zero,
               QosLiveliness.AUTOMATIC, zero, False)


class _Bag:
    """Adds one connection per topic on first use; messages are serialised here and held in ``calls`` (the
    writer's thread) until the caller flushes it, once per frame (:meth:`OrderedCalls.add`). Adding a
    connection waits for that thread to catch up, as the rosbags Writer is never used from two threads at once."""

    def __init__(self, writer: Any, calls: OrderedCalls, msgs: RosMessages) -> None:
        self.writer = writer
        self.calls = calls
        self.store = msgs.store
        self.connections: dict[str, Any] = {}
        self.counts: dict[str, int] = {}

    def write(self, topic: str, msgtype: str, msg: Any, time_ns: int, latched: bool = False) -> None:
        if topic not in self.connections:
            self.calls.drain()
            self.connections[topic] = self.writer.add_connection(topic, msgtype, typestore=self.store,
                                                                 offered_qos_profiles=[_qos(latched)])
            self.counts[topic] = 0
        data = self.store.serialize_cdr(msg, msgtype)
        self.calls.add(len(data), self.writer.write, self.connections[topic], time_ns, data)
        self.counts[topic] += 1


class Rosbag2Exporter(Exporter):
    name = "rosbag2"
    creates_own_dir = True

    def check(self, source: ExportSource, options: ExportOptions) -> None:
        if options.compression is Compression.LZ4:
            raise ExportError("rosbag2 (rosbags MCAP storage) compresses with zstd or none, not lz4")

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

        msgs = RosMessages()
        # Bag format 8, which every ROS 2 distribution from Humble on reads: format 9 (Jazzy) stores QoS profiles
        # in a form Humble's rosbag2 fails to parse (ros2/rosbag2#1476), and later ones still read 8.
        writer = Writer(tmp, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        if options.compression is Compression.ZSTD:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        writer.open()
        if options.compression is Compression.ZSTD:
            # rosbags' MCAP storage compresses each chunk with this callable (zstd level 3) and has no option.
            if hasattr(writer.storage, "compressor"):
                writer.storage.compressor = zstd_compressor().compress
            else:  # a rosbags release that compresses otherwise: its own level
                log.warning("rosbags: cannot set the zstd level; chunks use the library's default")
        try:
            rows = {id(s): FrameRows(s, options, msgs.summary) for s in source.records}
            with ordered_calls(QUEUE_BYTES, "rosbag2-writer") as calls:
                bag = _Bag(writer, calls, msgs)
                for src in source.records:
                    names, first = Naming(src, source), src.frames["time_s"].iloc[0]
                    bag.write(names.topic("/tf_static"), "tf2_msgs/msg/TFMessage", msgs.tf_static(src, names),
                              nanoseconds(first), latched=True)
                for item, data in tqdm(frames_with_data(source), total=source.n_frames(), desc="rosbag2",
                                       unit="frame", disable=not options.progress):
                    for topic, msgtype, msg in self._frame(msgs, item, data, Naming(item.source, source),
                                                           rows[id(item.source)]):
                        bag.write(topic, msgtype, msg, nanoseconds(item.time_s))
                    calls.flush()
            summary = {"frames": source.n_frames(), "messages": dict(sorted(bag.counts.items())),
                       "objects": msgs.summary.to_dict()}
            writer.set_custom_data("roadsynth.export", dumps_json({**description, "counts": summary}, indent=None))
            writer.close()
        except BaseException:
            writer.abort()
            raise
        return summary

    @staticmethod
    def _frame(msgs: RosMessages, item: FrameItem, data: FrameData, names: Naming, rows: FrameRows):
        t = nanoseconds(item.time_s)
        info = item.source.info
        yield names.topic("/tf"), "tf2_msgs/msg/TFMessage", msgs.tf(item, names, t)
        yield names.topic("/ego/pose"), "geometry_msgs/msg/PoseStamped", msgs.ego_pose(item, names, t)
        for cam in info.cameras:
            yield (names.topic(f"/camera/{cam.name}/image/compressed"), "sensor_msgs/msg/CompressedImage",
                   msgs.image(data.images[cam.name], names.frame(cam.name), t))
            yield (names.topic(f"/camera/{cam.name}/camera_info"), "sensor_msgs/msg/CameraInfo",
                   msgs.camera_info(cam, names.frame(cam.name), t))
            yield (names.topic(f"/camera/{cam.name}/detections"), "vision_msgs/msg/Detection2DArray",
                   msgs.detections_2d(rows.sensor(item.frame, cam.name), names.frame(cam.name), t))
        for lidar in info.lidars:
            yield (names.topic(f"/lidar/{lidar.name}/points"), "sensor_msgs/msg/PointCloud2",
                   msgs.point_cloud(data.points[lidar.name], names.frame(lidar.name), t))
            yield (names.topic(f"/lidar/{lidar.name}/detections"), "vision_msgs/msg/Detection3DArray",
                   msgs.detections_3d(rows.sensor(item.frame, lidar.name), names.frame(lidar.name), t))
        for radar in info.radars:
            yield (names.topic(f"/radar/{radar.name}/points"), "sensor_msgs/msg/PointCloud2",
                   msgs.radar_cloud(data.radars[radar.name], names.frame(radar.name), t))
            yield (names.topic(f"/radar/{radar.name}/scan"), "radar_msgs/msg/RadarScan",
                   msgs.radar_scan(data.radars[radar.name], names.frame(radar.name), t))
        yield (names.topic("/scene/markers"), "visualization_msgs/msg/MarkerArray",
               msgs.markers(rows.objects(item.frame), names.frame("world"), t, item.source.hold_ns(item.frame)))


EXPORTER = Rosbag2Exporter()
