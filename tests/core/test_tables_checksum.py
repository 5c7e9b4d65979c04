"""Parquet page checksums (issue 24): a byte flipped inside a value fails naming the file, where without the
checksum the same flip reads silently as another value (the control that shows the test can fail)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.core import tables
from pipeline.core.record import DatasetRecord, RecordError, lidar_path
from pipeline.core.tables import read_parquet, write_parquet, write_sweep
from tests.exporters.synthetic_record import build_record

CORRUPT = r"corrupt \(page checksum mismatch"


def _trajectories(n: int = 400) -> pd.DataFrame:
    rng = np.random.default_rng(0)  # random doubles: no compressor shortens them, each byte is a value's byte
    return pd.DataFrame({"frame": np.repeat(np.arange(n // 4), 4), "track_id": np.tile(np.arange(4), n // 4),
                         "x_m": rng.uniform(-500, 500, n), "y_m": rng.uniform(-500, 500, n)})


def _without_checksums(monkeypatch) -> None:
    """The project's writers as they are, but with pyarrow told to write no page checksum."""
    write_table = pq.write_table
    monkeypatch.setattr(pq, "write_table", lambda *a, **k: write_table(*a, **{**k, "write_page_checksum": False}))


def _chunk_end(path: Path, column: str) -> int:
    """The offset just past the (single) data page of ``column``: its last bytes are the values' last bytes."""
    group = pq.ParquetFile(path).metadata.row_group(0)
    chunk = next(group.column(i) for i in range(group.num_columns) if group.column(i).path_in_schema == column)
    start = chunk.dictionary_page_offset if chunk.has_dictionary_page else chunk.data_page_offset
    return start + chunk.total_compressed_size


def _flip(path: Path, offset: int) -> None:
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x10
    path.write_bytes(bytes(data))


def _silent_flip(path: Path, column: str, read) -> int:
    """A byte (counted back from the end of ``column``'s page) whose flip ``read`` accepts, changing values."""
    original, end = path.read_bytes(), _chunk_end(path, column)
    before = read(path)[column].to_numpy()
    for back in range(1, 64):
        _flip(path, end - back)
        try:
            after = read(path)[column].to_numpy()
        except ValueError:
            continue
        finally:
            path.write_bytes(original)
        if not np.array_equal(after, before):
            return back
    raise AssertionError(f"no silent flip found in {column}")


def test_a_flipped_value_byte_in_a_table_fails_naming_the_file(tmp_path, monkeypatch):
    checked, control = tmp_path / "trajectories.parquet", tmp_path / "control" / "trajectories.parquet"
    control.parent.mkdir()
    write_parquet(_trajectories(), checked)
    with monkeypatch.context() as patched:
        _without_checksums(patched)
        write_parquet(_trajectories(), control)
    back = _silent_flip(control, "x_m", read_parquet)  # without the checksum a flip reads as another position
    _flip(control, _chunk_end(control, "x_m") - back)
    assert not np.array_equal(read_parquet(control)["x_m"], _trajectories()["x_m"])

    _flip(checked, _chunk_end(checked, "x_m") - back)  # the same value byte: the pages differ only by their CRC
    with pytest.raises(ValueError, match=CORRUPT) as err:
        read_parquet(checked)
    assert str(err.value).startswith(f"{checked}: ") and "roadsynth simulate" in str(err.value)


def test_a_flipped_value_byte_in_a_lidar_sweep_fails_naming_the_file(tmp_path, monkeypatch):
    roots = {}
    for name, crc in (("checked", True), ("control", False)):
        root = build_record(tmp_path / name, frames=1, ground_points=500)
        path = lidar_path(root, "top", _first_frame(root))
        with monkeypatch.context() as patched:
            if not crc:
                _without_checksums(patched)
            write_sweep(pa.Table.from_pandas(pd.read_parquet(path), preserve_index=False), path)  # the sweep writer
        roots[name] = (root, path)
    root, path = roots["control"]
    frame = _first_frame(root)
    read = lambda p: pd.DataFrame(DatasetRecord(root).point_columns("top", frame))  # noqa: E731
    back = _silent_flip(path, "x_m", read)
    _flip(path, _chunk_end(path, "x_m") - back)
    read(path)  # reads: the points moved silently

    root, path = roots["checked"]
    _flip(path, _chunk_end(path, "x_m") - back)
    with pytest.raises(RecordError, match=CORRUPT) as err:
        DatasetRecord(root).point_columns("top", frame)
    assert str(err.value).startswith(f"{path}: ") and "LiDAR top" in str(err.value)


def _first_frame(root: Path) -> int:
    return int(DatasetRecord(root).frames["frame"].iloc[0])


def test_checksummed_files_stay_deterministic_and_old_files_still_read(tmp_path, monkeypatch):
    write_parquet(_trajectories(), tmp_path / "a.parquet")
    write_parquet(_trajectories(), tmp_path / "b.parquet")
    assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes()
    with monkeypatch.context() as patched:
        _without_checksums(patched)
        write_parquet(_trajectories(), tmp_path / "old.parquet")  # written before checksums: nothing to check
    assert (tmp_path / "old.parquet").stat().st_size < (tmp_path / "a.parquet").stat().st_size
    pd.testing.assert_frame_equal(read_parquet(tmp_path / "old.parquet"), _trajectories())


def test_a_damaged_file_that_is_not_a_checksum_mismatch_keeps_its_own_message(tmp_path):
    path = tmp_path / "t.parquet"
    path.write_bytes(b"PAR1 not a table")
    with pytest.raises(ValueError, match="not a readable Parquet table") as err:
        read_parquet(path)
    assert "checksum" not in str(err.value) and tables.damage_message(path, OSError("x")).startswith(f"{path}: ")
