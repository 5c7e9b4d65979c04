"""Builders of the ROS 2 messages of the rosbag2 export, one method per message, from record data.

Messages are rosbags typestore dataclasses (:func:`exporters.ros_types.typestore`); times are
simulation time in nanoseconds; frame ids come from :class:`exporters.log_common.Naming`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from exporters.filters import KEPT, FilterSummary
from exporters.log_common import (
    CLASS_COLORS,
    DEFAULT_COLOR,
    POINT_FIELDS,
    POINT_STRIDE,
    RADAR_FIELDS,
    RADAR_STRIDE,
    Naming,
    quat_from_matrix,
    quat_from_yaw,
    split_ns,
    unpack_radar,
)
from exporters.ros_types import typestore
from exporters.source import FrameItem, RecordSource
from pipeline.core.record import CameraInfo

_POINT_DATATYPE = {"<f4": 7, "<u2": 4, "u1": 2, "<i4": 5}  # sensor_msgs/PointField FLOAT32, UINT16, UINT8, INT32


class RosMessages:
    """Message factory bound to one typestore; ``summary`` counts the objects of the rows it is given."""

    def __init__(self) -> None:
        self.store = typestore()
        self.t = self.store.types
        self.summary = FilterSummary()

    # -- small pieces ----------------------------------------------------------------------------------
    def header(self, frame_id: str, time_ns: int):
        sec, nsec = split_ns(time_ns)
        return self.t["std_msgs/msg/Header"](stamp=self.t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                             frame_id=frame_id)

    def pose(self, xyz, quat):
        return self.t["geometry_msgs/msg/Pose"](
            position=self.t["geometry_msgs/msg/Point"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
            orientation=self.t["geometry_msgs/msg/Quaternion"](x=quat[0], y=quat[1], z=quat[2], w=quat[3]))

    def transform(self, parent: str, child: str, xyz, quat, time_ns: int):
        return self.t["geometry_msgs/msg/TransformStamped"](
            header=self.header(parent, time_ns), child_frame_id=child,
            transform=self.t["geometry_msgs/msg/Transform"](
                translation=self.t["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2])),
                rotation=self.t["geometry_msgs/msg/Quaternion"](x=quat[0], y=quat[1], z=quat[2], w=quat[3])))

    def vector3(self, x: float, y: float, z: float):
        return self.t["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    # -- messages --------------------------------------------------------------------------------------
    def tf_static(self, src: RecordSource, names: Naming):
        t0 = round(float(src.frames["time_s"].iloc[0]) * 1e9)
        sensors = [*src.info.cameras, *src.info.lidars, *src.info.radars]
        return self.t["tf2_msgs/msg/TFMessage"](transforms=[
            self.transform(names.frame("ego"), names.frame(s.name), s.T_array[:3, 3],
                           quat_from_matrix(s.T_array[:3, :3]), t0) for s in sensors])

    def tf(self, item: FrameItem, names: Naming, time_ns: int):
        row = item.row
        return self.t["tf2_msgs/msg/TFMessage"](transforms=[self.transform(
            names.frame("world"), names.frame("ego"), (row.ego_x_m, row.ego_y_m, row.ego_z_m),
            quat_from_yaw(row.ego_yaw_rad), time_ns)])

    def ego_pose(self, item: FrameItem, names: Naming, time_ns: int):
        row = item.row
        return self.t["geometry_msgs/msg/PoseStamped"](
            header=self.header(names.frame("world"), time_ns),
            pose=self.pose((row.ego_x_m, row.ego_y_m, row.ego_z_m), quat_from_yaw(row.ego_yaw_rad)))

    def image(self, data: bytes, frame_id: str, time_ns: int):
        return self.t["sensor_msgs/msg/CompressedImage"](header=self.header(frame_id, time_ns), format="png",
                                                         data=np.frombuffer(data, dtype=np.uint8))

    def camera_info(self, cam: CameraInfo, frame_id: str, time_ns: int):
        k = cam.K_array
        return self.t["sensor_msgs/msg/CameraInfo"](
            header=self.header(frame_id, time_ns), height=cam.height_px, width=cam.width_px,
            distortion_model="plumb_bob", d=np.asarray(cam.distortion, np.float64), k=k.reshape(-1),
            r=np.eye(3).reshape(-1), p=np.hstack([k, np.zeros((3, 1))]).reshape(-1), binning_x=0, binning_y=0,
            roi=self.t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                           do_rectify=False))

    def point_cloud(self, packed: memoryview, frame_id: str, time_ns: int):
        """PointCloud2 of one sweep packed by :func:`exporters.log_common.pack_points`."""
        return self._cloud(packed, frame_id, time_ns, POINT_FIELDS, POINT_STRIDE)

    def radar_cloud(self, packed: memoryview, frame_id: str, time_ns: int):
        """PointCloud2 of one radar scan packed by :func:`exporters.log_common.pack_radar` (offsets from the same
        table that packs it)."""
        return self._cloud(packed, frame_id, time_ns, RADAR_FIELDS, RADAR_STRIDE)

    def _cloud(self, packed: memoryview, frame_id: str, time_ns: int, table, stride: int):
        """PointCloud2 of ``packed`` rows of ``stride`` bytes laid out as ``table`` ((name, offset, dtype) rows)."""
        fields = [self.t["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=_POINT_DATATYPE[d], count=1)
                  for n, o, d in table]
        width = len(packed) // stride
        return self.t["sensor_msgs/msg/PointCloud2"](
            header=self.header(frame_id, time_ns), height=1, width=width, fields=fields, is_bigendian=False,
            point_step=stride, row_step=stride * width, data=np.frombuffer(packed, dtype=np.uint8), is_dense=True)

    def radar_scan(self, packed: memoryview, frame_id: str, time_ns: int):
        """radar_msgs/RadarScan of one scan: range, azimuth, elevation; doppler_velocity = the radial velocity
        relative to the radar (negative = approaching); amplitude = the SNR in dB."""
        d = unpack_radar(packed)
        ret = self.t["radar_msgs/msg/RadarReturn"]
        return self.t["radar_msgs/msg/RadarScan"](header=self.header(frame_id, time_ns), returns=[
            ret(range=float(r), azimuth=float(a), elevation=float(e), doppler_velocity=float(v), amplitude=float(s))
            for r, a, e, v, s in zip(d["range"], d["azimuth"], d["elevation"], d["radial_velocity"], d["snr"],
                                     strict=True)])

    def _hypothesis(self, cls: str, pose=None):
        pose = pose or self.pose((0, 0, 0), (0.0, 0.0, 0.0, 1.0))
        return self.t["vision_msgs/msg/ObjectHypothesisWithPose"](
            hypothesis=self.t["vision_msgs/msg/ObjectHypothesis"](class_id=cls, score=1.0),
            pose=self.t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)))

    def detections_2d(self, rows: list[dict], frame_id: str, time_ns: int):
        """Kept objects only (ground truth: score 1); ignore regions and hidden objects are counted, not sent."""
        detections: list[Any] = []
        for row in rows:
            if row["reason"] != KEPT or not row["box_finite"]:
                continue
            x1, y1, x2, y2 = (float(v) for v in row["box"])
            centre = self.t["vision_msgs/msg/Pose2D"](
                position=self.t["vision_msgs/msg/Point2D"](x=(x1 + x2) / 2, y=(y1 + y2) / 2), theta=0.0)
            detections.append(self.t["vision_msgs/msg/Detection2D"](
                header=self.header(frame_id, time_ns), results=[self._hypothesis(row["cls"])],
                bbox=self.t["vision_msgs/msg/BoundingBox2D"](center=centre, size_x=x2 - x1, size_y=y2 - y1),
                id=str(row["track_id"])))
        return self.t["vision_msgs/msg/Detection2DArray"](header=self.header(frame_id, time_ns), detections=detections)

    def detections_3d(self, rows: list[dict], frame_id: str, time_ns: int):
        """Every object of the LiDAR's label rows, box in the LiDAR frame (centre, size l/w/h, yaw about z)."""
        detections: list[Any] = []
        for row in rows:
            pose = self.pose((row["sensor_x_m"], row["sensor_y_m"], row["sensor_z_m"]),
                             quat_from_yaw(row["sensor_yaw_rad"]))
            detections.append(self.t["vision_msgs/msg/Detection3D"](
                header=self.header(frame_id, time_ns), results=[self._hypothesis(row["cls"], pose)],
                bbox=self.t["vision_msgs/msg/BoundingBox3D"](
                    center=pose, size=self.vector3(row["length_m"], row["width_m"], row["height_m"])),
                id=str(row["track_id"])))
        return self.t["vision_msgs/msg/Detection3DArray"](header=self.header(frame_id, time_ns), detections=detections)

    def markers(self, objects: list[dict], frame_id: str, time_ns: int, lifetime_ns: int):
        marker_t = self.t["visualization_msgs/msg/Marker"]
        sec, nsec = split_ns(lifetime_ns)
        lifetime = self.t["builtin_interfaces/msg/Duration"](sec=sec, nanosec=nsec)
        empty_image = self.t["sensor_msgs/msg/CompressedImage"](header=self.header("", 0), format="",
                                                                data=np.zeros(0, np.uint8))
        mesh = self.t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8))
        markers = []
        for o in objects:
            r, g, b, a = CLASS_COLORS.get(o["cls"], DEFAULT_COLOR)
            markers.append(marker_t(
                header=self.header(frame_id, time_ns), ns=o["cls"], id=int(o["track_id"]), type=marker_t.CUBE,
                action=marker_t.ADD, pose=self.pose((o["x_m"], o["y_m"], o["z_m"]), quat_from_yaw(o["yaw_rad"])),
                scale=self.vector3(o["length_m"], o["width_m"], o["height_m"]),
                color=self.t["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a), lifetime=lifetime, frame_locked=False,
                points=[], colors=[], texture_resource="", texture=empty_image, uv_coordinates=[],
                text=f"{o['cls']} {o['track_id']}", mesh_resource="", mesh_file=mesh,
                mesh_use_embedded_materials=False))
        return self.t["visualization_msgs/msg/MarkerArray"](markers=markers)
