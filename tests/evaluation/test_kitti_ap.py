"""KITTI AP on hand-made cases with closed-form answers, in every mode.

Recall of the devkit arithmetic used below: p is the 41-point precision array, AP_R40 =
mean(p[1:41]) and AP_R11 = mean(p[0::4]). In official and port modes p[i] is the precision at the i-th
threshold of getThresholds (one per true positive while there are fewer than 40 ground-truth
objects), the rest 0; in exact mode p[i] is the best precision at recall >= i / 40.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from evaluation.kitti import KittiFormatError, evaluate_kitti, kitti_summary_markdown
from evaluation.kitti.ap import devkit_thresholds

MODES = ("official", "port", "exact")


def obj(kind="Car", x=0.0, z=20.0, ry=0.0, bbox=(100.0, 100.0, 200.0, 160.0), trunc=0.0, occ=0, alpha=0.0, score=None):
    """One KITTI label line; the 3D box is a 1.5 x 1.6 x 4 m car at (x, 1.7, z)."""
    fields = [kind, trunc, occ, alpha, *bbox, 1.5, 1.6, 4.0, x, 1.7, z, ry]
    if kind == "DontCare":
        fields = [kind, -1, -1, -10, *bbox, -1, -1, -1, -1000, -1000, -1000, -10]
    text = " ".join(str(f) for f in fields)
    return text if score is None else f"{text} {score}"


def far(i: int) -> dict:
    """Keyword arguments of an object far from every other (2D and 3D)."""
    return {"x": -30.0 + 6 * i, "z": 40.0 + 5 * i, "bbox": (300.0 + 60 * i, 50.0, 350.0 + 60 * i, 110.0)}


def write(root: Path, gt: dict[str, list[str]], det: dict[str, list[str]]) -> tuple[Path, Path]:
    for name, frames in (("gt", gt), ("det", det)):
        (root / name).mkdir()
        for frame, lines in frames.items():
            (root / name / f"{frame}.txt").write_text("".join(line + "\n" for line in lines))
    return root / "gt", root / "det"


def run(tmp_path: Path, gt, det, mode: str, **kwargs) -> dict:
    root = tmp_path / f"{mode}-{len(list(tmp_path.iterdir()))}"
    root.mkdir()
    return evaluate_kitti(*write(root, gt, det), mode=mode, **kwargs)


def ap(result: dict, metric: str, cls: str = "Car", difficulty: str = "easy") -> tuple[float, float]:
    entry = result["results"][cls][difficulty][metric]
    return entry["ap_r40"], entry["ap_r11"]


@pytest.mark.parametrize("mode", MODES)
def test_one_of_two_cars_found(tmp_path: Path, mode: str) -> None:
    gt = {"000000": [obj(**far(0)), obj(**far(1))]}
    det = {"000000": [obj(**far(0), score=0.9)]}
    result = run(tmp_path, gt, det, mode)
    # official: one threshold, p = [1, 0, ...]; exact: precision 1 up to recall 1/2
    expected = (0.0, 1 / 11) if mode != "exact" else (0.5, 6 / 11)
    for metric in ("bbox", "bev", "3d", "aos"):
        assert ap(result, metric) == pytest.approx(expected, abs=1e-12)
    assert result["results"]["Car"]["easy"]["num_gt"] == 2
    json.dumps(result)


@pytest.mark.parametrize("mode", MODES)
def test_fewer_than_40_objects_all_found(tmp_path: Path, mode: str) -> None:
    gt = {"000000": [obj(**far(0)), obj(**far(1))]}
    det = {"000000": [obj(**far(0), score=0.9), obj(**far(1), score=0.8)]}
    result = run(tmp_path, gt, det, mode)
    # official: two thresholds -> p = [1, 1, 0, ...]: R40 = 1/40, R11 = 1/11; exact: a perfect 1
    expected = (1 / 40, 1 / 11) if mode != "exact" else (1.0, 1.0)
    assert ap(result, "bev") == pytest.approx(expected, abs=1e-12)
    assert ap(result, "3d") == pytest.approx(expected, abs=1e-12)


def test_devkit_thresholds() -> None:
    assert devkit_thresholds(np.array([0.8, 0.9]), 2).tolist() == [0.9, 0.8]
    assert len(devkit_thresholds(np.linspace(1, 0.01, 80), 80)) == 41  # one per 1/40 of recall
    assert len(devkit_thresholds(np.linspace(1, 0.01, 40), 40)) == 40  # R40 of a perfect detector = 39/40
    assert devkit_thresholds(np.zeros(0), 5).tolist() == []


@pytest.mark.parametrize("mode", MODES)
def test_false_positive_ranked_above_true_positive(tmp_path: Path, mode: str) -> None:
    gt = {"000000": [obj(**far(0))]}
    det = {"000000": [obj(**far(1), score=0.9), obj(**far(0), score=0.8)]}
    result = run(tmp_path, gt, det, mode)
    expected = (0.0, 0.5 / 11) if mode != "exact" else (0.5, 0.5)
    assert ap(result, "bbox") == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("mode", MODES)
def test_identical_rotated_boxes(tmp_path: Path, mode: str) -> None:
    """The port's float32 rotated IoU loses identical rotated boxes; the devkit's double-precision
    polygons (official) and exact mode find them."""
    gt = {"000000": [obj(x=1.0, z=20.0, ry=0.3)]}
    det = {"000000": [obj(x=1.0, z=20.0, ry=0.3, score=0.9)]}
    result = run(tmp_path, gt, det, mode)
    # one car found: the devkit's curve has one threshold, p = [1, 0, ...]
    expected = {"official": (0.0, 1 / 11), "port": (0.0, 0.0), "exact": (1.0, 1.0)}[mode]
    assert ap(result, "bev") == pytest.approx(expected, abs=1e-12)
    assert ap(result, "3d") == pytest.approx(expected, abs=1e-12)
    assert ap(result, "bbox")[1] == pytest.approx(1 / 11 if mode != "exact" else 1.0)


@pytest.mark.parametrize("mode", MODES)
def test_difficulty_filters(tmp_path: Path, mode: str) -> None:
    box = (100.0, 100.0, 200.0, 140.0)  # 40 px high: not above the easy minimum
    gt = {
        "000000": [
            obj(bbox=box),
            obj(**far(1), occ=1),
            obj(**far(2), trunc=0.2),
            obj(**far(3), occ=2, trunc=0.4),
            obj(**far(4), occ=3),
            obj(**{**far(5), "bbox": (800.0, 50.0, 850.0, 90.01)}),
        ]
    }
    result = run(tmp_path, gt, {}, mode)
    counts = {d: (e["num_gt"], e["num_gt_ignored"]) for d, e in result["results"]["Car"].items()}
    assert counts == {"easy": (1, 5), "moderate": (4, 2), "hard": (5, 1)}
    assert result["counts"]["frames_without_detection_file"] == 1


@pytest.mark.parametrize("mode", MODES)
def test_ignored_ground_truth_absorbs_its_detection(tmp_path: Path, mode: str) -> None:
    # a 30 px car is ignored at easy; its 30 px detection is ignored too (below the height): no FP
    small = {**far(0), "bbox": (300.0, 50.0, 350.0, 80.0)}
    gt = {"000000": [obj(**small), obj(**far(1))]}
    det = {"000000": [obj(**small, score=0.95), obj(**far(1), score=0.5)]}
    result = run(tmp_path, gt, det, mode)
    assert ap(result, "bbox", difficulty="easy") == pytest.approx((0, 1 / 11) if mode != "exact" else (1, 1))
    assert ap(result, "bbox", difficulty="moderate") == pytest.approx(
        (1 / 40, 1 / 11) if mode != "exact" else (1, 1)
    )


@pytest.mark.parametrize("mode", MODES)
def test_dontcare_without_3d_box_absorbs_false_positives_in_2d_only(tmp_path: Path, mode: str) -> None:
    region = (600.0, 40.0, 700.0, 120.0)
    gt = {"000000": [obj(**far(0)), obj("DontCare", bbox=region)]}
    fp_in_dontcare = obj(x=10.0, z=30.0, bbox=(610.0, 50.0, 690.0, 110.0), score=0.9)
    det = {"000000": [fp_in_dontcare, obj(**far(0), score=0.8)]}
    result = run(tmp_path, gt, det, mode)
    assert result["counts"]["dontcare"] == 1
    # 2D: the FP is inside the DontCare region and not counted; BEV: DontCare has no 3D box, FP counts
    assert ap(result, "bbox") == pytest.approx((0, 1 / 11) if mode != "exact" else (1, 1))
    assert ap(result, "bev") == pytest.approx((0, 0.5 / 11) if mode != "exact" else (0.5, 0.5))


@pytest.mark.parametrize("mode", MODES)
def test_dontcare_with_3d_box_absorbs_in_bev_and_3d_like_the_devkit(tmp_path: Path, mode: str) -> None:
    """The devkit tests every metric's DontCare regions with that metric's overlap over the
    detection's own size (BEV area, volume); the Python port does so in 2D only."""
    dontcare = "DontCare -1 -1 -10 600.0 40.0 700.0 120.0 2.0 3.0 6.0 10.0 1.7 30.0 0.0"
    gt = {"000000": [obj(**far(0)), dontcare]}
    # 4 x 1.6 m footprint, 1.5 m high, wholly inside the 6 x 3 x 2 m region: share 1 in BEV and 3D
    fp_in_dontcare = obj(x=10.0, z=30.0, bbox=(610.0, 50.0, 690.0, 110.0), score=0.9)
    det = {"000000": [fp_in_dontcare, obj(**far(0), score=0.8)]}
    result = run(tmp_path, gt, det, mode)
    absorbed = {"official": (0, 1 / 11), "port": (0, 0.5 / 11), "exact": (1, 1)}[mode]
    assert ap(result, "bev") == pytest.approx(absorbed)
    assert ap(result, "3d") == pytest.approx(absorbed)


