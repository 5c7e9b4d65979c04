"""Benchmark: export a 100-frame record to every format; MB/s and files/s per format.

The input, made once and not timed, is by default a rendered record: the highway simulated here (seed 1)
and ``--frames`` frames of the default rig rendered under morning, as the pipeline makes them (about a
minute on 2 cores). ``--dataset DIR`` exports a record of your own instead; ``--synthetic`` the exporters'
hand-built record (tests/exporters/synthetic_record.py: one 800x600 camera with RGB/instance/semantic/depth
PNGs, one LiDAR of ``--ground-points`` points, 5 objects per frame), quicker to make. Its points are
uniform random floats in no order, harder for zstd than a real sweep (ordered by ring and azimuth): the
rendered record is the realistic case, the synthetic one the worst.

Each format is exported ``--repeats`` times into a fresh folder; the best time counts. ``cpu s`` is the
least process CPU time of the repeats (all threads): on a shared machine it varies less than the wall
time, and ``cpu s`` / ``s`` shows how much of the work overlaps. ``MB out`` is the apparent size of the
output (hard-linked images included, though linking writes no image bytes); ``MB/s`` = MB out / seconds.
For compressed logs, ``raw MB/s`` counts the bytes before compression instead (the size of the same
export uncompressed / seconds), the usual measure of a compressor's speed. ``files/s`` = output files /
seconds. Targets: MCAP with zstd >= 150 MB/s; every format > 100 frames/s (issue 43: the last line names the
slowest). The allocator is set as ``roadsynth export`` sets it
(:func:`pipeline.core.processes.keep_freed_memory`; ``--default-malloc`` leaves it as it is).

    python bench/bench_export.py [--dataset DIR | --synthetic] [--frames 100] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench_records import rendered_record

from exporters.base import Compression, ExportOptions, get_exporter
from pipeline.core.processes import keep_freed_memory
from pipeline.core.record import DatasetRecord
from tests.exporters.synthetic_record import build_record

# The uncompressed log of each format comes before its compressed ones (their raw MB/s needs its size).
CASES = [("coco", Compression.ZSTD), ("kitti", Compression.ZSTD), ("yolo", Compression.ZSTD),
         ("mot", Compression.ZSTD), ("kitti-tracking", Compression.ZSTD), ("kitti-depth", Compression.ZSTD),
         ("mcap", Compression.NONE), ("mcap", Compression.ZSTD), ("mcap", Compression.LZ4),
         ("rosbag2", Compression.NONE), ("rosbag2", Compression.ZSTD), ("nuscenes", Compression.NONE),
         ("cityscapes", Compression.NONE)]
LOGS = {"mcap", "rosbag2"}


def _size_and_files(path: Path) -> tuple[int, int]:
    if path.is_file():
        return path.stat().st_size, 1
    files = [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files), len(files)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--dataset", type=Path, help="a rendered record to export (default: render one here)")
    source.add_argument("--synthetic", action="store_true", help="export the hand-built record (random points)")
    parser.add_argument("--frames", type=int, default=100, help="frames of the record rendered or built here")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--ground-points", type=int, default=100_000,
                        help="LiDAR points per sweep of the synthetic record (64 ch: ~100k)")
    parser.add_argument("--default-malloc", action="store_true", help="leave the allocator as it is (no mallopt)")
    parser.add_argument("--formats", help="comma-separated formats to export (default: all of them)")
    args = parser.parse_args()
    if not args.default_malloc:
        print(f"allocator thresholds raised as by roadsynth export: {keep_freed_memory()}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.dataset is not None:
            record, kind = args.dataset, f"rendered record {args.dataset}"
        elif args.synthetic:
            record = build_record(tmp / "record", frames=args.frames, ground_points=args.ground_points)
            kind = f"synthetic record, {args.ground_points} random ground points per sweep"
        else:
            record = rendered_record(tmp, args.frames, "morning", os.cpu_count() or 1, progress=True)
            kind = "record rendered here (highway seed 1, morning, default rig)"
        frames = len(DatasetRecord(record).frames)
        in_mb = sum(p.stat().st_size for p in record.rglob("*") if p.is_file()) / 1e6
        print(f"input: {kind}; {frames} frames, {in_mb:.1f} MB")
        print(f"{'format':<14} {'compr.':<6} {'s':>7} {'cpu s':>7} {'MB out':>8} {'MB/s':>8} {'raw MB/s':>9} "
              f"{'files':>6} {'files/s':>9} {'frames/s':>9}")
        raw_mb: dict[str, float] = {}
        rates: dict[str, float] = {}
        chosen = set(args.formats.split(",")) if args.formats else {fmt for fmt, _ in CASES}
        for fmt, compression in [case for case in CASES if case[0] in chosen]:
            best, cpu, size, files = float("inf"), float("inf"), 0, 0
            for i in range(args.repeats):
                out = tmp / f"{fmt}-{compression.value}-{i}" / ("out.mcap" if fmt == "mcap" else "out")
                start, start_cpu = time.perf_counter(), time.process_time()
                get_exporter(fmt).export([record], out, ExportOptions(compression=compression))
                best = min(best, time.perf_counter() - start)
                cpu = min(cpu, time.process_time() - start_cpu)
                size, files = _size_and_files(out)
                shutil.rmtree(out.parent)
            mb = size / 1e6
            if fmt in LOGS and compression is Compression.NONE:
                raw_mb[fmt] = mb
            raw = f"{raw_mb[fmt] / best:9.1f}" if fmt in LOGS and compression is not Compression.NONE else f"{'':9}"
            print(f"{fmt:<14} {compression.value:<6} {best:7.3f} {cpu:7.3f} {mb:8.1f} {mb / best:8.1f} {raw} "
                  f"{files:6d} {files / best:9.0f} {frames / best:9.1f}")
            rates[f"{fmt} {compression.value}" if fmt in LOGS else fmt] = frames / best
        if rates:
            slowest = min(rates, key=rates.get)
            print(f"slowest: {slowest}, {rates[slowest]:.1f} frames/s (target > 100)")


if __name__ == "__main__":
    main()
