"""pipeline.core.processes: keep_freed_memory keeps freed large blocks mapped (glibc), checked by resident memory
in fresh processes; ProcessCache builds once per key."""

from __future__ import annotations

import platform
import subprocess
import sys

import pytest

# Resident MB before, holding and after freeing a 48 MB block, the block touched so it is resident. With the
# default thresholds glibc maps a block of 48 MB (over its 32 MB ceiling) on its own and unmaps it on free.
PROBE = """
import sys
from pipeline.core.processes import keep_freed_memory
set_ = keep_freed_memory() if sys.argv[1] == "on" else None
def resident_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20
before = resident_mb()
block = bytearray(b"\\x01") * (48 << 20)
holding = resident_mb()
del block
print(set_, round(before), round(holding), round(resident_mb()))
"""

glibc = pytest.mark.skipif(sys.platform != "linux" or platform.libc_ver()[0] != "glibc", reason="glibc only")


def _probe(mode: str) -> tuple[str, int, int, int]:
    out = subprocess.run([sys.executable, "-c", PROBE, mode], check=True, capture_output=True, text=True).stdout
    flag, *mb = out.split()
    return flag, *map(int, mb)


@glibc
def test_freed_blocks_stay_mapped_only_when_set():
    flag, before, holding, after = _probe("on")
    assert flag == "True"
    assert holding - before >= 45 and after - before >= 45  # freed, yet kept for the next allocation
    flag, before, holding, after = _probe("off")
    assert flag == "None"
    assert holding - before >= 45 and after - before <= 5  # returned to the system at once: the default


def test_process_cache_builds_once_per_key_and_forgets_what_it_lent():
    from pipeline.core.processes import ProcessCache

    cache, built = ProcessCache(), []

    def build(value):
        built.append(value)
        return value

    assert cache.get("a", lambda: build(1)) == 1 and cache.get("a", lambda: build(2)) == 1
    assert cache.get("b", lambda: build(3)) == 3 and built == [1, 3] and cache.peek("a") is None
    with cache.lent("c", 4):
        assert cache.peek("c") == 4 and cache.get("c", lambda: build(5)) == 4
    assert not cache and cache.peek("c") is None and built == [1, 3]
    with cache.lent("d", None):  # nothing lent: nothing kept, nothing dropped
        assert not cache