def test_two_dimensional_detection_meets_dontcare_sentinel_in_bev_like_the_devkit(tmp_path: Path) -> None:
    """The devkit reads "-1 -1 -1 -1000 -1000 -1000" as a 1 x 1 m square at (-1000, -1000), so a
    2D-only detection lies wholly inside a KITTI DontCare region in BEV and is not a false positive
    there; in 3D its height range is empty, so it stays one. Official mode reproduces this; exact
    mode leaves objects without a 3D box out of BEV and 3D."""
    gt = {"000000": [obj(**far(0)), obj("DontCare", bbox=(600.0, 40.0, 700.0, 120.0))]}
    two_d = "Car -1 -1 -10 300.0 150.0 360.0 200.0 -1 -1 -1 -1000 -1000 -1000 -10 0.9"
    det = {"000000": [two_d, obj(**far(0), score=0.8)]}
    official = run(tmp_path, gt, det, "official")
    assert ap(official, "bev") == pytest.approx((0, 1 / 11))
    assert ap(official, "3d") == pytest.approx((0, 0.5 / 11))
    exact = run(tmp_path, gt, det, "exact")
    assert ap(exact, "bev") == pytest.approx((0.5, 0.5))


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize(
    ("cls", "neighbour", "other"), [("Car", "Van", "Truck"), ("Pedestrian", "Person_sitting", "Cyclist")]
)
def test_neighbour_classes_are_ignored_not_missed(
    tmp_path: Path, mode: str, cls: str, neighbour: str, other: str
) -> None:
    for name, expected_exact in ((neighbour, (1.0, 1.0)), (other, (0.5, 0.5))):
        gt = {"000000": [obj(cls, **far(0)), obj(name, **far(1))]}
        det = {"000000": [obj(cls, **far(1), score=0.9), obj(cls, **far(0), score=0.8)]}
        root = tmp_path / name
        root.mkdir()
        result = evaluate_kitti(*write(root, gt, det), mode=mode, classes=(cls,))
        assert result["results"][cls]["easy"]["num_gt"] == 1
        if mode == "exact":
            # a detection on the neighbour is neither TP nor FP; on another class it is a FP
            assert ap(result, "bbox", cls) == pytest.approx(expected_exact)
        else:
            assert ap(result, "bbox", cls)[1] == pytest.approx(expected_exact[0] / 11)


