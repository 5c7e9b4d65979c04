"""Official-mode KITTI AP against the C++ devkit's own numbers on fixed label sets.

tests/data/kitti/devkit_golden.json holds what the devkit (evaluate_object.cpp, boost::geometry
overlaps) printed for the cases of kitti_devkit_cases.py: detections that are the ground truth
itself (coincident rotated boxes, duplicates), half exact and half jittered, all jittered, with
DontCare regions with and without a 3D box, 2D-only detections, empty frames, and empty ground
truth files. Regenerate with tests/evaluation/regenerate_kitti_devkit_golden.py --devkit PATH.

Tolerance 1e-5: the devkit prints its precisions with 6 decimals (AP error < 1e-6). The rules
checked here matter at a coarser scale: on these sets, DontCare in 2D only moves some AP by 2e-3 or
more per case, and leaving the "-1 -1 -1" sentinel out of BEV by 1.3e-3 where it occurs.
With KITTI_DEVKIT=PATH set, the devkit binary is also run here on the same files.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from evaluation.kitti import evaluate_kitti
from tests.evaluation.kitti_devkit_cases import CASES, write_case
from tests.evaluation.regenerate_kitti_devkit_golden import GOLDEN, case_digest, run_devkit

TOLERANCE = 1e-5
DIFFICULTIES = ("easy", "moderate", "hard")


def _golden() -> dict:
    return json.loads(GOLDEN.read_text())["cases"]


def _compare(result: dict, expected: dict, not_evaluated: list[str] | None = None) -> list[str]:
    """Every (class, metric, difficulty) of the devkit's answer that the result misses by more than
    TOLERANCE, and every AP that is None where the devkit evaluated or a number where it did not."""
    misses = []
    if not_evaluated is not None:
        for cls in ("Car", "Pedestrian", "Cyclist"):
            for metric in ("bbox", "bev", "3d"):
                none = [result["results"][cls][d][metric]["ap_r40"] is None for d in DIFFICULTIES]
                skipped = f"{cls}/{metric}" in not_evaluated
                if any(none) != skipped or len(set(none)) > 1:
                    misses.append(f"{cls} {metric}: AP None {none}, devkit skipped: {skipped}")
    for cls, per_metric in expected.items():
        for metric, per_difficulty in per_metric.items():
            for diff in DIFFICULTIES:
                got = result["results"][cls][diff][metric]
                if got["ap_r40"] is None:
                    misses.append(f"{cls} {metric} {diff}: None, the devkit evaluated it")
                    continue
                for key in ("ap_r40", "ap_r11"):
                    want = per_difficulty[diff][key]
                    if abs(got[key] - want) > TOLERANCE:
                        misses.append(f"{cls} {metric} {diff} {key}: {got[key]:.6f} vs devkit {want:.6f}")
    return misses


@pytest.mark.parametrize("case", sorted(CASES))
def test_official_mode_equals_devkit(tmp_path: Path, case: str) -> None:
    golden = _golden()[case]
    gt_dir, det_dir = write_case(case, tmp_path)
    assert case_digest(gt_dir, det_dir) == golden["sha256"], "case files changed: regenerate the golden values"
    result = evaluate_kitti(gt_dir, det_dir, mode="official", metrics=("bbox", "bev", "3d"))
    assert golden["results"], "the devkit evaluated nothing: a useless case"
    assert _compare(result, golden["results"], golden["not_evaluated"]) == []


def test_cases_cover_what_the_devkit_skips() -> None:
    golden = _golden()
    assert {"Cyclist/bbox", "Cyclist/3d", "Pedestrian/bev", "Pedestrian/3d"} <= set(
        golden["sparse_detections"]["not_evaluated"]
    )
    assert "Pedestrian/bbox" not in golden["sparse_detections"]["not_evaluated"]
    assert all(not case["not_evaluated"] for name, case in golden.items() if name != "sparse_detections")


def test_port_mode_is_not_the_devkit(tmp_path: Path) -> None:
    """The port's float32 rotated IoU loses coincident boxes: on detections equal to the ground
    truth its BEV/3D AP falls far from the devkit's, while its 2D AP (no rotated IoU) agrees."""
    golden = _golden()["gt_as_detection"]["results"]
    gt_dir, det_dir = write_case("gt_as_detection", tmp_path)
    port = evaluate_kitti(gt_dir, det_dir, mode="port", metrics=("bbox", "bev", "3d"))
    misses = _compare(port, golden)
    assert misses and all(" bbox " not in m for m in misses)
    assert port["results"]["Car"]["moderate"]["bev"]["ap_r40"] < golden["Car"]["bev"]["moderate"]["ap_r40"] - 0.5


@pytest.mark.skipif(not os.environ.get("KITTI_DEVKIT"), reason="set KITTI_DEVKIT to a built evaluate_object binary")
@pytest.mark.parametrize("case", sorted(CASES))
def test_official_mode_equals_devkit_binary(tmp_path: Path, case: str) -> None:
    live = run_devkit(Path(os.environ["KITTI_DEVKIT"]), case, tmp_path)
    result = evaluate_kitti(tmp_path / "label_2", tmp_path / "results" / "data", mode="official",
                            metrics=("bbox", "bev", "3d"))  # fmt: skip
    assert _compare(result, live["results"], live["not_evaluated"]) == []
