"""An MCAP writer that compresses chunks on worker threads while the next chunk fills.

mcap's own ``Writer`` compresses a full chunk on the thread that adds the messages, so compression, most
of an MCAP export's work, waits for message building and message building waits for compression; and a
chunk's bytes are copied four times between the message and the file. :class:`PipelinedWriter` writes the
same records in the same order, serialised by mcap's record classes, but hands each full chunk to a pool
(join, CRC and compression together, one copy) and writes the compressed chunks in order as they finish:
byte for byte what ``mcap.writer.Writer`` writes with its default options when its chunks are compressed
the same way (tests/exporters/test_mcap_writer.py). Each chunk is compressed by one thread, so the bytes
do not depend on the number of workers.

Used from one thread (the pool only compresses). Supported: what the exporter uses, with mcap's defaults
(all indexes, repeated schemas and channels, statistics, summary offsets, chunk and summary CRCs); no
attachments, no unchunked output.
"""

from __future__ import annotations

import struct
import threading
import zlib
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import BinaryIO

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.writer import MCAP0_MAGIC

from exporters.base import Compression
from exporters.writing import ZSTD_LEVEL

Payload = bytes | bytearray | memoryview
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time
_CHUNK_HEAD = struct.Struct("<BQQQQI")  # opcode, record length, start, end, uncompressed size, uncompressed CRC
_NAMES = {Compression.ZSTD: "zstd", Compression.LZ4: "lz4", Compression.NONE: ""}
_local = threading.local()


def payload_size(part: Payload) -> int:
    """Bytes in ``part`` (a memoryview's ``len`` counts items, not bytes)."""
    return part.nbytes if isinstance(part, memoryview) else len(part)


def chunk_compressor(compression: Compression) -> Callable[[bytes], bytes]:
    """The function that compresses one chunk: zstd at :data:`exporters.writing.ZSTD_LEVEL` on the calling thread
    (one compressor per thread), lz4 frames as mcap writes them, or none."""
    if compression is Compression.ZSTD:
        return _zstd
    if compression is Compression.LZ4:
        import lz4.frame

        return lz4.frame.compress
    return bytes


def _zstd(data: bytes) -> bytes:
    compressor = getattr(_local, "zstd", None)
    if compressor is None:
        import zstandard

        compressor = _local.zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
    return compressor.compress(data)


def _compress_chunk(parts: list[Payload], compress: Callable[[bytes], bytes]) -> tuple[bytes, int, int]:
    """(compressed chunk, its uncompressed size, CRC-32 of the uncompressed bytes); runs on a worker."""
    data = b"".join(parts)
    return compress(data), len(data), zlib.crc32(data)


@dataclass
class _Chunk:
    parts: list[Payload] = field(default_factory=list)
    size: int = 0
    start: int = 0
    end: int = 0
    messages: int = 0
    indexes: dict[int, list[tuple[int, int]]] = field(default_factory=dict)  # channel -> (log time, offset)


@dataclass
class _Sealed:
    chunk: _Chunk
    future: Future[tuple[bytes, int, int]]


