"""Background writing (:class:`exporters.writing.OrderedCalls`, MCAP chunk compression) and frame prefetching
(``frames_with_data``)."""

from __future__ import annotations

import pkgutil
import random
import threading
import time

import numpy as np
import pytest

from exporters.base import get_exporter
from exporters.log_common import POINT_FIELDS, POINT_STRIDE, frames_with_data, pack_points
from exporters.source import ExportSource
from exporters.writing import ordered_calls


def test_ordered_calls_run_in_order_one_at_a_time_on_the_worker():
    delays = [random.Random(0).uniform(0.0, 0.002) for _ in range(100)]
    done, running, most = [], [], [0]

    def call(i: int, delay: float) -> None:
        running.append(i)
        most[0] = max(most[0], len(running))
        time.sleep(delay)
        running.remove(i)
        done.append((i, threading.current_thread().name))

    with ordered_calls(4, "test-writer") as calls:
        for i, delay in enumerate(delays):
            calls.submit(1, call, i, delay)
    assert [i for i, _ in done] == list(range(100))
    assert most[0] == 1 and all(name.startswith("test-writer") for _, name in done)


def test_ordered_calls_block_beyond_the_pending_bytes():
    gate, finished = threading.Event(), []
    with ordered_calls(5, "test-writer") as calls:
        calls.submit(3, lambda: (gate.wait(), finished.append(0)))
        threading.Timer(0.05, gate.set).start()
        start = time.perf_counter()
        calls.submit(3, finished.append, 1)  # 6 bytes > 5: waits until the first call is done
        assert time.perf_counter() - start >= 0.04 and finished[:1] == [0]
    assert finished == [0, 1]


def test_held_calls_run_as_one_batch_in_order():
    """add() holds calls; flush, submit or leaving the block queues them as one worker task, in order."""
    done = []
    with ordered_calls(100, "test-writer") as calls:
        calls.add(1, done.append, "a")
        calls.add(1, done.append, "b")
        assert done == [] and not calls._pending  # held, not yet queued
        calls.flush()
        assert len(calls._pending) == 1  # one task for both
        calls.add(1, done.append, "c")
        calls.submit(1, done.append, "d")  # after the held call
        calls.add(1, done.append, "e")  # queued when the block ends
    assert done == ["a", "b", "c", "d", "e"]


def test_ordered_calls_raise_a_failed_call_later():
    def fail() -> None:
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"), ordered_calls(100, "test-writer") as calls:
        calls.submit(1, fail)
        calls.submit(1, time.sleep, 0.01)


def test_ordered_calls_drop_queued_calls_when_the_block_fails():
    gate, started = threading.Event(), []
    with pytest.raises(KeyError), ordered_calls(100, "test-writer") as calls:
        calls.submit(1, gate.wait)
        calls.submit(1, started.append, 1)
        threading.Timer(0.05, gate.set).start()
        raise KeyError("caller failed")
    assert started == []


def test_pack_points_follows_the_point_fields():
    """The packed sweep equals a structured array built from POINT_FIELDS (names, offsets, dtypes), padding zero,
    over each column's whole range."""
    rng = np.random.default_rng(7)
    n = 1000
    columns = {"x_m": rng.normal(0, 50, n).astype(np.float32), "y_m": rng.normal(0, 50, n).astype(np.float32),
               "z_m": rng.normal(0, 5, n).astype(np.float32), "intensity": rng.random(n, dtype=np.float32),
               "ring": rng.integers(0, 2**16, n).astype(np.uint16),
               "semantic": rng.integers(0, 256, n).astype(np.uint8),
               "instance_id": rng.integers(-2**31, 2**31, n).astype(np.int32)}
    columns["x_m"][:3] = [np.nan, np.inf, -0.0]
    record_name = {"x": "x_m", "y": "y_m", "z": "z_m", "intensity": "intensity", "ring": "ring", "class": "semantic",
                   "instance": "instance_id"}
    dtype = np.dtype({"names": [f[0] for f in POINT_FIELDS], "formats": [f[2] for f in POINT_FIELDS],
                      "offsets": [f[1] for f in POINT_FIELDS], "itemsize": POINT_STRIDE})
    expected = np.zeros(n, dtype=dtype)
    for name, _, _ in POINT_FIELDS:
        expected[name] = columns[record_name[name]]
    packed = pack_points(columns)
    assert len(packed) == n * POINT_STRIDE
    assert bytes(packed) == expected.tobytes()
    assert bytes(pack_points({k: v[:0] for k, v in columns.items()})) == b""


def test_frames_with_data_keeps_export_order(morning, night):
    source = ExportSource([night, morning])
    loaded = list(frames_with_data(source, ahead=1))
    assert [(i.source.stem, i.frame) for i, _ in loaded] == [(i.source.stem, i.frame) for i in source.frames()]
    for item, data in loaded:
        assert data.images["front"] == item.source.record.image_path("front", "rgb", item.frame).read_bytes()
        assert data.points["top"] == pack_points(item.source.record.points("top", item.frame))


@pytest.mark.parametrize(("fmt", "target", "thread"),
                         [("mcap", "exporters.mcap_writer:_compress_chunk", "mcap-compress"),
                          ("rosbag2", "rosbags.rosbag2:Writer.write", "rosbag2-writer")])
def test_background_error_fails_the_export_atomically(tmp_path, morning, monkeypatch, fmt, target, thread):
    """An error on a background thread (MCAP: compressing a chunk; rosbag2: the writer's thread) fails the
    export and leaves nothing behind."""
    original, threads = pkgutil.resolve_name(target), []
    fail_at = 1 if fmt == "mcap" else 5  # the two-frame record fills one MCAP chunk

    def failing(*args, **kwargs):
        threads.append(threading.current_thread().name)
        if len(threads) == fail_at:
            raise OSError("disk full")
        return original(*args, **kwargs)

    monkeypatch.setattr(target.replace(":", "."), failing)
    with pytest.raises(OSError, match="disk full"):
        get_exporter(fmt).export([morning], tmp_path / "out")
    assert list(tmp_path.iterdir()) == []  # nor the MCAP's layout beside it
    assert threads and all(name.startswith(thread) for name in threads)


def test_zstd_chunks_do_not_depend_on_the_worker_count(monkeypatch):
    """Log chunks are compressed by ZSTD_THREADS zstd workers: the bytes are the same with 1, 2 or 4 workers (so
    the same on any machine), one zstd frame that decompresses to the chunk."""
    import zstandard

    from exporters import writing as io

    rng = np.random.default_rng(3)
    points = np.repeat(rng.normal(0, 30, (1 << 18, 1)).astype(np.float32), 3, axis=1)  # compressible, ~3 MB
    chunk = rng.bytes(1 << 20) + points.tobytes()
    outputs = []
    for workers in (1, 2, 4):
        monkeypatch.setattr(io, "ZSTD_THREADS", workers)
        outputs.append(io.zstd_compressor().compress(chunk))
    assert outputs[0] == outputs[1] == outputs[2]
    assert len(outputs[0]) < 0.8 * len(chunk)
    assert zstandard.ZstdDecompressor().decompress(outputs[0]) == chunk
    assert zstandard.get_frame_parameters(outputs[0]).content_size == len(chunk)
