"""Benchmark: the cost of Parquet page checksums (a CRC-32 per data page, written by pipeline.core.tables and checked
when read) on the render stage's LiDAR sweeps (:func:`write_sweep`) and on the record's label table
(:func:`write_parquet`).

Renders --frames frames of the highway at noon (or reads the record --record DIR), then writes every sweep and the
label table --repeat times on one thread with and without checksums, reads them back with and without
verification, and prints ms and kB per sweep (per table for labels).

    python bench/bench_parquet_checksum.py [--frames 10] [--record DIR] [--repeat 5]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
from bench_records import rendered_record

from pipeline.core import tables
from pipeline.core.record_writers.lidar import SWEEP_SCHEMA

_WRITE_TABLE = pq.write_table


def _write_table_without_checksum(*args, **kwargs) -> None:
    _WRITE_TABLE(*args, **{**kwargs, "write_page_checksum": False})


def _timed(fn: Callable[[], object], repeat: int) -> float:
    """Best of ``repeat`` passes, in ms (the least disturbed by the other processes on the machine)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best * 1e3


def _measure(name: str, batch: list[pa.Table], write: Callable[[pa.Table, Path], None], out: Path,
             repeat: int) -> list[tuple[str, bool, float, float, float]]:
    rows = []
    paths = [out / f"{name}-{i}.parquet" for i in range(len(batch))]
    for crc in (False, True):
        pq.write_table = _WRITE_TABLE if crc else _write_table_without_checksum  # the project's writer, CRC off
        try:
            write_ms = _timed(lambda: [write(t, p) for t, p in zip(batch, paths, strict=True)], repeat)
        finally:
            pq.write_table = _WRITE_TABLE
        read_ms = _timed(lambda crc=crc: [pq.ParquetFile(p, page_checksum_verification=crc).read() for p in paths],
                         repeat)
        kb = sum(p.stat().st_size for p in paths) / 1e3
        for p, t in zip(paths, batch, strict=True):
            assert pq.ParquetFile(p, page_checksum_verification=True).read().equals(t)
        n = len(batch)
        rows.append((name, crc, write_ms / n, read_ms / n, kb / n))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--record", type=Path, help="a rendered record (default: render --frames highway frames)")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        record = args.record or rendered_record(tmp, args.frames)
        sweeps = [pq.read_table(p).cast(SWEEP_SCHEMA) for p in sorted(record.glob("lidars/*/*.parquet"))]
        labels = [pq.read_table(record / "labels.parquet")]
        (tmp / "out").mkdir()
        rows = _measure("sweep", sweeps, tables.write_sweep, tmp / "out", args.repeat)
        rows += _measure("labels", labels, tables.write_arrow, tmp / "out", args.repeat)
    points = sum(len(s) for s in sweeps) / len(sweeps)
    print(f"Parquet page checksums: {len(sweeps)} sweeps of {points:,.0f} points and one label table of "
          f"{len(labels[0]):,} rows, one thread, best of {args.repeat} passes")
    print("table  | checksum | write ms | read ms |     kB")
    print("-------|----------|----------|---------|-------")
    for name, crc, write_ms, read_ms, kb in rows:
        print(f"{name:6s} | {'yes' if crc else 'no':>8s} | {write_ms:8.2f} | {read_ms:7.2f} | {kb:6.1f}")
    for name in ("sweep", "labels"):
        (_, _, w0, r0, k0), (_, _, w1, r1, k1) = [r for r in rows if r[0] == name]
        print(f"{name}: write ratio with / without {w1 / w0:.2f}, read ratio {r1 / r0:.2f}, size ratio {k1 / k0:.4f}")


if __name__ == "__main__":
    main()
