"""Rotated BEV and 3D IoU: against shapely, closed forms, and the port's coincident-box defect."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import example, given, settings
from hypothesis import strategies as st

from evaluation.kitti.iou import (
    bev_intersection_exact,
    bev_intersection_port,
    bev_iou,
    box3d_iou,
    image_box_overlap,
    rect_corners,
)

coord = st.floats(-6, 6, allow_nan=False)
size = st.floats(0.05, 6, allow_nan=False)
angle = st.floats(-2 * np.pi, 2 * np.pi, allow_nan=False)
rect = st.tuples(coord, coord, size, size, angle)


def _shapely_area(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """GEOS's snap-rounding overlay on a 1e-12 m grid (robust; moves an area by < 1e-10 here). Its default floating
    overlay is not robust: it returns 0 for two boxes with one centre and angle that share their two long edges (the
    example below; the right answer is 3.0 x 2.51)."""
    pa, pb = shapely.polygons(rect_corners(a)), shapely.polygons(rect_corners(b))
    return shapely.area(shapely.intersection(pa, pb, grid_size=1e-12))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(rect, rect), min_size=1, max_size=20))
@example([((0.0, -2.9156826462677468, 3.0, 2.51, 2.2734375), (0.0, -2.9156826462677468, 3.2109375, 2.51, 2.2734375))])
def test_exact_intersection_matches_shapely(pairs) -> None:
    a = np.array([p[0] for p in pairs])
    b = np.array([p[1] for p in pairs])
    np.testing.assert_allclose(bev_intersection_exact(a, b), _shapely_area(a, b), rtol=0, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(rect, st.integers(0, 3))
def test_exact_iou_of_coincident_and_quarter_turned_boxes(box, quarter_turns) -> None:
    a = np.array([box])
    assert bev_iou(a, a, rotated="float64")[0] == pytest.approx(1.0, abs=1e-9)
    # a square turned by a multiple of 90 degrees is the same polygon
    square = np.array([[box[0], box[1], box[2], box[2], box[4]]])
    turned = square.copy()
    turned[0, 4] += quarter_turns * np.pi / 2
    assert bev_iou(square, turned, rotated="float64")[0] == pytest.approx(1.0, abs=1e-9)


def test_random_pairs_vectorised_match_shapely() -> None:
    rng = np.random.default_rng(1)
    n = 5000
    a = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(0.1, 5, (n, 2)), rng.uniform(-4, 4, n)])
    b = np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(0.1, 5, (n, 2)), rng.uniform(-4, 4, n)])
    b[:500] = a[:500]  # coincident
    b[500:1000, :2] = a[500:1000, :2] + 1e-7  # nearly coincident
    b[500:1000, 2:] = a[500:1000, 2:]
    reference = _shapely_area(a, b)
    np.testing.assert_allclose(bev_intersection_exact(a, b), reference, rtol=0, atol=1e-9)
    # the port's float32 algorithm agrees away from degenerate contacts
    np.testing.assert_allclose(bev_intersection_port(a[1000:], b[1000:]), reference[1000:], rtol=1e-4, atol=1e-4)


def test_port_algorithm_loses_coincident_rotated_boxes() -> None:
    """The port's inclusion test has no tolerance and collinear edges never cross, so for identical
    rotated rectangles float32 rounding drops corners and the intersection collapses."""
    box = np.array([[1.0, 20.0, 4.0, 1.6, 0.3]])
    assert bev_iou(box, box, rotated="float64")[0] == pytest.approx(1.0, abs=1e-12)
    assert bev_iou(box, box, rotated="port")[0] == 0.0
    # axis-aligned boxes are computed without rounding, so the port gets them right
    aligned = np.array([[1.0, 20.0, 4.0, 1.6, 0.0]])
    assert bev_iou(aligned, aligned, rotated="port")[0] == pytest.approx(1.0, abs=1e-5)  # float32
    # over many random coincident boxes most lose area in the port
    rng = np.random.default_rng(0)
    boxes = np.column_stack([rng.uniform(-20, 20, (200, 2)), rng.uniform(1, 5, (200, 2)), rng.uniform(-3, 3, 200)])
    port = bev_iou(boxes, boxes, rotated="port")
    assert np.mean(port < 0.99) > 0.5
    np.testing.assert_allclose(bev_iou(boxes, boxes, rotated="float64"), 1.0, atol=1e-12)


def test_3d_iou_uses_camera_y_down() -> None:
    # box = (x, y, z, h, w, l, ry), y is the bottom; it spans [y - h, y]
    a = np.array([[0.0, 2.0, 10.0, 1.0, 2.0, 4.0, 0.7]])  # y in [1, 2]
    b = np.array([[0.0, 2.5, 10.0, 2.0, 2.0, 4.0, 0.7]])  # y in [0.5, 2.5]
    # overlap in y is [1, 2]: 1 m of 1 m and 2 m -> IoU = 8 / (8 + 16 - 8)
    assert box3d_iou(a, b, rotated="float64")[0] == pytest.approx(0.5, abs=1e-12)
    disjoint = b.copy()
    disjoint[0, 1] = 5.0  # y in [3, 5]
    assert box3d_iou(a, disjoint, rotated="float64")[0] == 0.0
    shifted = a.copy()
    shifted[0, 0] += 2.0  # half the length: with ry = 0 the length lies along x
    shifted[0, 6] = a[0, 6] = 0.0
    assert box3d_iou(a, shifted, rotated="float64")[0] == pytest.approx(1.0 / 3.0, abs=1e-12)


def test_image_box_overlap() -> None:
    a = np.array([[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 10.0]])
    b = np.array([[5.0, 0.0, 15.0, 10.0], [10.0, 0.0, 20.0, 10.0], [2.0, 2.0, 4.0, 4.0]])
    np.testing.assert_allclose(image_box_overlap(a, b), [50 / 150, 0.0, 4 / 100])
    np.testing.assert_allclose(image_box_overlap(a, b, criterion="a"), [0.5, 0.0, 0.04])
    with pytest.raises(ValueError, match="criterion"):
        image_box_overlap(a, b, criterion="b")


def test_share_of_a_inside_b_bev_and_3d() -> None:
    """criterion "a": the devkit's DontCare test, intersection over the detection's own area or volume."""
    det = np.array([[0.0, 2.0, 10.0, 1.0, 2.0, 4.0, 0.0]])  # 4 x 2 m, y in [1, 2]
    region = np.array([[2.0, 2.0, 10.0, 4.0, 2.0, 4.0, 0.0]])  # shifted by half the length, y in [-2, 2]
    cols = [0, 2, 5, 4, 6]
    assert bev_iou(det[:, cols], region[:, cols], rotated="float64", criterion="a")[0] == pytest.approx(0.5)
    assert box3d_iou(det, region, rotated="float64", criterion="a")[0] == pytest.approx(0.5)
    assert box3d_iou(region, det, rotated="float64", criterion="a")[0] == pytest.approx(4 / 32)
    with pytest.raises(ValueError, match="criterion"):
        bev_iou(det[:, cols], region[:, cols], rotated="float64", criterion="b")
    with pytest.raises(ValueError, match="float64"):
        bev_iou(det[:, cols], region[:, cols], rotated="float32")


def test_sentinel_sizes_are_a_unit_square_as_in_the_devkit() -> None:
    """The devkit builds its polygon from the sizes as read: "-1 -1 -1" is a 1 x 1 m square (a
    rectangle turned by pi), so two sentinels at the same place overlap fully in BEV; in 3D their
    height range [y + 1, y] is empty."""
    sentinel = np.array([[-1000.0, -1000.0, -1000.0, -1.0, -1.0, -1.0, -10.0]])
    assert bev_iou(sentinel[:, [0, 2, 5, 4, 6]], sentinel[:, [0, 2, 5, 4, 6]], rotated="float64")[0] == pytest.approx(1)
    assert box3d_iou(sentinel, sentinel, rotated="float64")[0] == 0.0
    unit = np.array([[-1000.0, -1000.0, 1.0, 1.0, -10.0]])
    assert bev_intersection_exact(sentinel[:, [0, 2, 5, 4, 6]], unit)[0] == pytest.approx(1.0, abs=1e-9)
