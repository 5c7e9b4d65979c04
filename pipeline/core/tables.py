"""Deterministic Parquet I/O for the pipeline's tidy tables.

Fixed writer settings (zstd, no pandas index metadata, one row group per 1M rows) so that the same
table gives the same bytes on any machine with the same pyarrow version. LiDAR sweeps, written once per frame
and read by every exporter, use :func:`write_sweep` instead: LZ4 with the floats' bytes split into streams.

Every table is written with Parquet's own CRC-32 per data page and read with the CRCs checked
(:func:`read_parquet`, :func:`open_parquet`): a flipped byte inside a value would otherwise decode as a different
value (a vehicle that teleports, a changed label) and now fails naming the file. Files written without checksums
still read (there is nothing to check).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq


def write_parquet(frame: pd.DataFrame, path: Path) -> None:
    # nthreads=1: the conversion is per column and cheap; a thread pool per call costs more than it saves.
    table = pa.Table.from_pandas(frame, preserve_index=False, nthreads=1)
    # pandas metadata embeds library versions and index details; the schema itself is what readers need.
    write_arrow(table.replace_schema_metadata(None), path)


def write_arrow(table: pa.Table, path: Path) -> None:
    """Write an Arrow table with the fixed settings (a DataFrame of the same columns gives the same bytes)."""
    pq.write_table(table, path, compression="zstd", compression_level=3, row_group_size=1 << 20,
                   use_dictionary=False, write_statistics=True, version="2.6", write_page_checksum=True)


def write_sweep(table: pa.Table, path: Path) -> None:
    """Write a LiDAR sweep: the fixed settings, but LZ4 with byte-stream-split float columns: faster to write and
    read than zstd, and smaller. Columns declared not nullable are written without definition levels (faster; LZ4
    without the byte split is faster still but much larger). The page checksums cost a little of the write and the
    read (bench/bench_parquet_checksum.py; the figures are in docs/performance.md)."""
    floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
    pq.write_table(table, path, compression="lz4", row_group_size=1 << 20, use_dictionary=False,
                   write_statistics=True, version="2.6", use_byte_stream_split=floats or False,
                   write_page_checksum=True)


def read_parquet(path: Path, columns: list[str] | None = None) -> pd.DataFrame:
    """A Parquet table as a DataFrame, every page's checksum checked; a missing, damaged or corrupt file fails
    naming it (ValueError; FileNotFoundError when missing)."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: table not found")
    try:
        return pq.read_table(path, columns=columns, page_checksum_verification=True).to_pandas()
    except (pa.ArrowException, OSError) as exc:  # a damaged file: name it (pyarrow's message does not)
        raise ValueError(damage_message(path, exc)) from None


def open_parquet(path: Path) -> pq.ParquetFile:
    """A Parquet file opened with page checksum verification on, for readers that read it themselves (wrap their
    reads in ``except (pa.ArrowException, OSError)`` and report :func:`damage_message`)."""
    return pq.ParquetFile(path, page_checksum_verification=True)


def damage_message(path: Path, exc: BaseException, what: str = "Parquet table") -> str:
    """What to tell the user about a table pyarrow could not read: a page checksum mismatch means the bytes
    changed after the file was written (disk, copy, an edit), so the file must be made again."""
    if "checksum" in str(exc).lower():
        return (f"{path}: corrupt (page checksum mismatch: its bytes changed after it was written); re-create it "
                "with the stage that wrote it (`roadsynth simulate` for a simulation's tables, `roadsynth render` "
                "for a dataset record's)")
    return f"{path}: not a readable {what} ({exc})"


def require_finite(frame: pd.DataFrame, source: str, *, keys: tuple[str, ...] = ("frame", "track_id")) -> None:
    """Raise ValueError naming ``source``, the field and the first row (by its ``keys`` columns) when a float column
    of ``frame`` holds NaN or an infinity."""
    for column in frame.columns:
        values = frame[column].to_numpy()
        if values.dtype.kind != "f":
            continue
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.argmax(bad))
            where = ", ".join(f"{k} {frame[k].iloc[row]}" for k in keys if k in frame.columns) or f"row {row}"
            raise ValueError(f"{source}: field {column} is {values[row]} at {where} ({int(bad.sum())} row(s) "
                             "not finite)")


def write_ipc(table: pa.Table, path: Path) -> None:
    """Write an Arrow table as an uncompressed Arrow IPC file: for intermediate tables written and read once (a
    render's shards), where Parquet's encoding and compression cost more than the bytes they save."""
    with pa.OSFile(str(path), "wb") as sink, pa.ipc.new_file(sink, table.schema) as writer:
        writer.write_table(table)


def read_ipc(path: Path) -> pa.Table:
    """An Arrow IPC file (:func:`write_ipc`), checked whole; a missing or damaged file fails naming it."""
    if not Path(path).is_file():
        raise FileNotFoundError(f"{path}: table not found")
    try:
        with pa.OSFile(str(path)) as source:
            table = pa.ipc.open_file(source).read_all()
        table.validate(full=True)
    except (pa.ArrowInvalid, OSError) as exc:
        raise ValueError(f"{path}: not a readable Arrow IPC table ({exc})") from None
    return table


def read_ipc_files(paths: list[Path]) -> pd.DataFrame:
    """The rows of several Arrow IPC files of one schema (:func:`write_ipc`), in order, as one DataFrame."""
    return pa.concat_tables([read_ipc(path) for path in paths]).to_pandas()
