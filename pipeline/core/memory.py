"""Process-wide allocator setting for stages that stream large buffers (the log exports).

A log export handles a few MB per frame (PNG bytes, packed sweeps, MB-sized chunks and their compressed copies)
and frees them again. glibc's malloc serves blocks above its mmap threshold (128 kB at start, adapting up to
32 MB) with fresh ``mmap`` calls and returns freed heap tops above its trim threshold to the system, so such
a process keeps unmapping memory and faulting it in again, page by page. :func:`keep_freed_memory` raises
both thresholds, so blocks below 64 MB come from the heap and up to 256 MB of freed heap stays mapped for
reuse. It makes the rosbag2 export of the benchmark record measurably faster; MCAP gained as much until its
writer came to copy each chunk once (:mod:`exporters.mcap_writer`), and now differs by no more than the noise
(docs/performance.md).

It changes the whole process, for as long as it runs: the ``roadsynth export`` command calls it (a process
that ends with its export); library users may call it in their own processes. The render stage gains
nothing from it (measured), so it is not set there. Other C libraries (musl, macOS) are left as they are.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import sys

log = logging.getLogger(__name__)

MMAP_THRESHOLD_BYTES = 64 << 20
TRIM_THRESHOLD_BYTES = 256 << 20
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds (module docstring) for this process; True when set."""
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
    done = (mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
            and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1)
    log.debug("glibc %s: mmap threshold %d, trim threshold %d: %s", get_version().decode(), MMAP_THRESHOLD_BYTES,
              TRIM_THRESHOLD_BYTES, "set" if done else "refused")
    return done