@pytest.mark.parametrize("mode", MODES)
def test_aos(tmp_path: Path, mode: str) -> None:
    gt = {"000000": [obj(**far(0), alpha=0.0), obj(**far(1), alpha=0.0)]}
    det = {"000000": [obj(**far(0), alpha=np.pi / 2, score=0.9), obj(**far(1), alpha=0.0, score=0.8)]}
    result = run(tmp_path, gt, det, mode)
    if mode == "exact":
        # similarity (1 + cos) / 2: 0.5 at recall 1/2, (0.5 + 1) / 2 at recall 1
        assert ap(result, "aos") == pytest.approx((0.75, 0.75), abs=1e-12)
    else:
        assert ap(result, "aos") == pytest.approx((0.75 / 40, 0.75 / 11), abs=1e-12)


def test_aos_skipped_when_alpha_unknown(tmp_path: Path) -> None:
    gt = {"000000": [obj(**far(0))]}
    det = {"000000": [obj(**far(0), alpha=-10, score=0.9)]}
    result = run(tmp_path, gt, det, "exact")
    assert ap(result, "aos") == (None, None)
    assert result["notes"] and "alpha" in result["notes"][0]
    assert ap(result, "bbox") == (1.0, 1.0)


def test_many_objects_official_equals_exact_when_thresholds_hit_recall_steps(tmp_path: Path) -> None:
    # 80 cars found with distinct scores: getThresholds picks every other score, one per 1/40 recall
    n = 80
    gt = {f"{i:06d}": [obj(**far(0))] for i in range(n)}
    det = {f"{i:06d}": [obj(**far(0), score=1 - i / 100)] for i in range(n)}
    official = run(tmp_path, gt, det, "official", metrics=("bbox",))
    exact = run(tmp_path, gt, det, "exact", metrics=("bbox",))
    assert ap(official, "bbox") == pytest.approx((1.0, 1.0))
    assert ap(exact, "bbox") == pytest.approx((1.0, 1.0))
    assert official["counts"]["frames"] == n


