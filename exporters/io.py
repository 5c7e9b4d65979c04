"""Atomic output writing and image placement shared by the exporters.

An export is written into a temporary sibling of its destination (``.<name>.tmp-<pid>``) and renamed
into place only when complete, so a failure leaves the destination as it was and nothing half-written.
Images are hard-linked from the record when the file system allows it (same device, links permitted),
copied otherwise; either way the bytes are the record's.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)


def _tmp_sibling(path: Path, tag: str) -> Path:
    return path.with_name(f".{path.name}.{tag}-{os.getpid()}")


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        path.unlink()


@contextlib.contextmanager
def atomic_dir(out: Path) -> Iterator[Path]:
    """Yield an empty temporary sibling folder of ``out``; replace ``out`` by it when the block succeeds."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_sibling(out, "tmp")
    _remove(tmp)
    tmp.mkdir()
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _replace(tmp, out)


@contextlib.contextmanager
def atomic_file(out: Path) -> Iterator[Path]:
    """Yield a temporary sibling path of the file ``out``; move it onto ``out`` when the block succeeds."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_sibling(out, "tmp")
    _remove(tmp)
    try:
        yield tmp
    except BaseException:
        _remove(tmp)
        raise
    _replace(tmp, out)


@contextlib.contextmanager
def atomic_named_dir(out: Path) -> Iterator[Path]:
    """Like :func:`atomic_dir`, but yield a *not yet existing* path with ``out``'s own name (inside a
    temporary sibling folder), for writers that create their folder and name files after it (rosbag2)."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    holder = _tmp_sibling(out, "tmp")
    _remove(holder)
    holder.mkdir()
    try:
        yield holder / out.name
        _replace(holder / out.name, out)
    finally:
        shutil.rmtree(holder, ignore_errors=True)


def _replace(tmp: Path, out: Path) -> None:
    """Move ``tmp`` onto ``out``; an existing ``out`` (file or folder) is set aside first, then deleted."""
    old = _tmp_sibling(out, "old")
    if out.exists() or out.is_symlink():
        _remove(old)
        out.rename(old)
    tmp.rename(out)
    if old.exists():
        _remove(old)
    log.info("wrote %s", out)


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
