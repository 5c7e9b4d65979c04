"""Control: how often a detector finds real photographed people, by their height in an 800x600 frame.

The realism report scores our people by box height (30-60 px, >= 60 px). What a detector reaches on *real* people of
those heights says how far such a figure can go at all. This takes photos of yours (none ships with the project;
any street photo with whole people in it), finds each photo's people with the detector itself at full size (class
person, score >= --label-score), and for each height H of --heights: crops each person with its surroundings (the box
grown by 1.5 of its width and 0.6 of its height on each side, clipped to the photo), shrinks the crop by area
averaging so that the person stands H px tall, pastes it at 12 places of an 800x600 frame (--background, e.g. one of
our rendered frames; grey 114 without), in four passes shifted by a few pixels (the detector's grids see the person at
several phases), and runs the detector on every frame as `roadsynth detect --onnx` does (its options: family,
letterbox, class map). A person is found when a person detection at --score or more overlaps its box at IoU >= 0.5,
greedily by score, one detection per person, as COCO matches.

Prints, per height, the people placed, found and the recall. It is a control, not a bench of our code: the crops are
sharp-edged patches on another background, and a photo's few people are one sample of poses, clothes and light.

    .venv/bin/python bench/bench_people_scale.py --onnx MODEL.onnx --photo STREET.jpg [--photo ...]
        [--background FRAME.png] [--heights 30 36 42 48 54 60 72 90]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.detect.onnx import OnnxDetector

PERSON = 1  # COCO category id
FRAME_W, FRAME_H = 800, 600
GROW_W, GROW_H = 1.5, 0.6  # the crop's surroundings, in the person's width and height, each side
PLACES = [(10 + c * 195, 10 + r * 195) for r in range(3) for c in range(4)]  # top-left corners of the pastes
PASSES = 4  # each shifted by (3, 2) px from the last


def read_rgb(path: Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB of an image file; a clear error for one that cannot be read."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise SystemExit(f"{path}: not an image OpenCV can read")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def people(detector: OnnxDetector, rgb: np.ndarray, score: float) -> np.ndarray:
    """(N, 4) float64 x1 y1 x2 y2 of the person detections at ``score`` or more."""
    d = detector.predict([rgb])[0]
    keep = (d.category_ids == PERSON) & (d.scores >= score)
    return np.asarray(d.boxes[keep], np.float64).reshape(-1, 4)


def iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(A, B) IoU of x1 y1 x2 y2 boxes."""
    lo = np.maximum(a[:, None, :2], b[None, :, :2])
    hi = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.prod(np.clip(hi - lo, 0, None), axis=2)
    area = lambda x: np.prod(x[:, 2:] - x[:, :2], axis=1)  # noqa: E731
    return inter / (area(a)[:, None] + area(b)[None, :] - inter)


def found(truth: np.ndarray, boxes: np.ndarray, scores: np.ndarray) -> int:
    """How many ``truth`` boxes a detection matches at IoU >= 0.5, detections taken by descending score, each
    matching the unmatched truth box it overlaps most (COCO's greedy matching)."""
    if not len(truth) or not len(boxes):
        return 0
    overlap = iou(boxes[np.argsort(-scores, kind="stable")], truth)
    taken = np.zeros(len(truth), bool)
    for row in overlap:
        row = np.where(taken, -1.0, row)
        k = int(np.argmax(row))
        if row[k] >= 0.5:
            taken[k] = True
    return int(taken.sum())


def crop(rgb: np.ndarray, box: np.ndarray, height_px: int) -> tuple[np.ndarray, np.ndarray]:
    """The person ``box`` with its surroundings, shrunk so that it stands ``height_px`` tall, and the box in the
    crop's pixels."""
    x1, y1, x2, y2 = box
    w, h = x2 - x1, y2 - y1
    cx1, cy1 = int(max(x1 - GROW_W * w, 0)), int(max(y1 - GROW_H * h, 0))
    cx2, cy2 = int(min(x2 + GROW_W * w, rgb.shape[1])), int(min(y2 + GROW_H * h, rgb.shape[0]))
    s = height_px / h
    size = (max(1, round((cx2 - cx1) * s)), max(1, round((cy2 - cy1) * s)))
    small = cv2.resize(rgb[cy1:cy2, cx1:cx2], size, interpolation=cv2.INTER_AREA)
    return small, np.array([(x1 - cx1) * s, (y1 - cy1) * s, (x2 - cx1) * s, (y2 - cy1) * s])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--onnx", type=Path, required=True, help="the detector (any `detect --onnx` runs)")
    ap.add_argument("--photo", type=Path, action="append", required=True, help="a photo with whole people; repeat")
    ap.add_argument("--background", type=Path, help="the frame the crops are pasted on (resized to 800x600)")
    ap.add_argument("--heights", type=int, nargs="+", default=[30, 36, 42, 48, 54, 60, 72, 90])
    ap.add_argument("--score", type=float, default=0.3, help="the detector's threshold for a find")
    ap.add_argument("--label-score", type=float, default=0.5, help="the threshold for a person at full size")
    args = ap.parse_args()
    detector = OnnxDetector(args.onnx)
    back = (np.full((FRAME_H, FRAME_W, 3), 114, np.uint8) if args.background is None else
            cv2.resize(read_rgb(args.background), (FRAME_W, FRAME_H), interpolation=cv2.INTER_AREA))
    photos = []
    for path in args.photo:
        rgb = read_rgb(path)
        boxes = people(detector, rgb, args.label_score)
        print(f"{path}: {len(boxes)} people at score >= {args.label_score}, "
              f"{', '.join(str(round(b[3] - b[1])) for b in boxes)} px tall")
        photos.append((rgb, boxes))
    print("\n| person height, px | placed | found | recall |\n|---|---|---|---|")
    for height in args.heights:
        placed = hits = 0
        for rgb, boxes in photos:
            for box in boxes:
                small, inside = crop(rgb, box, height)
                ch, cw = small.shape[:2]
                for k in range(PASSES):
                    frame, truth = back.copy(), []
                    for x, y in PLACES:
                        x, y = x + 3 * k, y + 2 * k
                        if x + cw <= FRAME_W and y + ch <= FRAME_H:
                            frame[y:y + ch, x:x + cw] = small
                            truth.append(inside + [x, y, x, y])
                    d = detector.predict([frame])[0]
                    mine = (d.category_ids == PERSON) & (d.scores >= args.score)
                    placed += len(truth)
                    hits += found(np.array(truth).reshape(-1, 4), np.asarray(d.boxes[mine], np.float64),
                                  np.asarray(d.scores[mine]))
        print(f"| {height} | {placed} | {hits} | {hits / placed:.2f} |" if placed else f"| {height} | 0 | 0 | - |")


if __name__ == "__main__":
    main()