def test_exact_ap_is_none_without_ground_truth(tmp_path: Path) -> None:
    result = run(tmp_path, {"000000": [obj(**far(0))]}, {}, "exact", classes=("Cyclist",))
    assert ap(result, "bev", "Cyclist") == (None, None)


def test_arguments_and_inconsistent_frames_fail(tmp_path: Path) -> None:
    gt_dir, det_dir = write(tmp_path, {"000000": [obj()]}, {"000001": [obj(score=0.5)]})
    with pytest.raises(KittiFormatError, match="000001"):
        evaluate_kitti(gt_dir, det_dir)
    (det_dir / "000001.txt").unlink()
    with pytest.raises(ValueError, match="mode"):
        evaluate_kitti(gt_dir, det_dir, mode="fast")
    with pytest.raises(ValueError, match="metrics"):
        evaluate_kitti(gt_dir, det_dir, metrics=("bev", "map"))
    with pytest.raises(ValueError, match="Truck"):
        evaluate_kitti(gt_dir, det_dir, classes=("Truck",), min_overlap={"Car": 0.7})
    with pytest.raises(KittiFormatError, match="calib"):
        evaluate_kitti(gt_dir, det_dir, calib_dir=tmp_path)


def test_min_overlap_is_strict_and_per_metric(tmp_path: Path) -> None:
    # detection shifted by a quarter of the 2D box width: 2D IoU = 0.75 / 1.25 = 0.6
    gt = {"000000": [obj(bbox=(100.0, 100.0, 200.0, 160.0))]}
    det = {"000000": [obj(bbox=(125.0, 100.0, 225.0, 160.0), score=0.9)]}
    gt_dir, det_dir = write(tmp_path, gt, det)
    found = evaluate_kitti(
        gt_dir, det_dir, mode="exact", classes=("Car",), min_overlap={"Car": {"bbox": 0.59, "bev": 0.7, "3d": 0.7}}
    )
    assert ap(found, "bbox") == (1.0, 1.0)
    missed = evaluate_kitti(gt_dir, det_dir, mode="exact", classes=("Car",), min_overlap={"Car": 0.6})
    assert ap(missed, "bbox") == (0.0, 0.0)
    assert found["settings"]["min_overlap"]["Car"] == {"bbox": 0.59, "bev": 0.7, "3d": 0.7}


def test_summary_markdown(tmp_path: Path) -> None:
    gt = {"000000": [obj(**far(0)), obj(**far(1))]}
    det = {"000000": [obj(**far(0), score=0.9)]}
    text = kitti_summary_markdown(run(tmp_path, gt, det, "exact"))
    assert "| Car | BEV | 0.7 | 50.00 |" in text
    assert text.count("\n|") >= 2 + 3 * 4


def test_official_mode_skips_what_the_devkit_does_not_evaluate(tmp_path: Path) -> None:
    """The devkit evaluates BEV/3D for a class only if one of its detections has a 3D box, and a class
    at all only if it is detected: official mode reports None there (with a note), port mode 0."""
    gt = {"000000": [obj(**far(0)), obj("Cyclist", **far(1))]}
    det = {"000000": ["Car -1 -1 -10 300.0 50.0 350.0 110.0 -1 -1 -1 -1000 -1000 -1000 -10 0.9"]}
    official = run(tmp_path, gt, det, "official", metrics=("bbox", "bev", "3d"))
    assert ap(official, "bbox") == pytest.approx((0.0, 1 / 11))
    assert ap(official, "bev") == ap(official, "3d") == (None, None)
    assert ap(official, "bbox", "Cyclist") == (None, None)
    assert any("Car: bev, 3d not evaluated" in n for n in official["notes"])
    port = run(tmp_path, gt, det, "port", metrics=("bbox", "bev", "3d"))
    assert ap(port, "bev") == (0.0, 0.0) and ap(port, "bbox", "Cyclist") == (0.0, 0.0)
