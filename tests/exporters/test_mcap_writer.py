"""exporters.mcap_writer.PipelinedWriter against mcap's own Writer (the reference) and mcap's reader."""

from __future__ import annotations

import io
import random
import threading
import types

import mcap.writer
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from exporters.base import Compression
from exporters.mcap_writer import PipelinedWriter, chunk_compressor

CHUNK = 64 << 10
_MCAP_COMPRESSION = {Compression.ZSTD: mcap.writer.CompressionType.ZSTD,
                     Compression.LZ4: mcap.writer.CompressionType.LZ4,
                     Compression.NONE: mcap.writer.CompressionType.NONE}


def _operations(seed: int = 0) -> list[tuple]:
    """A log that exercises what the writer must get right: schemas and channels registered between messages
    (they go into the chunk being filled), metadata between chunks, log times out of order within a chunk,
    empty, small and larger-than-a-chunk messages, compressible and incompressible data."""
    rng = random.Random(seed)
    noise = np.random.default_rng(seed).bytes(300_000)
    ops: list[tuple] = [("schema", "a.A", b"schema a"), ("channel", "/a", 1)]
    for i in range(240):
        if i == 60:
            ops += [("schema", "b.B", b"schema b" * 9), ("channel", "/b", 2), ("channel", "/b2", 2)]
        if i in (90, 91, 200):
            ops.append(("metadata", f"m{i}", {"key": "value" * i, "other": ""}))
        size = rng.choice([0, 7, 1000, 20_000, 90_000, 200_000])
        data = noise[:size] if rng.random() < 0.5 else bytes([i % 256]) * size
        ops.append(("message", 1 if i < 60 else rng.choice([1, 2, 3]), 10_000 + 50 * i - rng.randint(0, 400), data))
    ops.append(("metadata", "last", {"a": "b"}))
    return ops


def _write(writer, ops: list[tuple], *, parts: bool = False) -> None:
    writer.start(profile="test", library="roadsynth tests")
    sequence: dict[int, int] = {}
    for op in ops:
        if op[0] == "schema":
            writer.register_schema(name=op[1], encoding="protobuf", data=op[2])
        elif op[0] == "channel":
            writer.register_channel(op[1], "protobuf", op[2])
        elif op[0] == "metadata":
            writer.add_metadata(op[1], op[2])
        else:
            _, channel, time_ns, data = op
            if parts:  # the same bytes handed over in pieces, one a typed (non-byte) memoryview
                cut = len(data) // 8 * 4
                data = [data[:2], memoryview(np.frombuffer(data[2:2 + cut], dtype="<u4")), data[2 + cut:]]
            writer.add_message(channel, log_time=time_ns, data=data, publish_time=time_ns + 1,
                               sequence=sequence.setdefault(channel, 0))
            sequence[channel] += 1
    writer.finish()


def _reference(ops: list[tuple], compression: Compression, monkeypatch) -> bytes:
    """mcap's Writer with its defaults, compressing zstd chunks as ours does (level and threads)."""
    monkeypatch.setattr(mcap.writer, "zstandard", types.SimpleNamespace(compress=chunk_compressor(Compression.ZSTD)))
    out = io.BytesIO()
    _write(mcap.writer.Writer(out, chunk_size=CHUNK, compression=_MCAP_COMPRESSION[compression]), ops)
    return out.getvalue()


def _pipelined(ops: list[tuple], compression: Compression, workers: int = 2, parts: bool = False) -> bytes:
    out = io.BytesIO()
    _write(PipelinedWriter(out, chunk_size=CHUNK, compression=compression, workers=workers), ops, parts=parts)
    return out.getvalue()


@pytest.mark.parametrize("compression", list(Compression))
def test_bytes_equal_mcaps_own_writer(compression, monkeypatch):
    ops = _operations()
    expected = _reference(ops, compression, monkeypatch)
    assert _pipelined(ops, compression) == expected
    assert _pipelined(ops, compression, parts=True) == expected
    chunks = [r for r in StreamReader(io.BytesIO(expected), emit_chunks=True).records if isinstance(r, Chunk)]
    assert len(chunks) > 20  # the log spans many chunks, so the pipeline really ran
    assert {c.compression for c in chunks} == {{"none": ""}.get(compression.value, compression.value)}


def test_bytes_do_not_depend_on_the_worker_count():
    ops = _operations(1)
    one = _pipelined(ops, Compression.ZSTD, workers=1)
    assert _pipelined(ops, Compression.ZSTD, workers=2) == one
    assert _pipelined(ops, Compression.ZSTD, workers=5) == one


def test_mcaps_reader_returns_every_message_with_valid_crcs():
    ops = _operations(2)
    data = _pipelined(ops, Compression.ZSTD)
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    summary = reader.get_summary()
    messages = [op for op in ops if op[0] == "message"]
    assert summary.statistics.message_count == len(messages)
    assert [c.topic for c in summary.channels.values()] == ["/a", "/b", "/b2"]
    assert [(m.name, m.metadata) for m in reader.iter_metadata()] == [(op[1], op[2]) for op in ops
                                                                      if op[0] == "metadata"]
    read = [(channel.id, message.log_time, message.data)
            for _, channel, message in reader.iter_messages(log_time_order=False)]
    assert read == [(channel, time_ns, data) for _, channel, time_ns, data in messages]
    # Every chunk's CRC is checked when it is decompressed (validate_crcs), through the stream reader too.
    assert sum(1 for _ in StreamReader(io.BytesIO(data), validate_crcs=True).records) > len(messages)


def test_a_failed_compression_is_raised_and_the_workers_stop(monkeypatch):
    import exporters.mcap_writer as module

    calls = []
    original = module._compress_chunk

    def failing(parts, compress):
        calls.append(threading.current_thread().name)
        if len(calls) == 3:
            raise OSError("no space for the chunk")
        return original(parts, compress)

    monkeypatch.setattr(module, "_compress_chunk", failing)
    writer = PipelinedWriter(io.BytesIO(), chunk_size=CHUNK, compression=Compression.ZSTD)
    with pytest.raises(OSError, match="no space for the chunk"), writer:
        _write(writer, _operations(3))
    assert all(name.startswith("mcap-compress") for name in calls)
    assert not [t for t in threading.enumerate() if t.name.startswith("mcap-compress")]


def test_at_least_one_worker():
    with pytest.raises(ValueError, match="workers must be at least 1, got 0"):
        PipelinedWriter(io.BytesIO(), chunk_size=CHUNK, compression=Compression.NONE, workers=0)
