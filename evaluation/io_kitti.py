"""KITTI label directories as :class:`GroundTruth` / :class:`Detections`, for the table and error metrics.

Reading itself is ``evaluation.kitti.read_label_dir`` (strict, errors name file, line and field). The
conversion:

- frames (file stems) sorted become images with ids 1..F and the attribute ``frame``;
- categories are the object types found in ground truth and detections (``DontCare`` excluded), ids
  1..K in sorted name order;
- bbox ``x1, y1, x2, y2`` becomes ``x1, y1, x2 - x1, y2 - y1``; ``area = w * h``;
- a ``DontCare`` region becomes a crowd region of *every* class (a detection inside it, by intersection
  over the detection's area — the devkit's DontCare criterion — is neither TP nor FP);
- ``distance_m`` is the norm of the 3D location (bottom centre, camera frame) where the object has a
  3D box; ``occlusion`` is the KITTI level 0-3;
- detection files for frames without ground truth are an error; frames without a detection file have
  no detections (counted in ``ignored``).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from evaluation.attributes import KITTI_OCCLUSION_LABELS
from evaluation.inputs import Detections, GroundTruth
from evaluation.validate import InputError

log = logging.getLogger(__name__)
DONT_CARE = "DontCare"


def _kitti():
    try:
        import evaluation.kitti as kitti
    except ImportError as exc:  # the KITTI package is built separately; say so instead of a bare ImportError
        raise InputError(f"KITTI input needs evaluation.kitti, which failed to import: {exc}") from exc
    return kitti


def _check_boxes(frames: dict, path: Path) -> None:
    for stem, frame in frames.items():
        w = frame.bbox[:, 2] - frame.bbox[:, 0]
        h = frame.bbox[:, 3] - frame.bbox[:, 1]
        bad = np.nonzero((w < 0) | (h < 0))[0]
        if len(bad):
            raise InputError(f"{path / (stem + '.txt')}: object {int(bad[0]) + 1}: field 'bbox': x2 < x1 or "
                             f"y2 < y1 ({frame.bbox[bad[0]].tolist()})")


def read_kitti(gt_dir: str | Path, det_dir: str | Path) -> tuple[GroundTruth, Detections, dict[str, int]]:
    """Read a KITTI label_2 ground-truth directory and a scored detection directory.

    Returns ``(ground_truth, detections, ignored_counts)``.
    """
    kitti = _kitti()
    gt_dir, det_dir = Path(gt_dir), Path(det_dir)
    gt_frames = kitti.read_label_dir(gt_dir, with_score=False)
    if not det_dir.is_dir():
        raise InputError(f"{det_dir}: the ground truth is a KITTI label directory, so the detections must be "
                         "one too (one <frame>.txt per frame with a 16th column, score)")
    det_frames = kitti.read_label_dir(det_dir, with_score=True)
    unknown = sorted(set(det_frames) - set(gt_frames))
    if unknown:
        raise InputError(f"{det_dir / (unknown[0] + '.txt')}: frame '{unknown[0]}' has no ground truth in "
                         f"{gt_dir} ({len(unknown)} such files)")
    _check_boxes(gt_frames, gt_dir)
    _check_boxes(det_frames, det_dir)
    stems = sorted(gt_frames)
    names = sorted({str(t) for f in (*gt_frames.values(), *det_frames.values()) for t in f.type} - {DONT_CARE})
    cat_of = {name: i for i, name in enumerate(names)}
    gt = _ground_truth(gt_frames, stems, names, cat_of, str(gt_dir))
    dt, n_dontcare_dets = _detections(det_frames, stems, cat_of, str(det_dir))
    ignored = {"kitti_frames_without_detection_file": len(set(stems) - set(det_frames)),
               "kitti_dontcare_detections": n_dontcare_dets}
    return gt, dt, ignored


def _ground_truth(frames: dict, stems: list[str], names: list[str], cat_of: dict[str, int], source: str) -> GroundTruth:
    img, cat, box, crowd, dist, dvalid, occ, ovalid = [], [], [], [], [], [], [], []
    n_cat = len(names)
    for i, stem in enumerate(stems):
        f = frames[stem]
        types = f.type.astype(str)
        care = types != DONT_CARE
        xywh = np.column_stack([f.bbox[:, :2], f.bbox[:, 2:] - f.bbox[:, :2]])
        n = int(care.sum())
        img.append(np.full(n, i))
        cat.append(np.array([cat_of[t] for t in types[care]], dtype=np.int64))
        box.append(xywh[care])
        crowd.append(np.zeros(n, bool))
        dist.append(np.linalg.norm(f.location[care], axis=1))
        dvalid.append(f.has_box3d[care])
        levels = f.occluded[care]
        occ.append(np.array([KITTI_OCCLUSION_LABELS.get(int(v), "") for v in levels], dtype=object))
        ovalid.append(np.isin(levels, list(KITTI_OCCLUSION_LABELS)))
        n_dc = int((~care).sum())  # DontCare: one crowd region per class
        img.append(np.full(n_dc * n_cat, i))
        cat.append(np.tile(np.arange(n_cat), n_dc))
        box.append(np.repeat(xywh[~care], n_cat, axis=0))
        crowd.append(np.ones(n_dc * n_cat, bool))
        dist.append(np.zeros(n_dc * n_cat))
        dvalid.append(np.zeros(n_dc * n_cat, bool))
        occ.append(np.full(n_dc * n_cat, "", dtype=object))
        ovalid.append(np.zeros(n_dc * n_cat, bool))
    bbox = np.concatenate(box) if box else np.zeros((0, 4))
    n = len(bbox)
    return GroundTruth(
        source=source, image_ids=np.arange(1, len(stems) + 1, dtype=np.int64),
        image_attrs=[{"frame": s} for s in stems], category_ids=np.arange(1, n_cat + 1, dtype=np.int64),
        category_names=names, ann_ids=np.arange(1, n + 1, dtype=np.int64),
        image_index=np.concatenate(img).astype(np.int64) if img else np.zeros(0, np.int64),
        category_index=np.concatenate(cat).astype(np.int64) if cat else np.zeros(0, np.int64),
        bbox=bbox, area=bbox[:, 2] * bbox[:, 3], iscrowd=np.concatenate(crowd) if crowd else np.zeros(0, bool),
        distance_m=np.concatenate(dist) if dist else np.zeros(0),
        distance_valid=np.concatenate(dvalid) if dvalid else np.zeros(0, bool),
        occlusion=np.concatenate(occ) if occ else np.zeros(0, object),
        occlusion_valid=np.concatenate(ovalid) if ovalid else np.zeros(0, bool),
        track_id=np.zeros(n, np.int64), track_valid=np.zeros(n, bool),  # label_2 has no track ids
    )


def _detections(frames: dict, stems: list[str], cat_of: dict[str, int], source: str) -> tuple[Detections, int]:
    index = {s: i for i, s in enumerate(stems)}
    img, cat, box, score = [], [], [], []
    n_dontcare = 0
    for stem in sorted(frames):
        f = frames[stem]
        types = f.type.astype(str)
        care = types != DONT_CARE
        n_dontcare += int((~care).sum())
        img.append(np.full(int(care.sum()), index[stem]))
        cat.append(np.array([cat_of[t] for t in types[care]], dtype=np.int64))
        box.append(np.column_stack([f.bbox[care, :2], f.bbox[care, 2:] - f.bbox[care, :2]]))
        score.append(f.score[care])
    if not img:
        return Detections(source, np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 4)), np.zeros(0)), 0
    return Detections(source=source, image_index=np.concatenate(img).astype(np.int64),
                      category_index=np.concatenate(cat).astype(np.int64), bbox=np.concatenate(box),
                      score=np.concatenate(score).astype(np.float64)), n_dontcare
