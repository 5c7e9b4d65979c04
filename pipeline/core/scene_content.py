"""What a record's frames show: vehicles tall enough for a detector, and near-duplicate frames.

Both are computed from the canonical record's tables alone (``frames.parquet``, ``labels.parquet``;
docs/dataset.md), so they score any record, old or new:

- **tall vehicles**: camera labels of class car, van, truck or bus that are ``visible`` with a tight 2D box
  at least ``min_height_px`` tall (``y2 - y1``). 30 px is where a COCO-trained detector starts to find our
  probe car at all (../shared/REALISM.md); KITTI's images hold about 4 cars each.
- **near-duplicate frame**: a frame whose ego moved less than ``min_travel_m`` since the previous frame of
  the record *and* whose set of labelled objects (visible, tight box >= ``min_object_px`` tall) is the same
  as the previous frame's, each box overlapping its previous box with IoU >= ``min_iou``. An ego waiting at
  a red light behind the same cars gives such frames; traffic crossing in front of it does not.
  The rate is near-duplicates / (frames - 1) per camera (0 for a record of one frame).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

VEHICLE_CLASSES = ("car", "van", "truck", "bus")
CYCLE_CLASSES = ("bicycle", "motorcycle")


def _visible_camera(labels: pd.DataFrame, min_height_px: float) -> pd.DataFrame:
    cam = labels[(labels["sensor_type"] == "camera") & labels["visible"]]
    return cam[(cam["y2"] - cam["y1"]) >= min_height_px]


def tall_counts(frames: pd.DataFrame, labels: pd.DataFrame, min_height_px: float = 30.0) -> pd.DataFrame:
    """Per (frame, camera): visible objects at least ``min_height_px`` tall, by group.

    Returns one row per frame and camera (frames without any such object count 0), columns ``frame``,
    ``sensor``, ``vehicles`` (car/van/truck/bus), ``cycles`` (bicycle/motorcycle), ``pedestrians``.
    """
    cameras = sorted(labels.loc[labels["sensor_type"] == "camera", "sensor"].unique())
    index = pd.MultiIndex.from_product([frames["frame"].to_numpy(), cameras], names=["frame", "sensor"])
    tall = _visible_camera(labels, min_height_px)
    group = np.select([tall["cls"].isin(VEHICLE_CLASSES), tall["cls"].isin(CYCLE_CLASSES),
                       tall["cls"] == "pedestrian"], ["vehicles", "cycles", "pedestrians"], "other")
    counts = (tall.assign(group=group).groupby(["frame", "sensor", "group"]).size().unstack("group")
              .reindex(index).reindex(columns=["vehicles", "cycles", "pedestrians"]).fillna(0).astype(np.int64))
    return counts.reset_index()


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of matching rows of two (N, 4) x1, y1, x2, y2 arrays."""
    w = np.clip(np.minimum(a[:, 2], b[:, 2]) - np.maximum(a[:, 0], b[:, 0]), 0, None)
    h = np.clip(np.minimum(a[:, 3], b[:, 3]) - np.maximum(a[:, 1], b[:, 1]), 0, None)
    inter = w * h
    area = lambda r: (r[:, 2] - r[:, 0]) * (r[:, 3] - r[:, 1])  # noqa: E731
    return inter / np.maximum(area(a) + area(b) - inter, 1e-9)


def near_duplicates(frames: pd.DataFrame, labels: pd.DataFrame, sensor: str, *, min_travel_m: float = 1.0,
                    min_iou: float = 0.8, min_object_px: float = 10.0) -> np.ndarray:
    """(F,) bool over ``frames`` sorted by frame: True where the frame nearly repeats the one before it (see the
    module docstring). The first frame is never a near-duplicate."""
    frames = frames.sort_values("frame").reset_index(drop=True)
    ego = frames[["ego_x_m", "ego_y_m"]].to_numpy()
    moved = np.r_[np.inf, np.hypot(*np.diff(ego, axis=0).T)]
    cam = _visible_camera(labels[labels["sensor"] == sensor], min_object_px)
    boxes = {f: g.set_index("track_id")[["x1", "y1", "x2", "y2"]] for f, g in cam.groupby("frame")}
    empty = pd.DataFrame(columns=["x1", "y1", "x2", "y2"], dtype=np.float64)
    out = np.zeros(len(frames), dtype=bool)
    for i in range(1, len(frames)):
        if moved[i] >= min_travel_m:
            continue
        prev, cur = boxes.get(frames["frame"][i - 1], empty), boxes.get(frames["frame"][i], empty)
        if set(prev.index) != set(cur.index):
            continue
        ious = _iou(prev.sort_index().to_numpy(np.float64), cur.sort_index().to_numpy(np.float64))
        out[i] = bool(np.all(ious >= min_iou))
    return out


def near_duplicate_rate(frames: pd.DataFrame, labels: pd.DataFrame, sensor: str, **kwargs: float) -> float:
    """Share of a record's frames after the first that are near-duplicates (0.0 for fewer than two frames)."""
    if len(frames) < 2:
        return 0.0
    return float(near_duplicates(frames, labels, sensor, **kwargs).sum() / (len(frames) - 1))
