"""Tall-vehicle counts and near-duplicate frames on hand-made frames and labels."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.core.scene_content import near_duplicate_rate, near_duplicates, tall_counts


def _frames(xs: list[float]) -> pd.DataFrame:
    return pd.DataFrame({"frame": np.arange(len(xs), dtype=np.int32), "ego_x_m": xs, "ego_y_m": 0.0})


def _label(frame: int, track: int, cls: str, box: tuple[float, float, float, float], visible: bool = True,
           sensor: str = "front") -> dict:
    x1, y1, x2, y2 = box
    return {"frame": frame, "sensor": sensor, "sensor_type": "camera", "track_id": track, "cls": cls,
            "visible": visible, "x1": x1, "y1": y1, "x2": x2, "y2": y2}


def test_tall_counts_by_group_threshold_and_visibility():
    labels = pd.DataFrame([
        _label(0, 1, "car", (0, 0, 50, 30)),  # exactly 30 px: counts
        _label(0, 2, "van", (0, 0, 50, 29.5)),  # just under
        _label(0, 3, "bus", (0, 10, 50, 100)),
        _label(0, 4, "pedestrian", (0, 0, 10, 40)),
        _label(0, 5, "bicycle", (0, 0, 10, 40)),
        _label(1, 1, "car", (0, 0, 50, 80), visible=False),  # not visible: never counts
    ])
    counts = tall_counts(_frames([0.0, 1.0, 2.0]), labels).set_index("frame")
    assert counts.loc[0, ["vehicles", "cycles", "pedestrians"]].tolist() == [2, 1, 1]
    assert counts.loc[1, "vehicles"] == 0 and counts.loc[2, "vehicles"] == 0  # frames without labels count 0
    assert len(counts) == 3


def test_near_duplicates_need_a_standing_ego_and_the_same_boxes():
    box = (100.0, 100.0, 200.0, 200.0)
    shifted = (150.0, 100.0, 250.0, 200.0)  # IoU 1/3 with box
    labels = pd.DataFrame([
        _label(0, 1, "car", box),
        _label(1, 1, "car", box),  # ego stood, same box: duplicate
        _label(2, 1, "car", shifted),  # ego stood, car moved: new
        _label(3, 1, "car", shifted), _label(3, 2, "car", box),  # a new car appeared: new
        _label(4, 1, "car", shifted), _label(4, 2, "car", box),  # same set, but the ego moved 1 m: new
        _label(5, 1, "car", shifted), _label(5, 2, "car", box), _label(5, 3, "car", (0, 0, 5, 5)),  # < 10 px: ignored
    ])
    frames = _frames([0.0, 0.2, 0.4, 0.6, 1.6, 1.7])
    np.testing.assert_array_equal(near_duplicates(frames, labels, "front"), [False, True, False, False, False, True])
    assert near_duplicate_rate(frames, labels, "front") == 2 / 5
    assert near_duplicate_rate(frames.iloc[:1], labels, "front") == 0.0
    # Two empty frames of a standing ego repeat each other too.
    assert near_duplicates(_frames([0.0, 0.0]), labels.iloc[:0], "front").tolist() == [False, True]
