"""KITTI object detection evaluation: 2D, BEV and 3D AP and AOS, R40 and R11 (see README.md here).

Public API:
    read_label_dir(path, *, with_score) -> dict[str, KittiFrame]
    read_label_file(path, *, with_score) -> KittiFrame
    read_calib(path) -> KittiCalib
    evaluate_kitti(gt_dir, det_dir, *, calib_dir=None, mode="official", classes=..., min_overlap=None,
                   metrics=...) -> dict (JSON-serialisable)
    kitti_summary_markdown(result) -> str
"""

from evaluation.kitti.evaluate import evaluate_kitti
from evaluation.kitti.readers import (
    KittiCalib,
    KittiFormatError,
    KittiFrame,
    read_calib,
    read_label_dir,
    read_label_file,
)
from evaluation.kitti.summary import kitti_summary_markdown

__all__ = [
    "KittiCalib",
    "KittiFormatError",
    "KittiFrame",
    "evaluate_kitti",
    "kitti_summary_markdown",
    "read_calib",
    "read_label_dir",
    "read_label_file",
]
