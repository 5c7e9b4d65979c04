"""CenterNet targets, decoding and letterboxing: closed-form cases."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pipeline.detect.data import Letterbox, letterbox
from pipeline.detect.losses import build_targets, detection_loss
from pipeline.detect.model import decode


def test_one_box():
    # Box 16 x 8 px centred at (26, 14): centre cell (row 3, col 6), offset (0.5, 0.5).
    t = build_targets(np.array([[18.0, 10.0, 34.0, 18.0]], np.float32), np.array([1]), np.zeros((0, 4)), 2, (8, 10))
    assert t["heatmap"][1, 3, 6] == 1.0 and t["heatmap"][0].max() == 0.0
    assert (t["heatmap"][1] == 1.0).sum() == 1 and t["heatmap"][1, 3, 5] < 1.0
    assert t["reg_mask"].sum() == 1 and t["reg_mask"][3, 6]
    assert t["size"][:, 3, 6] == pytest.approx(np.log([4.0, 2.0]))
    assert t["offset"][:, 3, 6] == pytest.approx([0.5, 0.5])
    assert not t["ignore"].any()


def test_crowd_region_marks_cells_by_their_centres():
    t = build_targets(np.zeros((0, 4), np.float32), np.zeros(0, np.int64), np.array([[0.0, 0.0, 10.0, 6.0]]), 1, (4, 4))
    # cell centres at 2, 6, 10, ... px: columns 0-1 (2, 6 < 10), row 0 only (2 < 6, 6 not < 6)
    assert t["ignore"].tolist() == [[True, True, False, False]] + [[False] * 4] * 3


def test_decode_inverts_the_targets():
    box = np.array([[18.0, 10.0, 34.0, 18.0]], np.float32)
    t = build_targets(box, np.array([1]), np.zeros((0, 4)), 2, (8, 10))
    logit = torch.logit(torch.from_numpy(t["heatmap"]).clamp(1e-4, 1 - 1e-4))[None]
    outputs = {"heatmap": logit, "size": torch.from_numpy(t["size"])[None],
               "offset": torch.from_numpy(t["offset"])[None]}
    boxes, scores, classes = decode(outputs, 1)
    assert boxes[0, 0].tolist() == pytest.approx(box[0].tolist(), abs=1e-4)
    assert classes[0, 0] == 1 and scores[0, 0] > 0.99


def test_loss_is_lower_for_the_right_answer():
    t = build_targets(np.array([[18.0, 10.0, 34.0, 18.0]], np.float32), np.array([0]), np.zeros((0, 4)), 1, (8, 10))
    tt = {k: torch.from_numpy(v)[None] for k, v in t.items()}
    good = {"heatmap": torch.logit(tt["heatmap"].clamp(1e-3, 1 - 1e-3)), "size": tt["size"], "offset": tt["offset"]}
    bad = {"heatmap": torch.zeros(1, 1, 8, 10), "size": torch.zeros(1, 2, 8, 10), "offset": torch.zeros(1, 2, 8, 10)}
    assert detection_loss(good, tt)["loss"] < 0.1 * detection_loss(bad, tt)["loss"]
    assert detection_loss(good, tt)["size"] == 0.0


def test_letterbox_maps_back():
    rgb = np.zeros((600, 800, 3), np.uint8)
    img, lb = letterbox(rgb, (384, 320))
    assert lb.scale == pytest.approx(0.48) and img.shape == (320, 384, 3)
    assert img[300, 10, 0] == pytest.approx(0.5)  # padding below the image
    back = lb.to_original(np.array([[48.0, 24.0, 96.0, 400.0]]), 800, 600)
    assert back[0].tolist() == pytest.approx([100.0, 50.0, 200.0, 600.0])  # clipped at the bottom
    assert Letterbox.fit(800, 600, (384, 288)).scale == pytest.approx(0.48)


def test_cells_near_the_centre_regress_the_same_box():
    # 40 x 24 px box centred at (40, 20): 10 x 6 cells, centre cell (row 5, col 10).
    box = np.array([[20.0, 8.0, 60.0, 32.0]], np.float32)
    t = build_targets(box, np.array([0]), np.zeros((0, 4)), 1, (12, 20))
    rows, cols = np.nonzero(t["reg_weight"])
    assert t["reg_mask"].sum() == 1 and t["reg_weight"][5, 10] == t["reg_weight"].max()
    assert t["reg_weight"].sum() == pytest.approx(1.0)
    assert len(rows) > 1 and np.abs(cols - 10).max() <= 0.54 * 10 / 2 and np.abs(rows - 5).max() <= 0.54 * 6 / 2
    # Every weighted cell, decoded on its own, gives back the box.
    centre_x, centre_y = (cols + t["offset"][0, rows, cols]) * 4, (rows + t["offset"][1, rows, cols]) * 4
    assert centre_x == pytest.approx(40.0) and centre_y == pytest.approx(20.0)
    sizes = np.exp(t["size"][:, rows, cols]).T * 4
    assert np.allclose(sizes, [40.0, 24.0], rtol=1e-5)


def test_the_smaller_box_owns_shared_cells():
    big = [0.0, 0.0, 64.0, 48.0]  # centre (32, 24): cell (6, 8)
    small = [28.0, 20.0, 36.0, 28.0]  # 8 x 8 px, same centre
    t = build_targets(np.array([big, small], np.float32), np.array([0, 0]), np.zeros((0, 4)), 1, (12, 16))
    assert np.exp(t["size"][:, 6, 8]) * 4 == pytest.approx([8.0, 8.0])
    assert np.exp(t["size"][:, 6, 11]) * 4 == pytest.approx([64.0, 48.0])  # beyond the small box's area


def test_decode_keeps_one_class_per_cell():
    heat = torch.full((1, 2, 4, 4), -10.0)
    heat[0, 0, 1, 1], heat[0, 1, 1, 1] = 2.0, 1.0  # a car and a less likely truck at the same cell
    outputs = {"heatmap": heat, "size": torch.zeros(1, 2, 4, 4), "offset": torch.full((1, 2, 4, 4), 0.5)}
    _, scores, classes = decode(outputs, 3)
    assert classes[0, 0] == 0 and scores[0, 0] == pytest.approx(torch.sigmoid(torch.tensor(2.0)).item())
    assert scores[0, 1] < 1e-3  # the truck peak is gone; what follows is background
