"""Foxglove layouts for MCAP exports: the panels that show a record's camera with its boxes, its LiDAR points
with the 3D cubes, and the ego pose.

A layout names topics and frames, so it must match the file: a single-record MCAP uses the plain names
(the shipped ``docs/foxglove_layout.json`` is :func:`layout` of such a file with camera ``front`` and LiDAR
``top``); a merged MCAP prefixes every topic and frame per record (:class:`exporters.log_common.Naming`), and its
layout has one tab per record. The MCAP exporter writes the layout of each export next to it
(:func:`layout_path`); Foxglove does not read layouts from the MCAP itself (import it with Layouts →
Import from file).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from exporters.log_common import prefixed_frame, prefixed_topic

_PUBLISH = {"type": "point", "poseTopic": "/move_base_simple/goal", "pointTopic": "/clicked_point",
            "poseEstimateTopic": "/initialpose", "poseEstimateXDeviation": 0.5, "poseEstimateYDeviation": 0.5,
            "poseEstimateThetaDeviation": 0.26179939}


def layout_path(mcap_path: Path) -> Path:
    """Where the layout of the MCAP file ``mcap_path`` goes: ``<stem>.layout.json`` beside it."""
    return Path(mcap_path).with_name(f"{Path(mcap_path).stem}.layout.json")


@dataclass(frozen=True)
class RecordView:
    """What one tab shows: ``title``; ``topic``/``frame`` prefixes ("" for a single record, else the
    record's stem); the camera shown in the image panel; the LiDARs and radars drawn in the 3D panel (radar
    detections as large points coloured by radial velocity, RADAR_VELOCITY_RANGE_MPS)."""

    title: str
    prefix: str
    camera: str | None
    lidars: tuple[str, ...]
    radars: tuple[str, ...] = ()

    def topic(self, name: str) -> str:
        return prefixed_topic(self.prefix, name)

    def frame(self, name: str) -> str:
        return prefixed_frame(self.prefix, name)


RADAR_VELOCITY_RANGE_MPS = (-30.0, 10.0)  # the colour map's ends: fast approach .. moving away


def _camera_cfg(view: RecordView) -> dict[str, Any]:
    image: dict[str, Any] = {"synchronize": False, "rotation": 0, "flipHorizontal": False, "flipVertical": False}
    if view.camera is not None:
        base = f"/camera/{view.camera}"
        image = {"imageTopic": view.topic(f"{base}/image"), "calibrationTopic": view.topic(f"{base}/calibration"),
                 "annotations": {view.topic(f"{base}/annotations"): {"visible": True}}, **image}
    return {
        "cameraState": {"distance": 20, "perspective": True, "phi": 60, "target": [0, 0, 0],
                        "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "thetaOffset": 45, "fovy": 45,
                        "near": 0.5, "far": 5000},
        "followMode": "follow-pose", "scene": {}, "transforms": {}, "topics": {}, "layers": {},
        "publish": _PUBLISH, "imageMode": image,
    }


def _scene_cfg(view: RecordView, grid_id: str) -> dict[str, Any]:
    topics: dict[str, Any] = {
        view.topic(f"/lidar/{name}/points"): {"visible": True, "pointSize": 2, "colorField": "intensity",
                                             "colorMode": "colormap", "colorMap": "turbo", "decayTime": 0}
        for name in view.lidars}
    for name in view.radars:
        low, high = RADAR_VELOCITY_RANGE_MPS
        topics[view.topic(f"/radar/{name}/detections")] = {
            "visible": True, "pointSize": 8, "pointShape": "circle", "colorField": "radial_velocity",
            "colorMode": "colormap", "colorMap": "rainbow", "minValue": low, "maxValue": high, "decayTime": 0}
    topics[view.topic("/scene/objects")] = {"visible": True}
    if view.camera is not None:
        topics[view.topic(f"/camera/{view.camera}/image")] = {"visible": False}
    ego = view.frame("ego")
    return {
        "cameraState": {"distance": 45, "perspective": True, "phi": 55, "target": [0, 0, 0],
                        "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "thetaOffset": 180, "fovy": 45,
                        "near": 0.5, "far": 5000},
        "followMode": "follow-pose", "followTf": ego,
        "scene": {"enableStats": False, "backgroundColor": "#15161a"},
        "transforms": {f"frame:{view.frame('world')}": {"visible": False}},
        "topics": topics,
        "layers": {grid_id: {"visible": True, "frameLocked": True, "label": "Grid", "instanceId": grid_id,
                             "layerId": "foxglove.Grid", "size": 200, "divisions": 40, "lineWidth": 1,
                             "color": "#248eff50", "position": [0, 0, 0], "rotation": [0, 0, 0], "order": 1,
                             "frameId": ego}},
        "publish": _PUBLISH, "imageMode": {},
    }


def _pose_cfg(view: RecordView) -> dict[str, Any]:
    return {"topicPath": view.topic("/ego/pose"), "diffEnabled": False, "diffMethod": "custom", "diffTopicPath": "",
            "showFullMessageForDiff": False, "expansion": "all"}


def _panels(view: RecordView, suffix: str, configs: dict[str, Any]) -> dict[str, Any]:
    """Add one record's three panels to ``configs``; return their mosaic (camera | 3D over pose)."""
    camera, scene, pose = (f"Image!roadsynth-camera{suffix}", f"3D!roadsynth-scene{suffix}",
                           f"RawMessages!roadsynth-pose{suffix}")
    configs[camera] = _camera_cfg(view)
    configs[scene] = _scene_cfg(view, f"roadsynth-grid{suffix}")
    configs[pose] = _pose_cfg(view)
    return {"direction": "row", "first": camera,
            "second": {"direction": "column", "first": scene, "second": pose, "splitPercentage": 80},
            "splitPercentage": 50}


def layout(views: list[RecordView]) -> dict[str, Any]:
    """The Foxglove layout (JSON-ready) of an MCAP holding ``views``: their panels directly for one record,
    a tab per record for several."""
    if not views:
        raise ValueError("a layout needs at least one record")
    configs: dict[str, Any] = {}
    if len(views) == 1:
        root: Any = _panels(views[0], "", configs)
    else:
        tabs = [{"title": v.title, "layout": _panels(v, f"-{i}", configs)} for i, v in enumerate(views)]
        root = "Tab!roadsynth-records"
        configs[root] = {"activeTabIdx": 0, "tabs": tabs}
    return {"configById": configs, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
            "layout": root}