class PipelinedWriter:
    """Writes an MCAP file to ``stream`` (positioned at its start) with chunks of about ``chunk_size`` bytes
    compressed by ``workers`` threads; at most ``workers + 1`` full chunks wait for compression or writing.

    The methods are mcap ``Writer``'s (``start``, ``register_schema``, ``register_channel``, ``add_message``,
    ``add_metadata``, ``finish``); ``close`` stops the workers and is safe to call after a failure. A
    worker's error is raised by the call that writes its chunk.
    """

    def __init__(self, stream: BinaryIO, *, chunk_size: int, compression: Compression, workers: int = 2) -> None:
        if workers < 1:
            raise ValueError(f"workers must be at least 1, got {workers}")
        self._stream = stream
        self._offset = 0
        self._chunk_size = chunk_size
        self._compression = _NAMES[compression]
        self._compress = chunk_compressor(compression)
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="mcap-compress")
        self._max_sealed = workers + 1
        self._sealed: deque[_Sealed] = deque()
        self._chunk = _Chunk()
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._stats = Statistics(attachment_count=0, channel_count=0, channel_message_counts={}, chunk_count=0,
                                 message_count=0, metadata_count=0, message_start_time=0, message_end_time=0,
                                 schema_count=0)

    def __enter__(self) -> PipelinedWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop the workers (chunks not yet compressed are dropped)."""
        self._pool.shutdown(wait=True, cancel_futures=True)

    def start(self, profile: str = "", library: str = "") -> None:
        self._write(MCAP0_MAGIC)
        self._write_record(Header(profile=profile, library=library))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._stats.schema_count += 1
        record = _serialised(schema)
        self._add_to_chunk([record], len(record))
        return schema.id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata=dict(metadata or {}))
        self._channels.append(channel)
        self._stats.channel_count += 1
        record = _serialised(channel)
        self._add_to_chunk([record], len(record))
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: Payload | Sequence[Payload], publish_time: int,
                    sequence: int = 0) -> None:
        """Add a message; ``data`` may be given as a sequence of parts that are joined only in the chunk. The
        parts are held, not copied, until their chunk is compressed: do not change them after the call."""
        parts = [data] if isinstance(data, bytes | bytearray | memoryview) else list(data)
        length = sum(map(payload_size, parts))
        stats = self._stats
        stats.message_start_time = log_time if stats.message_count == 0 else min(log_time, stats.message_start_time)
        stats.message_end_time = max(log_time, stats.message_end_time)
        stats.channel_message_counts[channel_id] = stats.channel_message_counts.get(channel_id, 0) + 1
        stats.message_count += 1
        chunk = self._chunk
        chunk.start = log_time if chunk.messages == 0 else min(chunk.start, log_time)
        chunk.end = max(chunk.end, log_time)
        chunk.indexes.setdefault(channel_id, []).append((log_time, chunk.size))
        chunk.messages += 1
        head = _MESSAGE_HEAD.pack(Opcode.MESSAGE, 22 + length, channel_id, sequence, log_time, publish_time)
        self._add_to_chunk([head, *parts], _MESSAGE_HEAD.size + length)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """Write a metadata record now (after the full chunks, before the chunk that is filling, as mcap does)."""
        self._write_sealed(0)
        offset = self._offset
        record = _serialised(Metadata(name=name, metadata=data))
        self._write(record)
        self._stats.metadata_count += 1
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=len(record), name=name))

    def finish(self) -> None:
        """Write the last chunk, the summary and the footer; stops the workers."""
        self._seal()
        self._write_sealed(0)
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._offset
        summary = RecordBuilder()
        offsets: list[SummaryOffset] = []
        groups = ((Opcode.SCHEMA, self._schemas), (Opcode.CHANNEL, self._channels),
                  (Opcode.STATISTICS, [self._stats]), (Opcode.CHUNK_INDEX, self._chunk_indexes),
                  (Opcode.ATTACHMENT_INDEX, []), (Opcode.METADATA_INDEX, self._metadata_indexes))
        for opcode, records in groups:
            group_start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + group_start,
                                         group_length=summary.count - group_start))
        offsets_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        footer_start = 0 if not data else summary_start
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, footer_start, offsets_start), zlib.crc32(data))
        self._write(data)
        self._write_record(Footer(summary_start=footer_start, summary_offset_start=offsets_start, summary_crc=crc))
        self._write(MCAP0_MAGIC)
        self.close()

    def _add_to_chunk(self, parts: list[Payload], size: int) -> None:
        chunk = self._chunk
        chunk.parts.extend(parts)
        chunk.size += size
        if chunk.size > self._chunk_size:
            self._seal()

    def _seal(self) -> None:
        """Hand the filling chunk to the pool (a chunk without messages is not written, as in mcap)."""
        chunk = self._chunk
        if chunk.messages == 0:
            return
        self._stats.chunk_count += 1
        self._sealed.append(_Sealed(chunk, self._pool.submit(_compress_chunk, chunk.parts, self._compress)))
        self._chunk = _Chunk()
        self._write_sealed(self._max_sealed)

    def _write_sealed(self, keep: int) -> None:
        """Write compressed chunks, oldest first, until at most ``keep`` wait."""
        while len(self._sealed) > keep:
            sealed = self._sealed.popleft()
            compressed, size, crc = sealed.future.result()
            chunk = sealed.chunk
            start = self._offset
            name = self._compression.encode()
            tail = struct.pack(f"<I{len(name)}sQ", len(name), name, len(compressed))
            length = _CHUNK_HEAD.size - 9 + len(tail) + len(compressed)
            self._write(_CHUNK_HEAD.pack(Opcode.CHUNK, length, chunk.start, chunk.end, size, crc) + tail)
            self._write(compressed)
            index_start = self._offset
            indexes = RecordBuilder()
            offsets = {}
            for channel_id, entries in chunk.indexes.items():
                offsets[channel_id] = index_start + indexes.count
                MessageIndex(channel_id=channel_id, records=entries).write(indexes)
            self._write(indexes.end())
            self._chunk_indexes.append(ChunkIndex(
                message_start_time=chunk.start, message_end_time=chunk.end, chunk_start_offset=start,
                chunk_length=index_start - start, message_index_offsets=offsets,
                message_index_length=self._offset - index_start, compression=self._compression,
                compressed_size=len(compressed), uncompressed_size=size))

    def _write_record(self, record: object) -> None:
        self._write(_serialised(record))

    def _write(self, data: Payload) -> None:
        self._stream.write(data)
        self._offset += len(data)


def _serialised(record: object) -> bytes:
    builder = RecordBuilder()
    record.write(builder)  # type: ignore[attr-defined]
    return builder.end()
