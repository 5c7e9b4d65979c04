"""Frames, rigid transforms and oriented 3D boxes.

Conventions (docs/design.md, "Frames and conventions"):

- World: SUMO network coordinates, metres, x east, y north, z up.
- Ego / vehicle / LiDAR frame: x forward, y left, z up (ISO 8855).
- Camera frame: OpenCV, x right, y down, z forward.
- Yaw: radians, counter-clockwise from +x, wrapped to [-pi, pi).
- SUMO reports a vehicle's *front bumper centre* and an angle in degrees *clockwise from north*;
  :func:`sumo_front_to_center` converts that to a box centre and yaw.
- A 3D box is (centre x, y, z; length, width, height; yaw): never a corner or a bumper.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * np.pi


class Frame(enum.Enum):
    """Coordinate frames used across the pipeline."""

    WORLD = "world"
    """SUMO network coordinates: x east, y north, z up (metres)."""
    EGO = "ego"
    """Ego vehicle body frame at the box centre: x forward, y left, z up."""
    LIDAR = "lidar"
    """A LiDAR's frame: x forward, y left, z up (KITTI velodyne)."""
    CAMERA = "camera"
    """A camera's optical frame (OpenCV): x right, y down, z forward."""


# Rotation taking vectors from an ISO 8855 body frame (x fwd, y left, z up) to the OpenCV optical
# frame of a camera looking along the body's +x: x_cam = -y_body, y_cam = -z_body, z_cam = x_body.
R_CAMERA_FROM_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def wrap_angle(angle_rad: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles to [-pi, pi)."""
    wrapped = (np.asarray(angle_rad, dtype=np.float64) + np.pi) % TWO_PI - np.pi
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def sumo_angle_to_yaw(angle_deg: np.ndarray | float) -> np.ndarray | float:
    """SUMO heading (degrees clockwise from north) to yaw (radians CCW from +x, in [-pi, pi))."""
    return wrap_angle(np.radians(90.0 - np.asarray(angle_deg, dtype=np.float64)))


def sumo_front_to_center(
    front_xy: np.ndarray, angle_deg: np.ndarray, length_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Convert SUMO front-bumper positions to box centres.

    Args:
        front_xy: (N, 2) float64 front bumper centre from ``vehicle.getPosition``.
        angle_deg: (N,) float64 SUMO angle, degrees clockwise from north.
        length_m: (N,) float64 vehicle length.

    Returns:
        centre_xy (N, 2) float64 and yaw_rad (N,) float64.
    """
    front_xy = np.asarray(front_xy, dtype=np.float64).reshape(-1, 2)
    yaw = np.atleast_1d(sumo_angle_to_yaw(angle_deg))
    half = 0.5 * np.asarray(length_m, dtype=np.float64)
    centre = front_xy - half[:, None] * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    return centre, yaw


def rotation_z(yaw_rad: float) -> np.ndarray:
    """(3, 3) rotation about +z by ``yaw_rad``."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """(3, 3) rotation R = Rz(yaw) @ Ry(pitch) @ Rx(roll) (intrinsic z-y'-x'', ISO 8855)."""
    cr, sr = np.cos(roll_rad), np.sin(roll_rad)
    cp, sp = np.cos(pitch_rad), np.sin(pitch_rad)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    return rotation_z(yaw_rad) @ ry @ rx


_EYE = np.eye(3)
_ORTHONORMAL_TOL = 1e-9 + 1e-5 * _EYE


@dataclass(frozen=True)
class Transform:
    """A rigid transform ``p_to = rotation @ p_from + translation``.

    Attributes:
        rotation: (3, 3) float64 orthonormal, det +1.
        translation: (3,) float64 metres.
    """

    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        rot = np.asarray(self.rotation, dtype=np.float64)
        trans = np.asarray(self.translation, dtype=np.float64).reshape(3)
        if rot.shape != (3, 3):
            raise ValueError(f"rotation must be (3, 3), got {rot.shape}")
        # np.allclose(rot @ rot.T, I, atol=1e-9) (its default rtol 1e-5 on the diagonal), without its per-call
        # overhead: a frame builds a dozen transforms.
        if not np.all(np.abs(rot @ rot.T - _EYE) <= _ORTHONORMAL_TOL) or np.linalg.det(rot) < 0:
            raise ValueError("rotation must be orthonormal with determinant +1")
        object.__setattr__(self, "rotation", rot)
        object.__setattr__(self, "translation", trans)

    @classmethod
    def identity(cls) -> Transform:
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_xyz_rpy(
        cls, xyz: tuple[float, float, float], rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ) -> Transform:
        """Pose of a child frame in its parent: position ``xyz`` and roll/pitch/yaw."""
        return cls(rotation_rpy(*rpy_rad), np.asarray(xyz, dtype=np.float64))

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> Transform:
        matrix = np.asarray(matrix, dtype=np.float64)
        if matrix.shape != (4, 4):
            raise ValueError(f"matrix must be (4, 4), got {matrix.shape}")
        return cls(matrix[:3, :3], matrix[:3, 3])

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) float64 homogeneous matrix."""
        out = np.eye(4)
        out[:3, :3] = self.rotation
        out[:3, 3] = self.translation
        return out

    def inverse(self) -> Transform:
        rot_t = self.rotation.T
        return Transform(rot_t, -rot_t @ self.translation)

    def __matmul__(self, other: Transform) -> Transform:
        """Compose: ``(a @ b).apply(p) == a.apply(b.apply(p))``."""
        return Transform(self.rotation @ other.rotation, self.rotation @ other.translation + self.translation)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform (N, 3) points (or one (3,) point)."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.rotation.T + self.translation

    def apply_vectors(self, vectors: np.ndarray) -> np.ndarray:
        """Rotate (N, 3) direction vectors (no translation)."""
        return np.asarray(vectors, dtype=np.float64) @ self.rotation.T


def body_to_camera() -> Transform:
    """Transform from a camera mount's body frame (x fwd, y left, z up) to its optical frame."""
    return Transform(R_CAMERA_FROM_BODY, np.zeros(3))


@dataclass(frozen=True)
class Boxes3D:
    """Oriented 3D boxes, struct of arrays, yawed about +z of their frame.

    Attributes:
        center: (N, 3) float64 box centres, metres.
        size: (N, 3) float64 (length, width, height), metres; length along the heading.
        yaw_rad: (N,) float64 heading, CCW from +x, in [-pi, pi).
    """

    center: np.ndarray
    size: np.ndarray
    yaw_rad: np.ndarray

    def __post_init__(self) -> None:
        center = np.asarray(self.center, dtype=np.float64).reshape(-1, 3)
        size = np.asarray(self.size, dtype=np.float64).reshape(-1, 3)
        yaw = np.asarray(self.yaw_rad, dtype=np.float64).reshape(-1)
        if not (len(center) == len(size) == len(yaw)):
            raise ValueError(f"box arrays differ in length: {len(center)}, {len(size)}, {len(yaw)}")
        if np.any(size <= 0) or not np.all(np.isfinite(size)):
            raise ValueError("box sizes must be finite and positive")
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "yaw_rad", wrap_angle(yaw) if len(yaw) else yaw)

    def __len__(self) -> int:
        return len(self.center)

    def corners(self) -> np.ndarray:
        """(N, 8, 3) float64 corners; first four at the bottom, counter-clockwise from front-left."""
        signs = np.array(
            [[1, 1, -1], [-1, 1, -1], [-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1], [-1, -1, 1], [1, -1, 1]],
            dtype=np.float64,
        )
        local = 0.5 * signs[None, :, :] * self.size[:, None, :]
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        x = c[:, None] * local[..., 0] - s[:, None] * local[..., 1]
        y = s[:, None] * local[..., 0] + c[:, None] * local[..., 1]
        return np.stack([x, y, local[..., 2]], axis=-1) + self.center[:, None, :]

    def contains(self, points: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
        """(N, M) bool: which of (M, 3) points lie inside each box (grown by ``margin_m``)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        rel = points[None, :, :] - self.center[:, None, :]
        c, s = np.cos(self.yaw_rad)[:, None], np.sin(self.yaw_rad)[:, None]
        local_x = c * rel[..., 0] + s * rel[..., 1]
        local_y = -s * rel[..., 0] + c * rel[..., 1]
        half = 0.5 * self.size[:, None, :] + margin_m
        inside_xy = (np.abs(local_x) <= half[..., 0]) & (np.abs(local_y) <= half[..., 1])
        return inside_xy & (np.abs(rel[..., 2]) <= half[..., 2])

    def transformed(self, transform: Transform) -> Boxes3D:
        """Boxes expressed in another z-up frame (the transform must keep z up: yaw-only rotation)."""
        heading = np.stack([np.cos(self.yaw_rad), np.sin(self.yaw_rad), np.zeros(len(self))], axis=1)
        new_heading = transform.apply_vectors(heading)
        if len(self) and not np.allclose(new_heading[:, 2], 0.0, atol=1e-6):
            raise ValueError("transform tilts the z axis; yaw-only boxes cannot represent the result")
        return Boxes3D(transform.apply(self.center), self.size, np.arctan2(new_heading[:, 1], new_heading[:, 0]))
