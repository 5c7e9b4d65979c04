"""Benchmark: export a 100-frame record to every format; MB/s and files/s per format.

The input is the exporters' hand-built record (tests/exporters/synthetic_record.py: one 800x600
camera with RGB/instance/semantic/depth PNGs, one LiDAR of ~2,500 points, 5 objects per frame), built
once and not timed. Each format is exported ``--repeats`` times into a fresh folder; the best time
counts. ``cpu s`` is the least process CPU time of the repeats (all threads): on a shared machine it
varies less than the wall time, and ``cpu s`` / ``s`` shows how much of the work overlaps. ``MB out``
is the apparent size of the output (hard-linked images included, though linking writes no image
bytes); ``MB/s`` = MB out / seconds; ``files/s`` = output files / seconds. Target: MCAP with zstd
>= 150 MB/s.

    python bench/bench_export.py [--frames 100] [--repeats 3]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from exporters.base import Compression, ExportOptions, get_exporter
from tests.exporters.synthetic_record import build_record

CASES = [("coco", Compression.ZSTD), ("kitti", Compression.ZSTD), ("yolo", Compression.ZSTD),
         ("mcap", Compression.ZSTD), ("mcap", Compression.LZ4), ("mcap", Compression.NONE),
         ("rosbag2", Compression.ZSTD), ("rosbag2", Compression.NONE)]


def _size_and_files(path: Path) -> tuple[int, int]:
    if path.is_file():
        return path.stat().st_size, 1
    files = [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files), len(files)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--ground-points", type=int, default=100_000, help="LiDAR points per sweep (64 ch: ~100k)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        record = build_record(tmp / "record", frames=args.frames, ground_points=args.ground_points)
        in_mb = sum(p.stat().st_size for p in record.rglob("*") if p.is_file()) / 1e6
        print(f"input: {args.frames} frames, {in_mb:.1f} MB record")
        print(f"{'format':<10} {'compr.':<6} {'s':>7} {'cpu s':>7} {'MB out':>8} {'MB/s':>8} {'files':>6} "
              f"{'files/s':>9} {'frames/s':>9}")
        for fmt, compression in CASES:
            best, cpu, size, files = float("inf"), float("inf"), 0, 0
            for i in range(args.repeats):
                out = tmp / f"{fmt}-{compression.value}-{i}" / ("out.mcap" if fmt == "mcap" else "out")
                start, start_cpu = time.perf_counter(), time.process_time()
                get_exporter(fmt).export([record], out, ExportOptions(compression=compression))
                best = min(best, time.perf_counter() - start)
                cpu = min(cpu, time.process_time() - start_cpu)
                size, files = _size_and_files(out)
                shutil.rmtree(out.parent)
            print(f"{fmt:<10} {compression.value:<6} {best:7.3f} {cpu:7.3f} {size / 1e6:8.1f} {size / 1e6 / best:8.1f} "
                  f"{files:6d} {files / best:9.0f} {args.frames / best:9.1f}")


if __name__ == "__main__":
    main()
