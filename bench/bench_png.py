"""Benchmark: the render stage's PNG writer (pipeline.core.png: fixed row filter + zlib deflate, level 1; ISA-L's
deflate until 2026-11-27, dropped for writing different bytes in different processes) against OpenCV's (zlib level
1, the same fixed filter, run-length strategy), on the four images of rendered camera frames.

Renders --frames frames of the highway at noon (or reads the record --record DIR), encodes each image kind with
each writer --repeat times on one thread, checks that OpenCV decodes both to the same samples, and prints ms per
frame and kB per frame by kind.

    python bench/bench_png.py [--frames 10] [--record DIR] [--repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from bench_records import rendered_record

from pipeline.core.png import encode_png
from pipeline.core.record_writers.camera import PNG_FILTER, PNG_STRATEGY

OPENCV_FILTER = {"none": cv2.IMWRITE_PNG_FILTER_NONE, "sub": cv2.IMWRITE_PNG_FILTER_SUB,
                 "up": cv2.IMWRITE_PNG_FILTER_UP}
OPENCV_STRATEGY = {"rgb": cv2.IMWRITE_PNG_STRATEGY_RLE, "instance": cv2.IMWRITE_PNG_STRATEGY_RLE,
                   "semantic": cv2.IMWRITE_PNG_STRATEGY_RLE, "depth": cv2.IMWRITE_PNG_STRATEGY_DEFAULT}


def opencv_png(image: np.ndarray, kind: str) -> bytes:
    bgr = image[..., ::-1] if image.ndim == 3 else image
    params = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_FILTER, OPENCV_FILTER[PNG_FILTER[kind]],
              cv2.IMWRITE_PNG_STRATEGY, OPENCV_STRATEGY[kind]]
    ok, data = cv2.imencode(".png", np.ascontiguousarray(bgr), params)
    if not ok:
        raise RuntimeError(f"OpenCV could not encode a {kind} image")
    return data.tobytes()


def read_images(record: Path) -> dict[str, list[np.ndarray]]:
    """The record's camera images by kind, as the stage hands them to the writer (RGB in RGB order)."""
    images: dict[str, list[np.ndarray]] = {kind: [] for kind in PNG_FILTER}
    for camera in sorted((record / "cameras").iterdir()):
        for kind in PNG_FILTER:
            for path in sorted((camera / kind).glob("*.png")):
                image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
                images[kind].append(np.ascontiguousarray(image[..., ::-1]) if image.ndim == 3 else image)
    if not images["rgb"]:
        raise SystemExit(f"{record}: no camera images under cameras/<name>/rgb/")
    return images


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--record", type=Path, help="a rendered record (default: render --frames highway frames)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        record = args.record or rendered_record(Path(tmp_name), args.frames)
        images = read_images(record)
    frames = len(images["rgb"])
    writers = {"OpenCV (zlib 1, RLE)": opencv_png,
               "pipeline.core.png (zlib 1)": lambda image, kind: encode_png(image, PNG_FILTER[kind]),
               "pipeline.core.png (zlib 1, the record's strategies)":
                   lambda image, kind: encode_png(image, PNG_FILTER[kind], strategy=PNG_STRATEGY[kind])}
    rows = []
    for name, write in writers.items():
        ms, kb = {}, {}
        for kind, batch in images.items():
            for image in batch:  # lossless, both
                back = cv2.imdecode(np.frombuffer(write(image, kind), np.uint8), cv2.IMREAD_UNCHANGED)
                assert np.array_equal(back[..., ::-1] if back.ndim == 3 else back, image), (name, kind)
            start = time.perf_counter()
            size = sum(len(write(image, kind)) for _ in range(args.repeat) for image in batch)
            ms[kind] = (time.perf_counter() - start) / args.repeat / frames * 1e3
            kb[kind] = size / args.repeat / frames / 1e3
        rows.append((name, ms, kb))
    kinds = list(PNG_FILTER)
    print(f"PNG writers, {frames} frames of {images['rgb'][0].shape[1]}x{images['rgb'][0].shape[0]}, one thread, "
          f"mean of {args.repeat} passes")
    width = max(len(name) for name, _, _ in rows)
    print(f"{'writer':{width}s} | " + " | ".join(f"{k:>16}" for k in kinds) + " |     total (ms, kB)")
    print("-" * width + "-|-" + "-|-".join("-" * 16 for _ in kinds) + "-|-------------------")
    for name, ms, kb in rows:
        cells = " | ".join(f"{ms[k]:6.1f} ms {kb[k]:5.0f} kB" for k in kinds)
        print(f"{name:{width}s} | {cells} | {sum(ms.values()):6.1f} ms {sum(kb.values()):5.0f} kB")
    (_, base_ms, base_kb), *_, (_, new_ms, new_kb) = rows
    print(f"time ratio the record's writer / OpenCV: {sum(new_ms.values()) / sum(base_ms.values()):.2f}; "
          f"size ratio: {sum(new_kb.values()) / sum(base_kb.values()):.2f}")


if __name__ == "__main__":
    main()
