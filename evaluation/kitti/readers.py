"""Strict readers for KITTI object label files and calibration files.

A label file holds one object per line with 15 whitespace-separated columns (16 with a trailing
detection score)::

    type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score]

Conventions: ``bbox`` is x1, y1, x2, y2 in pixels; ``dimensions`` is h, w, l in metres;
``location`` is the bottom centre of the box in the rectified camera frame (x right, y down,
z forward); angles are radians. The KITTI format writes "no 3D box" as the sentinel dimensions
-1 -1 -1 (DontCare regions, 2D-only detectors); that exact sentinel is accepted and exposed as the
mask ``KittiFrame.has_box3d``; any other negative size is an error.

Every error names the file, the 1-based line number and the field.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["KittiCalib", "KittiFormatError", "KittiFrame", "read_calib", "read_label_dir", "read_label_file"]

FIELDS = (
    "type", "truncated", "occluded", "alpha", "bbox_x1", "bbox_y1", "bbox_x2", "bbox_y2",
    "height", "width", "length", "location_x", "location_y", "location_z", "rotation_y", "score",
)  # fmt: skip
N_COLUMNS = 15
# 0 fully visible, 1 partly occluded, 2 largely occluded, 3 unknown; detections and DontCare write -1. A level
# beyond these would silently move an object out of every difficulty; the int64 cast of 1e300 is undefined.
OCCLUSION_LEVELS = (-1.0, 0.0, 1.0, 2.0, 3.0)
# What a KITTI number looks like: the plain decimal and exponent forms (and inf/nan, refused as not finite) that
# numpy's fast parser reads too. Python's float() also takes "1_000" and non-ASCII digits; refused here, so that
# both parsers agree on every file.
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?|[+-]?(inf|infinity|nan)", re.IGNORECASE | re.ASCII)


class KittiFormatError(ValueError):
    """A KITTI file does not follow the format; the message names file, line and field."""


@dataclass(frozen=True)
class KittiFrame:
    """All objects of one KITTI label file, as a struct of arrays (N objects).

    Attributes:
        type: (N,) str, class name as written (e.g. "Car", "DontCare").
        truncated: (N,) float64, truncation fraction (detections often write -1).
        occluded: (N,) int64, occlusion level 0..3 (detections often write -1).
        alpha: (N,) float64, observation angle in radians (-10 = unknown).
        bbox: (N, 4) float64, 2D box x1, y1, x2, y2 in pixels.
        dimensions: (N, 3) float64, 3D box h, w, l in metres (-1 -1 -1 = no 3D box).
        location: (N, 3) float64, bottom centre x, y, z in the rectified camera frame, metres.
        rotation_y: (N,) float64, yaw around the camera y axis in radians.
        score: (N,) float64 detection confidence, or None for ground truth.
    """

    type: np.ndarray
    truncated: np.ndarray
    occluded: np.ndarray
    alpha: np.ndarray
    bbox: np.ndarray
    dimensions: np.ndarray
    location: np.ndarray
    rotation_y: np.ndarray
    score: np.ndarray | None

    def __len__(self) -> int:
        return int(self.type.shape[0])

    @property
    def has_box3d(self) -> np.ndarray:
        """(N,) bool: False where dimensions are the KITTI "no 3D box" sentinel -1 -1 -1."""
        return ~np.all(self.dimensions == -1.0, axis=1)

    @property
    def height_px(self) -> np.ndarray:
        """(N,) float64: 2D box height y2 - y1 in pixels (the devkit's difficulty measure)."""
        return self.bbox[:, 3] - self.bbox[:, 1]

    @classmethod
    def empty(cls, *, with_score: bool) -> KittiFrame:
        """A frame with no objects."""
        return _frame_from_table(np.empty((0, N_COLUMNS + int(with_score)), dtype=object), with_score)


def _fail(path: Path, line: int, field: str, message: str) -> KittiFormatError:
    return KittiFormatError(f"{path}:{line}: field '{field}': {message}")


def _read_text(path: Path) -> str:
    """A label or calibration file's text (UTF-8; KITTI files are ASCII): binary garbage fails naming the file."""
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise KittiFormatError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None


def _parse_float(path: Path, line: int, field: str, token: str) -> float:
    if not _NUMBER.fullmatch(token):
        raise _fail(path, line, field, f"expected a number, got {token!r}")
    value = float(token)
    if not math.isfinite(value):
        raise _fail(path, line, field, f"expected a finite number, got {token!r}")
    return value


def _frame_from_table(table: np.ndarray, with_score: bool) -> KittiFrame:
    numbers = table[:, 1:].astype(np.float64).reshape(len(table), table.shape[1] - 1)
    return _frame(table[:, 0].astype(str), numbers, with_score)


def _frame(types: np.ndarray, numbers: np.ndarray, with_score: bool) -> KittiFrame:
    return KittiFrame(
        type=types.astype(str),
        truncated=numbers[:, 0].copy(),
        occluded=numbers[:, 1].astype(np.int64),
        alpha=numbers[:, 2].copy(),
        bbox=numbers[:, 3:7].copy(),
        dimensions=numbers[:, 7:10].copy(),
        location=numbers[:, 10:13].copy(),
        rotation_y=numbers[:, 13].copy(),
        score=numbers[:, 14].copy() if with_score else None,
    )


def _check_line(path: Path, line: int, tokens: list[str], with_score: bool) -> list[object]:
    """Validate one split line; returns [type, 14 or 15 floats]."""
    expected = N_COLUMNS + int(with_score)
    if with_score and len(tokens) == N_COLUMNS:
        raise _fail(path, line, "score", "missing: detections need a 16th column, the score")
    if len(tokens) != expected:
        what = "16 (15 + score)" if with_score else "15 (no score column in ground truth)"
        raise _fail(path, line, "<columns>", f"expected {what} columns, got {len(tokens)}")
    values: list[object] = [tokens[0]]
    for field, token in zip(FIELDS[1:expected], tokens[1:], strict=True):
        values.append(_parse_float(path, line, field, token))
    if values[2] not in OCCLUSION_LEVELS:
        raise _fail(path, line, "occluded", f"expected an integer level 0-3 (-1 = unknown), got {tokens[2]!r}")
    x1, y1, x2, y2 = values[4:8]
    if x2 < x1 or y2 < y1:  # type: ignore[operator]
        raise _fail(path, line, "bbox", f"negative size: x1={x1} y1={y1} x2={x2} y2={y2}")
    dims = values[8:11]
    if dims != [-1.0, -1.0, -1.0]:
        for field, value in zip(("height", "width", "length"), dims, strict=True):
            if value < 0:  # type: ignore[operator]
                raise _fail(path, line, field, f"negative size {value} (only -1 -1 -1 means 'no 3D box')")
    return values


def read_label_file(path: str | Path, *, with_score: bool) -> KittiFrame:
    """Read one KITTI label file (blank lines are skipped).

    Args:
        path: the .txt file.
        with_score: True for detections (16 columns, the last one the score), False for ground truth.

    Raises:
        KittiFormatError: naming the file, the line and the field.
    """
    path = Path(path)
    lines = [(no, text.split()) for no, text in enumerate(_read_text(path).splitlines(), start=1) if text.strip()]
    if not lines:
        return KittiFrame.empty(with_score=with_score)
    expected = N_COLUMNS + int(with_score)
    for line_no, tokens in lines:
        if len(tokens) != expected:
            _check_line(path, line_no, tokens, with_score)  # raises with the precise message
    numbers = _parse_numbers([tokens[1:] for _, tokens in lines], expected - 1)
    if numbers is None or not _all_valid(numbers):
        # the strict per-line parser raises naming the line; should it accept every line, its values are the truth
        numbers = np.array([_check_line(path, no, tokens, with_score)[1:] for no, tokens in lines], dtype=np.float64)
    return _frame(np.array([tokens[0] for _, tokens in lines]), numbers, with_score)


def _parse_numbers(rows: list[list[str]], width: int) -> np.ndarray | None:
    """Fast path: numpy's C parser on all numbers at once; None if anything is not a number."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            flat = np.fromstring(" ".join(" ".join(row) for row in rows), dtype=np.float64, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    return flat.reshape(len(rows), width) if flat.size == len(rows) * width else None


def _all_valid(numbers: np.ndarray) -> bool:
    """Vectorised version of the per-line checks of _check_line, (N, 14 or 15) float64."""
    if not np.all(np.isfinite(numbers)):
        return False
    occluded, bbox, dims = numbers[:, 1], numbers[:, 3:7], numbers[:, 7:10]
    sentinel = np.all(dims == -1.0, axis=1)
    return bool(
        np.all(np.isin(occluded, OCCLUSION_LEVELS))
        and np.all(bbox[:, 2] >= bbox[:, 0])
        and np.all(bbox[:, 3] >= bbox[:, 1])
        and np.all((dims >= 0) | sentinel[:, None])
    )


def read_label_dir(path: str | Path, *, with_score: bool) -> dict[str, KittiFrame]:
    """Read every ``*.txt`` label file of a directory.

    Returns:
        frame id (the file stem, e.g. "000123") -> KittiFrame, in sorted frame-id order.

    Raises:
        KittiFormatError: the directory is missing or a file is malformed.
    """
    path = Path(path)
    if not path.is_dir():
        raise KittiFormatError(f"{path}: not a directory of KITTI label files")
    return {f.stem: read_label_file(f, with_score=with_score) for f in sorted(path.glob("*.txt"))}


@dataclass(frozen=True)
class KittiCalib:
    """One KITTI object calibration file.

    Attributes:
        P0, P1, P2, P3: (3, 4) float64 projection matrices of the rectified cameras 0..3.
        R0_rect: (3, 3) float64 rectifying rotation of camera 0.
        Tr_velo_to_cam: (3, 4) float64 velodyne -> camera 0 (unrectified) rigid transform.
        Tr_imu_to_velo: (3, 4) float64 IMU -> velodyne rigid transform.
    """

    P0: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    P3: np.ndarray
    R0_rect: np.ndarray
    Tr_velo_to_cam: np.ndarray
    Tr_imu_to_velo: np.ndarray

    def velo_to_rect(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) float64 velodyne points -> (N, 3) float64 rectified camera coordinates."""
        homogeneous = np.hstack([points, np.ones((len(points), 1))])
        return (self.R0_rect @ (self.Tr_velo_to_cam @ homogeneous.T)).T


_CALIB_SHAPES = {
    "P0": (3, 4), "P1": (3, 4), "P2": (3, 4), "P3": (3, 4),
    "R0_rect": (3, 3), "Tr_velo_to_cam": (3, 4), "Tr_imu_to_velo": (3, 4),
}  # fmt: skip


def read_calib(path: str | Path) -> KittiCalib:
    """Read a KITTI object calib file (lines ``KEY: v1 v2 ...``); unknown keys are ignored.

    Raises:
        KittiFormatError: a required key is missing or duplicated, or has the wrong count of numbers.
    """
    path = Path(path)
    found: dict[str, np.ndarray] = {}
    for line_no, text in enumerate(_read_text(path).splitlines(), start=1):
        if not text.strip():
            continue
        key, sep, rest = text.partition(":")
        key = key.strip()
        if not sep:
            raise _fail(path, line_no, key, "expected 'KEY: numbers'")
        if key not in _CALIB_SHAPES:
            continue
        if key in found:
            raise _fail(path, line_no, key, "duplicated")
        shape = _CALIB_SHAPES[key]
        tokens = rest.split()
        if len(tokens) != shape[0] * shape[1]:
            raise _fail(path, line_no, key, f"expected {shape[0] * shape[1]} numbers, got {len(tokens)}")
        found[key] = np.array([_parse_float(path, line_no, key, t) for t in tokens]).reshape(shape)
    missing = [k for k in _CALIB_SHAPES if k not in found]
    if missing:
        raise KittiFormatError(f"{path}: missing calibration keys {missing}")
    return KittiCalib(**found)
