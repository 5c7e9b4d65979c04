"""Frame selection of the render stage: even spacing, and no run of frames from a standing ego."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.stages.render import select_frames


def _ego(speeds_mps: list[float], hz: float = 10.0) -> pd.DataFrame:
    """Ego rows of a straight drive at the given speed per frame (position after each frame's interval)."""
    x = np.r_[0.0, np.cumsum(np.asarray(speeds_mps[1:]) / hz)]
    n = len(speeds_mps)
    return pd.DataFrame({"frame": np.arange(n), "time_s": np.arange(n) / hz, "x_m": x, "y_m": 0.0})


def test_a_fast_ego_keeps_the_evenly_spaced_selection():
    ego = _ego([12.0] * 21)  # 1.2 m per frame
    frames = ego["frame"].to_numpy()
    assert select_frames(frames, 3, ego) == [0, 10, 20] == select_frames(frames, 3)
    assert select_frames(frames, None, ego) == list(range(21))


def test_a_standing_ego_gives_one_frame_every_two_seconds():
    # 2 s driving at 12 m/s, 6 s standing, 2 s driving: the 60 standing frames give 3 (every 2 s, 20 frames).
    ego = _ego([12.0] * 21 + [0.0] * 60 + [12.0] * 20)
    frames = ego["frame"].to_numpy()
    kept = select_frames(frames, None, ego)
    standing = [f for f in kept if 21 <= f <= 80]
    assert standing == [40, 60, 80]
    assert len(kept) == 21 + 3 + 20
    # Asking for more frames than are not standing gives those, not repeats.
    assert select_frames(frames, 90, ego) == kept
    # A slow ego (0.5 m per frame) keeps every 2nd frame.
    slow = _ego([5.0] * 11)
    assert select_frames(slow["frame"].to_numpy(), None, slow) == [0, 2, 4, 6, 8, 10]


def test_bad_count():
    with pytest.raises(ValueError, match="--frames"):
        select_frames(np.arange(5), 0)
