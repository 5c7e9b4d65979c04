"""Frames, transforms and boxes: closed-form cases and properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.core.geometry import (
    R_CAMERA_FROM_BODY,
    Boxes3D,
    Transform,
    sumo_angle_to_yaw,
    sumo_front_to_center,
    wrap_angle,
)


@pytest.mark.parametrize(
    ("angle_deg", "yaw_rad"),
    [(0.0, math.pi / 2), (90.0, 0.0), (180.0, -math.pi / 2), (270.0, -math.pi), (45.0, math.pi / 4)],
)
def test_sumo_angle_is_clockwise_from_north(angle_deg, yaw_rad):
    # North (0 deg) is +y, i.e. yaw pi/2; east (90 deg) is +x, yaw 0; west wraps to -pi.
    assert sumo_angle_to_yaw(angle_deg) == pytest.approx(yaw_rad)


def test_front_bumper_to_centre_heading_east_and_north():
    front = np.array([[10.0, 5.0], [0.0, 0.0]])
    centre, yaw = sumo_front_to_center(front, np.array([90.0, 0.0]), np.array([4.0, 6.0]))
    np.testing.assert_allclose(centre, [[8.0, 5.0], [0.0, -3.0]], atol=1e-12)
    np.testing.assert_allclose(yaw, [0.0, math.pi / 2])


@given(st.floats(-1e4, 1e4, allow_nan=False))
def test_wrap_angle_range_and_equivalence(angle):
    w = wrap_angle(angle)
    assert -math.pi <= w < math.pi
    assert math.cos(w) == pytest.approx(math.cos(angle), abs=1e-6)
    assert math.sin(w) == pytest.approx(math.sin(angle), abs=1e-6)


def test_camera_axes_from_body():
    # Body forward is optical +z, body left is optical -x, body up is optical -y.
    np.testing.assert_array_equal(R_CAMERA_FROM_BODY @ [1, 0, 0], [0, 0, 1])
    np.testing.assert_array_equal(R_CAMERA_FROM_BODY @ [0, 1, 0], [-1, 0, 0])
    np.testing.assert_array_equal(R_CAMERA_FROM_BODY @ [0, 0, 1], [0, -1, 0])


@given(
    st.tuples(*[st.floats(-50, 50)] * 3),
    st.tuples(st.floats(-3, 3), st.floats(-1.5, 1.5), st.floats(-3, 3)),
)
def test_transform_inverse_and_composition(xyz, rpy):
    t = Transform.from_xyz_rpy(xyz, rpy)
    pts = np.array([[1.0, 2.0, 3.0], [-4.0, 0.5, 9.0]])
    np.testing.assert_allclose(t.inverse().apply(t.apply(pts)), pts, atol=1e-9)
    np.testing.assert_allclose((t @ t.inverse()).matrix, np.eye(4), atol=1e-9)
    np.testing.assert_allclose((t @ t).apply(pts), t.apply(t.apply(pts)), atol=1e-9)


def test_transform_rejects_non_rotation():
    with pytest.raises(ValueError, match="orthonormal"):
        Transform(np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    # The tolerance is np.allclose's with atol 1e-9: 1e-5 relative on the diagonal of R R^T, 1e-9 off it.
    Transform(np.diag([1.0, 1.0, 1.0 + 4e-6]), np.zeros(3))
    for bad in (np.diag([1.0, 1.0, 1.0 + 6e-6]), np.array([[1.0, 2e-9, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
                np.full((3, 3), np.nan)):
        with pytest.raises(ValueError, match="orthonormal"):
            Transform(bad, np.zeros(3))
    Transform(np.array([[1.0, 4e-10, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), np.zeros(3))


def test_box_corners_and_contains():
    box = Boxes3D(center=[[10.0, 0.0, 1.0]], size=[[4.0, 2.0, 2.0]], yaw_rad=[math.pi / 2])
    corners = box.corners()[0]
    # Yawed 90 degrees: length runs along y.
    np.testing.assert_allclose(corners[:, 0].min(), 9.0)
    np.testing.assert_allclose(corners[:, 1].max(), 2.0)
    np.testing.assert_allclose(corners[:, 2].min(), 0.0)
    inside = box.contains(np.array([[10.0, 1.9, 1.0], [11.1, 0.0, 1.0], [10.0, 0.0, 2.1]]))
    np.testing.assert_array_equal(inside[0], [True, False, False])


def test_boxes_transformed_to_ego_frame():
    ego = Transform.from_xyz_rpy((100.0, 50.0, 0.0), (0.0, 0.0, math.pi / 2))  # ego pose in world
    world_boxes = Boxes3D(center=[[100.0, 60.0, 0.75]], size=[[4.5, 1.8, 1.5]], yaw_rad=[math.pi / 2])
    in_ego = world_boxes.transformed(ego.inverse())
    np.testing.assert_allclose(in_ego.center, [[10.0, 0.0, 0.75]], atol=1e-9)
    np.testing.assert_allclose(in_ego.yaw_rad, [0.0], atol=1e-12)


def test_boxes_reject_bad_sizes():
    with pytest.raises(ValueError, match="positive"):
        Boxes3D(center=[[0, 0, 0]], size=[[1, 0, 1]], yaw_rad=[0.0])
