"""Process plumbing of the stages: the glibc allocator thresholds, a frozen heap, worker processes (their start
method, their initializer, running shards over them) and per-process caches that forked workers inherit.

Allocator (:func:`keep_freed_memory`, the one helper that sets it). glibc's malloc serves blocks above its mmap
threshold (128 kB at start, adapting up to 32 MB) with fresh ``mmap`` calls and returns freed heap tops above its
trim threshold to the system, so a process that keeps allocating and freeing large buffers keeps unmapping memory
and faulting it in again, page by page. Raising both thresholds keeps freed memory mapped for reuse; peak memory
stays the same, only memory already used once stays mapped. Two callers, each with the thresholds measured for
it (docs/performance.md):

- ``roadsynth export`` (the log exports handle a few MB per frame: PNG bytes, packed sweeps, MB-sized chunks and
  their compressed copies): :data:`EXPORT_THRESHOLDS`, blocks below 64 MB from the heap, 256 MB of freed heap
  kept;
- ``roadsynth render`` (a frame's image-sized temporaries), in its main process and in every worker:
  :data:`RENDER_THRESHOLDS`, blocks below 32 MB (glibc's largest) from the heap, 1 GB of freed heap kept.

It changes the whole process, for as long as it runs (both commands are processes that end with their stage);
library users may call it in their own processes. Other C libraries (musl, macOS) are left as they are.

Worker processes (:func:`pool_context`, :func:`run_in_pool`, :func:`die_with_parent`): a pool of ``workers - 1``
processes plus the calling process, each holding one shard at a time; on a failure or Ctrl-C the workers are
killed and the shards done so far are kept (the stage's resume finds them).
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import contextlib
import ctypes
import ctypes.util
import gc
import importlib
import logging
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Hashable, Iterator, Sequence
from contextlib import AbstractContextManager
from typing import Any

log = logging.getLogger(__name__)

EXPORT_THRESHOLDS = (64 << 20, 256 << 20)  # (mmap, trim) threshold, bytes: the log exports
RENDER_THRESHOLDS = (32 << 20, 1 << 30)  # (mmap, trim) threshold, bytes: the render and its workers
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def keep_freed_memory(thresholds: tuple[int, int] = EXPORT_THRESHOLDS) -> bool:
    """Set glibc's mmap and trim thresholds (bytes; module docstring) for this process; True when set."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        get_version = libc.gnu_get_libc_version  # glibc only
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    get_version.restype = ctypes.c_char_p
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    mmap_threshold, trim_threshold = thresholds
    done = mallopt(_M_MMAP_THRESHOLD, mmap_threshold) == 1 and mallopt(_M_TRIM_THRESHOLD, trim_threshold) == 1
    log.debug("glibc %s: mmap threshold %d, trim threshold %d: %s", get_version().decode(), mmap_threshold,
              trim_threshold, "set" if done else "refused")
    return done


