"""Benchmark ``detect --onnx`` throughput against a plain onnxruntime loop, same images, one run.

The plain loop is what a script does by hand (the model README's recipe): default session options,
then per image read, letterbox, run, decode and class-wise NMS (OpenCV's), one after the other. Ours is
:class:`pipeline.detect.onnx.OnnxDetector` under :func:`pipeline.detect.infer.detect_coco` (threads
for every allowed core, the next batch's images read while the model runs, batches where the model
has a dynamic batch axis), including the conversion to COCO results. The images of the COCO export
are cycled ``--passes`` times; after one untimed warm-up image each side is timed ``--repeat`` times,
alternating, and the best is kept. Prints images/s of each and the ratio, the process CPU seconds
(all threads; steadier than wall time on a shared machine) and the detections each found.

    .venv/bin/python bench/bench_onnx_detect.py --onnx MODEL.onnx --coco DIR [--passes 8] [--repeat 5]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import time
from pathlib import Path

import cv2
import numpy as np


def plain_loop(model: Path, paths: list[Path], conf: float) -> int:
    """The hand-written loop (YOLOX raw head); returns the number of detections."""
    import onnxruntime as ort

    from pipeline.detect.heads import anchor_grid

    sess = ort.InferenceSession(str(model), providers=["CPUExecutionProvider"])
    size = sess.get_inputs()[0].shape[2]
    grid, stride = anchor_grid(size, size)
    found = 0
    for path in paths:
        img = cv2.imread(str(path))
        h, w = img.shape[:2]
        r = min(size / h, size / w)
        pad = np.full((size, size, 3), 114, np.uint8)
        pad[: int(h * r), : int(w * r)] = cv2.resize(img, (int(w * r), int(h * r)), interpolation=cv2.INTER_LINEAR)
        out = sess.run(None, {sess.get_inputs()[0].name: pad.transpose(2, 0, 1)[None].astype(np.float32)})[0][0]
        xy, wh = (out[:, :2] + grid) * stride, np.exp(out[:, 2:4]) * stride
        scores = out[:, 4:5] * out[:, 5:]
        cls = scores.argmax(1)
        sc = scores[np.arange(len(cls)), cls]
        k = sc >= conf
        if k.any():
            boxes = np.concatenate([xy[k] - wh[k] / 2, wh[k]], 1) / r
            found += len(cv2.dnn.NMSBoxesBatched(boxes.tolist(), sc[k].tolist(), cls[k].tolist(), conf, 0.65))
    return found


def ours(model: Path, data, conf: float) -> int:
    from pipeline.detect.infer import detect_coco
    from pipeline.detect.onnx import OnnxDetector

    detector = OnnxDetector(model, score_threshold=conf, max_detections=10**6)
    return len(detect_coco(detector.predict, data, batch_size=detector.batch, progress=False))


def main() -> None:
    from pipeline.core.config.detector import DETECTOR_CLASSES
    from pipeline.detect.data import annotation_file, load_coco

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--onnx", type=Path, required=True, help="a YOLOX raw-head model (e.g. yolox_nano.onnx)")
    parser.add_argument("--coco", type=Path, required=True)
    parser.add_argument("--split")
    parser.add_argument("--passes", type=int, default=8, help="cycle the images this many times")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--conf", type=float, default=0.05)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    data = load_coco(annotation_file(args.coco, args.split), DETECTOR_CLASSES)
    data = dataclasses.replace(data, images=data.images * args.passes)
    paths = [im.path for im in data.images]
    plain_loop(args.onnx, paths[:1], args.conf)  # warm-up: page cache, onnxruntime's first-run costs
    best = {"plain onnxruntime loop": float("inf"), "roadsynth detect --onnx": float("inf")}
    cpu = dict.fromkeys(best, float("inf"))
    counts = {}
    for _ in range(args.repeat):
        for name, run in (("plain onnxruntime loop", lambda: plain_loop(args.onnx, paths, args.conf)),
                          ("roadsynth detect --onnx", lambda: ours(args.onnx, data, args.conf))):
            t0, c0 = time.perf_counter(), time.process_time()
            counts[name] = run()
            best[name] = min(best[name], time.perf_counter() - t0)
            cpu[name] = min(cpu[name], time.process_time() - c0)
    print(f"{len(paths)} images ({len(paths) // args.passes} distinct x {args.passes}), model {args.onnx.name}")
    print(f"{'':<26}{'seconds':>9}{'images/s':>10}{'vs plain':>10}{'CPU s':>8}{'detections':>12}")
    base = best["plain onnxruntime loop"]
    for name, seconds in best.items():
        print(f"{name:<26}{seconds:>9.2f}{len(paths) / seconds:>10.1f}{base / seconds:>9.2f}x{cpu[name]:>8.2f}"
              f"{counts[name]:>12}")


if __name__ == "__main__":
    main()
