"""ROS 2 message types for rosbag2 export: the Humble typestore plus vision_msgs and radar_msgs registered from
their .msg fields.

rosbags ships the core ROS 2 interfaces (sensor_msgs, tf2_msgs, visualization_msgs, ...) but not
vision_msgs nor radar_msgs. The definitions below are the fields of ros-perception/vision_msgs 4.x (ROS 2 Humble
and later), the package that defines Detection2DArray and Detection3DArray, and of ros-perception/radar_msgs
(RadarScan: a header and RadarReturns of range, azimuth, elevation, doppler_velocity, amplitude); rosbags.typesys
parses and registers them, so the bag carries the real definitions and any ROS 2 tool decodes them.
"""

from __future__ import annotations

from functools import cache

VISION_MSGS: dict[str, str] = {
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"),
    "vision_msgs/msg/Detection2D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox2D bbox\n"
        "string id\n"),
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox3D bbox\n"
        "string id\n"),
    "vision_msgs/msg/Detection3DArray": "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
}

RADAR_MSGS: dict[str, str] = {
    "radar_msgs/msg/RadarReturn": (
        "float32 range\nfloat32 azimuth\nfloat32 elevation\nfloat32 doppler_velocity\nfloat32 amplitude\n"),
    "radar_msgs/msg/RadarScan": "std_msgs/Header header\nradar_msgs/RadarReturn[] returns\n",
}


@cache
def typestore():
    """ROS 2 Humble typestore with vision_msgs and radar_msgs registered (built once)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for name, text in {**VISION_MSGS, **RADAR_MSGS}.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store
