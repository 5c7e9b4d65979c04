"""Atomic output writing, image placement and background writing shared by the exporters.

An export is written into a temporary sibling of its destination (``.<name>.tmp-<pid>``) and renamed
into place only when complete, so a failure leaves the destination as it was and nothing half-written.
Images are hard-linked from the record when the file system allows it (same device, links permitted),
copied otherwise; either way the bytes are the record's. The rosbag2 export hands its writer's calls to
:class:`OrderedCalls`, which runs them on one worker thread in order, so output bytes never depend on
timing (MCAP has its own pipeline: :mod:`exporters.mcap_writer`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from pipeline.core.files import atomic_dir, atomic_file, atomic_named_dir

log = logging.getLogger(__name__)
# zstd level of MCAP and rosbag2 chunks (both libraries hard-code 3): level 1 takes much less CPU time
# for a file of nearly the same size (bench/bench_export.py; docs/performance.md).
ZSTD_LEVEL = 1
# zstd workers per rosbag2 chunk. Compressing chunks on the writer thread is that export's longest path, so
# zstd splits each chunk into 2 MB jobs compressed at once (same CPU time, less wall time when a core is free:
# docs/performance.md). MCAP compresses whole chunks on a pool instead (one thread each).
# The output does not depend on the number of workers once there is one, but differs from single-threaded
# output, so the count is fixed rather than taken from the machine: the same bytes everywhere.
ZSTD_THREADS = 2
__all__ = ["ZSTD_LEVEL", "ZSTD_THREADS", "OrderedCalls", "atomic_dir", "atomic_file", "atomic_named_dir", "dumps_json",
           "link_or_copy", "ordered_calls", "write_json", "zstd_compressor"]


def zstd_compressor() -> Any:
    """The zstd compressor of log chunks: :data:`ZSTD_LEVEL`, :data:`ZSTD_THREADS` workers."""
    import zstandard

    return zstandard.ZstdCompressor(level=ZSTD_LEVEL, threads=ZSTD_THREADS)


def link_or_copy(src: Path, dst: Path, *, link: bool = True) -> bool:
    """Hard-link ``src`` to ``dst`` (parent folders created); copy when linking fails or ``link`` is False.

    Returns True when linked.
    """
    dst.parent.mkdir(parents=True, exist_ok=True)
    if link:
        try:
            os.link(src, dst)
            return True
        except OSError:
            pass
    shutil.copyfile(src, dst)
    return False


def dumps_json(data: Any, *, indent: int | None = 2) -> str:
    """Deterministic JSON: sorted keys, ASCII, fixed separators, trailing newline."""
    separators = (",", ": ") if indent is not None else (",", ":")
    return json.dumps(data, sort_keys=True, indent=indent, separators=separators, ensure_ascii=True,
                      allow_nan=False) + "\n"


def write_json(path: Path, data: Any, *, indent: int | None = 2) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dumps_json(data, indent=indent))


class OrderedCalls:
    """Runs calls one at a time, in the order submitted, on one worker thread.

    For log writers whose calls mostly compress and write chunks (zstd, lz4, CRCs and file writes release
    the GIL): that work then overlaps the caller's building of the next messages. Since the calls keep
    their order and never run concurrently, the output is the same bytes as calling directly. At most
    ``max_pending_bytes`` of submitted payload waits at a time; :meth:`submit` blocks beyond that. A
    call's error is raised by a later :meth:`submit` or :meth:`drain`.

    Small calls can be batched: :meth:`add` holds a call until :meth:`flush` (or the next :meth:`submit` or
    :meth:`drain`) hands all held calls to the worker as one, which then takes the interpreter lock once per
    batch (e.g. a frame's messages) rather than once per call. Order is kept either way.
    """

    def __init__(self, pool: ThreadPoolExecutor, max_pending_bytes: int) -> None:
        self._pool = pool
        self._max_pending_bytes = max_pending_bytes
        self._pending: deque[tuple[Future, int]] = deque()
        self._pending_bytes = 0
        self._held: list[tuple[Callable[..., Any], tuple, dict]] = []
        self._held_bytes = 0

    def submit(self, size_bytes: int, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        """Queue ``fn(*args, **kwargs)``, whose payload is ``size_bytes`` long (after any held calls)."""
        self.flush()
        self._queue(size_bytes, fn, *args, **kwargs)

    def add(self, size_bytes: int, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        """Hold ``fn(*args, **kwargs)`` for the next batch (see the class)."""
        self._held.append((fn, args, kwargs))
        self._held_bytes += size_bytes

    def flush(self) -> None:
        """Queue the held calls as one."""
        if self._held:
            held, size = self._held, self._held_bytes
            self._held, self._held_bytes = [], 0
            self._queue(size, _call_all, held)

    def drain(self) -> None:
        """Queue the held calls, then wait for every queued call; afterwards the caller may use the writer
        directly."""
        self.flush()
        while self._pending:
            self._wait_oldest()

    def _queue(self, size_bytes: int, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> None:
        self._pending.append((self._pool.submit(fn, *args, **kwargs), size_bytes))
        self._pending_bytes += size_bytes
        while self._pending_bytes > self._max_pending_bytes:
            self._wait_oldest()

    def _wait_oldest(self) -> None:
        future, size = self._pending.popleft()
        self._pending_bytes -= size
        future.result()


def _call_all(calls: list[tuple[Callable[..., Any], tuple, dict]]) -> None:
    for fn, args, kwargs in calls:
        fn(*args, **kwargs)


@contextlib.contextmanager
def ordered_calls(max_pending_bytes: int, name: str) -> Iterator[OrderedCalls]:
    """An :class:`OrderedCalls` on a thread named ``name``; leaving the block waits for the queued calls.
    When the block or a call fails, the calls not yet started are dropped."""
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix=name) as pool:
        calls = OrderedCalls(pool, max_pending_bytes)
        try:
            yield calls
            calls.drain()
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
