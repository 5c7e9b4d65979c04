"""The preview's bird's-eye view: object points in their class colour (the 2D boxes' colours) and the camera's
field of view, on a real record and on hand-made cameras with closed-form fields of view."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pipeline.core.geometry import R_CAMERA_FROM_BODY, Transform
from pipeline.core.record import CameraInfo, DatasetRecord, LidarInfo
from pipeline.stages.preview import (
    BEV_PX,
    CLASS_BGR,
    FOV_BGR,
    _bev_panel,
    camera_fov_bev,
    contact_sheet,
    point_colours,
)

NO_LABELS = pd.DataFrame({"frame": pd.Series(dtype="int32"), "sensor": pd.Series(dtype=object)})


def _camera(yaw_rad: float = 0.0, distortion=(0.0,) * 5, xyz=(0.0, 0.0, 0.0)) -> CameraInfo:
    """A 160x120 camera with a 90 deg horizontal field of view (fx = 80) at ``xyz``, level, turned by ``yaw``."""
    body_to_ego = Transform.from_xyz_rpy(xyz, (0.0, 0.0, yaw_rad))
    optical_to_ego = body_to_ego @ Transform(R_CAMERA_FROM_BODY.T, np.zeros(3))
    return CameraInfo("cam", 160, 120, [[80.0, 0.0, 80.0], [0.0, 80.0, 60.0], [0.0, 0.0, 1.0]], list(distortion),
                      optical_to_ego.matrix.tolist())


LIDAR = LidarInfo("top", 32, 120.0, 10.0, Transform.from_xyz_rpy((0.0, 0.0, 1.05), (0.0, 0.0, 0.0)).matrix.tolist())


def _half_angles(directions: np.ndarray, axis_rad: float) -> np.ndarray:
    return np.arctan2(directions[:, 1], directions[:, 0]) - axis_rad


@pytest.mark.parametrize("yaw_rad", [0.0, math.pi / 2, math.pi])
def test_a_pinhole_cameras_field_of_view(yaw_rad):
    origin, directions = camera_fov_bev(_camera(yaw_rad, xyz=(0.6, -0.3, 0.65)), LIDAR)
    np.testing.assert_allclose(origin, [0.6, -0.3], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0)
    half = np.angle(np.exp(1j * _half_angles(directions, yaw_rad)))  # wrapped to (-pi, pi]
    np.testing.assert_allclose(np.sort(half), [-math.pi / 4, math.pi / 4], atol=1e-9)


def test_barrel_distortion_widens_the_field_of_view_to_the_corners():
    k1 = -0.05
    _, directions = camera_fov_bev(_camera(distortion=(k1, 0.0, 0.0, 0.0, 0.0)), LIDAR)
    # The image corner (1, 0.75) in distorted normalised coordinates, radius 1.25, is the widest ray: undistorted,
    # its radius r solves r (1 + k1 r^2) = 1.25 and its x is r / 1.25 (radial distortion keeps the direction).
    roots = np.roots([k1, 0.0, 1.0, -1.25])
    r = min(v.real for v in roots if abs(v.imag) < 1e-12 and v.real > 0)
    expected = math.atan(r / 1.25)
    assert expected > math.pi / 4
    np.testing.assert_allclose(np.sort(_half_angles(directions, 0.0)), [-expected, expected], atol=1e-6)


def test_a_camera_looking_straight_down_has_no_field_of_view_from_above():
    pitched_down = Transform.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, math.pi / 2, 0.0))  # body x (optical z) to -z
    down = CameraInfo("down", 160, 120, [[80.0, 0.0, 80.0], [0.0, 80.0, 60.0], [0.0, 0.0, 1.0]], [0.0] * 5,
                      (pitched_down @ Transform(R_CAMERA_FROM_BODY.T, np.zeros(3))).matrix.tolist())
    assert camera_fov_bev(down, LIDAR) is None


def test_object_points_take_their_class_colour(small_record):
    record = DatasetRecord(small_record)
    lidar = record.info.lidars[0].name
    labels = record.labels
    checked = 0
    for frame in record.frames["frame"]:
        pts = record.points(lidar, frame)
        colours = point_colours(pts)
        ids = pts["instance_id"].to_numpy()
        cls_of = labels[labels["frame"] == frame].drop_duplicates("track_id").set_index("track_id")["cls"]
        on_object = ids > 0
        expected = np.array([CLASS_BGR[cls_of[t]] for t in ids[on_object]], np.uint8).reshape(-1, 3)
        np.testing.assert_array_equal(colours[on_object], expected)
        static = colours[~on_object]
        assert (static[:, 0] == static[:, 1]).all() and (static[:, 1] == static[:, 2]).all()  # grey
        checked += int(on_object.sum())
    assert checked > 0


def test_the_panel_draws_the_class_colours_and_the_field_of_view(small_record):
    record = DatasetRecord(small_record)
    lidar, camera = record.info.lidars[0], record.info.cameras[0]
    frame = int(record.frames["frame"].iloc[0])
    pts = record.points(lidar.name, frame)
    classes = record.labels.set_index("track_id")["cls"]
    plain = _bev_panel(record, lidar, frame, NO_LABELS, BEV_PX)
    shown = pts[(pts["instance_id"] > 0) & (pts["x_m"].abs() < 50) & (pts["y_m"].abs() < 50)]  # inside the panel
    assert len(shown)
    for cls in set(classes[shown["instance_id"].unique()]):
        assert (plain == CLASS_BGR[cls]).all(axis=2).any(), cls
    with_fov = _bev_panel(record, lidar, frame, NO_LABELS, BEV_PX, camera)
    changed = np.argwhere((with_fov != plain).any(axis=2))  # (row, col)
    assert len(changed) > BEV_PX // 2  # two lines from the camera to the panel's edge
    assert (with_fov == FOV_BGR).all(axis=2).any()
    # every changed pixel lies on one of the two field-of-view lines (closed form: +-45 deg from 0.6 m ahead)
    scale = BEV_PX / 120.0
    x = (BEV_PX / 2 - changed[:, 0] - 0.5) / scale - 0.6  # metres ahead of the camera
    y = (BEV_PX / 2 - changed[:, 1] - 0.5) / scale  # metres to the left
    assert (np.abs(np.abs(y) - x) / math.sqrt(2) <= 1.5 / scale).all()


def test_the_contact_sheet(small_record):
    sheet = contact_sheet(DatasetRecord(small_record), frames=2)
    assert sheet.shape == (2 * 120, 160 + 120, 3)
