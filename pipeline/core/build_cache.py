"""A disk cache for what processes build again and again from the same inputs: the procedural actor meshes at
import, and the static world of a simulation.

Importing :mod:`pipeline.world.actors` builds every body family in every pose, their hulls and smooth normals (310
models, ~3.3 s of CPU), once per process: each render worker that starts fresh, each closed-loop episode on Ray, each
CLI command that renders, each test process. What it builds depends on nothing but the code, so, like numba's and
Python's own caches, it is kept on disk beside the code (``pipeline/__pycache__/``, or ``$ROADSYNTH_CACHE_DIR``) under
a key that changes with any byte of the package's Python sources, the Python and numpy versions and the machine's
architecture (numpy's floating-point paths), and loaded from there (~50 ms). The static world of a simulation
(:func:`pipeline.world.static.load_static_world`: ~3 s of CPU for the urban network) is kept the same way, its key
the sources' and its road tables' bytes and seed: each condition rendered from one simulation, and each closed-loop
episode on one network, builds it once. A stale or damaged file is never read: another key is another file, and a
file that does not load is rebuilt. Where the folder cannot be written the value is built as before. Of each name,
the files of the ``keep`` most recently used keys stay (one for the meshes: older keys' files are removed when a new
one is written).
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import pickle
import platform
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numpy as np

log = logging.getLogger(__name__)

T = TypeVar("T")
PACKAGE = Path(__file__).resolve().parents[1]  # pipeline/


def cache_dir() -> Path:
    """``$ROADSYNTH_CACHE_DIR`` if set, else ``pipeline/__pycache__``."""
    override = os.environ.get("ROADSYNTH_CACHE_DIR")
    return Path(override) if override else PACKAGE / "__pycache__"


def source_key(root: Path = PACKAGE) -> str:
    """A hex digest of every ``*.py`` file under ``root`` (relative paths and bytes, in sorted order), the Python
    and numpy versions and the machine's architecture."""
    digest = hashlib.sha256(f"{sys.version}|{np.__version__}|{platform.machine()}".encode())
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_path(name: str, key: str, folder: Path | None = None) -> Path:
    """Where :func:`cached` keeps NAME's value of ``key`` (in ``folder``, default :func:`cache_dir`)."""
    return (cache_dir() if folder is None else Path(folder)) / f"{name}-{key[:24]}.pickle"


def cached(name: str, build: Callable[[], T], *, folder: Path | None = None, key: str | None = None,
           keep: int = 1) -> T:
    """``build()``'s value, from ``folder/NAME-KEY.pickle`` when an earlier process with the same sources wrote it;
    otherwise built and written there (atomically) for the next one. ``key`` defaults to :func:`source_key`.
    ``keep``: how many of NAME's files stay, the most recently used (a load counts as a use)."""
    if keep < 1:
        raise ValueError(f"keep must be at least 1, got {keep}")
    path = cache_path(name, source_key() if key is None else key, folder)
    folder = path.parent
    try:
        with path.open("rb") as handle:
            value = pickle.load(handle)
        if keep > 1:
            with contextlib.suppress(OSError):
                os.utime(path)  # used now: the last to go
        return value
    except FileNotFoundError:
        pass
    except Exception as exc:  # a damaged or foreign file: build again (and replace it)
        log.debug("%s: not loaded (%s); building it again", path, exc)
    value = build()
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tmp.open("wb") as handle:
            pickle.dump(value, handle, protocol=5)
        os.replace(tmp, path)
        _forget_all_but(folder, name, path, keep)
    except OSError as exc:
        log.debug("%s: not written (%s)", path, exc)
    finally:
        with contextlib.suppress(OSError):  # nothing half-written is left behind
            tmp.unlink(missing_ok=True)
    return value


def _forget_all_but(folder: Path, name: str, newest: Path, keep: int) -> None:
    """Remove NAME's files in ``folder`` but ``newest`` and the ``keep`` - 1 most recently used others."""
    others = []
    for old in folder.glob(f"{name}-*.pickle"):
        if old != newest:
            with contextlib.suppress(OSError):  # another process may have removed it meanwhile
                others.append((old.stat().st_mtime_ns, old.name, old))
    for _, _, old in sorted(others, reverse=True)[keep - 1:]:
        old.unlink(missing_ok=True)