@contextlib.contextmanager
def frozen_heap() -> Iterator[None]:
    """Keep the objects alive when the block starts out of the cyclic garbage collector's reach while it runs.

    They are mostly the imported modules' objects, and each full collection visited all of them, in the main
    process and during the static world build that the render's workers wait for (docs/performance.md). Frozen
    (gc.freeze), they are skipped, and workers forked from this process keep sharing their pages (a collection
    writes to every object it visits). Thawed (gc.unfreeze) at the end.
    """
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def die_with_parent() -> None:
    """Initializer of a stage's worker processes: leave Ctrl-C and SIGTERM to the main process (which stops the
    pool and reports; a worker sent SIGTERM itself just ends), and die when the worker's parent dies, even by
    ``kill -9``, instead of waiting forever for work that will not come. On Linux the kernel kills it
    (PR_SET_PDEATHSIG; with a forkserver the parent is the server, which exits with the main process); elsewhere a
    thread watches the parent's pid."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the CLI's handler, which a forked worker inherits
    parent = os.getppid()
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0:
            if os.getppid() != parent:  # the parent died before the request
                os._exit(1)
            return
        log.debug("prctl(PR_SET_PDEATHSIG) failed (errno %d); watching the parent instead", ctypes.get_errno())
    threading.Thread(target=_exit_when_orphaned, args=(parent,), name="parent-watch", daemon=True).start()


def _exit_when_orphaned(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(1)


def pool_context(preload: Sequence[str], *, fork_safe: bool) -> multiprocessing.context.BaseContext:
    """The process pool's start method, for workers that need the modules ``preload`` imported.

    Importing them costs a worker seconds of CPU (open3d, pandas, pyarrow, the pipeline). Plain fork gives it this
    process's for nothing, but some libraries' threads do not survive a fork of a process that has started them
    (Embree's worker threads, once a scene was cast): ``fork_safe`` says whether this process is still free of
    them. So on Linux, while it is, workers fork from this process (``preload`` imported here first, once for
    this process's own shards and every child). Otherwise they fork from a server process that imports
    ``preload`` once and does no other work (forkserver; started here, so that its imports run while this
    process goes on), or, where the platform has neither, spawn.
    """
    methods = multiprocessing.get_all_start_methods()
    if sys.platform.startswith("linux") and "fork" in methods and fork_safe:
        for module in preload:
            importlib.import_module(module)
        return multiprocessing.get_context("fork")
    if "forkserver" not in methods:
        return multiprocessing.get_context("spawn")
    from multiprocessing import forkserver

    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(preload))
    forkserver.ensure_running()
    return context


def run_in_pool(jobs: Sequence[Any], work: Callable[[Any], int], workers: int,
                context: multiprocessing.context.BaseContext | None,
                progress: Callable[[], AbstractContextManager[Any]]) -> None:
    """Run ``work(job)`` for every job, with a progress bar from ``progress`` (advanced by what ``work`` returns):
    here, when ``context`` is None, or with ``context`` in a pool of ``workers - 1`` processes plus this process,
    which has everything imported and so works while the pool starts up (in a thread; the main thread only hands
    out jobs). Each worker holds one job at a time, so all finish within about one job of each other.

    The pool gets its first jobs before this process starts any thread (the progress bar's monitor, its own
    work): a fork context forks every child at the first submit, and a fork must not copy a process mid-work in
    another thread.
    """
    if context is None:
        with progress() as bar:
            for job in jobs:
                bar.update(work(job))
        return
    queue = collections.deque(jobs)
    children = min(workers, len(jobs)) - 1
    with _stopped_on_failure(cf.ProcessPoolExecutor(children, mp_context=context,
                                                    initializer=die_with_parent)) as pool:
        busy: dict[cf.Future, cf.Executor] = {pool.submit(work, queue.popleft()): pool for _ in range(children)}
        with progress() as bar, _stopped_on_failure(cf.ThreadPoolExecutor(1)) as here:
            idle: list[cf.Executor] = [here]
            while queue or busy:
                while queue and idle:
                    executor = idle.pop()
                    busy[executor.submit(work, queue.popleft())] = executor
                done, _ = cf.wait(busy, return_when=cf.FIRST_COMPLETED)
                for future in done:
                    idle.append(busy.pop(future))
                    bar.update(future.result())


@contextlib.contextmanager
def _stopped_on_failure(executor: cf.Executor) -> Iterator[cf.Executor]:
    """``executor`` for the block; shut down at its end, and when the block fails (an error, Ctrl-C) without
    starting its queued jobs: a pool's workers are killed at once (a job of theirs is lost, the rest of the
    work is kept), this process's own job in progress is waited for (a thread cannot be stopped), so that
    nothing writes into the stage's work folder once the stage has returned and released its lock."""
    try:
        yield executor
    except BaseException:
        processes = getattr(executor, "_processes", None) or {}  # ProcessPoolExecutor's workers, by pid
        for process in list(processes.values()):
            process.kill()
        executor.shutdown(wait=True, cancel_futures=True)
        raise
    executor.shutdown(wait=True)


class ProcessCache:
    """One value per process, for the latest key: built on first use, dropped and built again when the key
    changes (a process serves one stage run at a time). Workers forked from this process inherit it, so what the
    main process built before the fork costs them nothing; :meth:`lent` puts in a value built elsewhere."""

    def __init__(self) -> None:
        self._key: Hashable | None = None
        self._value: Any = None

    def get(self, key: Hashable, build: Callable[[], Any]) -> Any:
        """The value for ``key``: the cached one, or ``build()`` (replacing any other key's)."""
        if self._key != key or self._value is None:
            self.clear()
            self._value = build()
            self._key = key
        return self._value

    def peek(self, key: Hashable) -> Any:
        """The cached value for ``key``, or None."""
        return self._value if self._key == key else None

    @contextlib.contextmanager
    def lent(self, key: Hashable, value: Any) -> Iterator[None]:
        """Within the block, ``value`` (when not None) is the value for ``key``; forgotten at the end, so that it
        is never mistaken for another run's."""
        if value is not None:
            self.clear()
            self._key, self._value = key, value
        try:
            yield
        finally:
            if value is not None and self._key == key:
                self.clear()

    def clear(self) -> None:
        self._key, self._value = None, None

    def __len__(self) -> int:
        return int(self._key is not None)
