"""The record writers' closed-form parts (pipeline.core.record_writers)."""

from __future__ import annotations

import numpy as np


def test_depth_png_values_round_half_to_even_and_clip():
    from pipeline.core.record import DEPTH_SCALE
    from pipeline.core.record_writers.camera import depth_png

    depth = np.float32([[1.5, 0.0, 300.0, 2.0], [384.5 / 256, 385.5 / 256, 0.5 / 256, 7.0]])
    valid = np.array([[True, True, True, False], [True, True, True, True]])
    assert depth_png(depth, valid, np.float32(DEPTH_SCALE)).tolist() == [[384, 1, 65535, 0], [384, 386, 1, 1792]]
