"""Atomic outputs: write into a temporary sibling, rename into place only when complete.

A failure leaves the destination as it was and removes the temporary, so nothing half-written is ever
seen where DVC (or a user) looks. Used by every stage and exporter. What a stage may replace, the lock of an
output and the temporaries of killed runs: :mod:`pipeline.core.outputs`.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

log = logging.getLogger(__name__)


def _tmp_sibling(path: Path, tag: str) -> Path:
    return path.with_name(f".{path.name}.{tag}-{os.getpid()}")


def remove_path(path: Path) -> None:
    """Remove the file, link or folder ``path``."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    elif path.exists() or path.is_symlink():
        path.unlink()


def _fresh_sibling(out: Path) -> Path:
    """The temporary sibling of ``out`` (parent folders created), cleared of any leftover."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = _tmp_sibling(out, "tmp")
    remove_path(tmp)
    return tmp


@contextlib.contextmanager
def atomic_dir(out: Path) -> Iterator[Path]:
    """Yield an empty temporary sibling folder of ``out``; replace ``out`` by it when the block succeeds."""
    out = Path(out)
    tmp = _fresh_sibling(out)
    tmp.mkdir()
    try:
        yield tmp
        replace_path(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


@contextlib.contextmanager
def atomic_file(out: Path) -> Iterator[Path]:
    """Yield a temporary sibling path of the file ``out``; move it onto ``out`` when the block succeeds."""
    out = Path(out)
    tmp = _fresh_sibling(out)
    try:
        yield tmp
        replace_path(tmp, out)
    except BaseException:
        if tmp.exists() or tmp.is_symlink():
            remove_path(tmp)
        raise


@contextlib.contextmanager
def atomic_named_dir(out: Path) -> Iterator[Path]:
    """Like :func:`atomic_dir`, but yield a *not yet existing* path with ``out``'s own name (inside a
    temporary sibling folder), for writers that create their folder and name files after it (rosbag2)."""
    out = Path(out)
    holder = _fresh_sibling(out)
    holder.mkdir()
    try:
        yield holder / out.name
        replace_path(holder / out.name, out)
    finally:
        shutil.rmtree(holder, ignore_errors=True)


MANIFEST_KEY = "files"  # meta.json's list of the files a stage wrote into its output folder


def seal(folder: Path) -> None:
    """Record in ``folder/meta.json`` (when the folder has one) every other file the stage wrote there, by relative
    path, with its size: the manifest by which a later run knows the folder holds only what a stage wrote
    (:mod:`pipeline.core.outputs`). meta.json is left out of byte comparisons, so the record changes no output."""
    meta_path = folder / "meta.json"
    if not meta_path.is_file():
        return
    meta = json.loads(meta_path.read_text())
    if not isinstance(meta, dict):
        return
    meta[MANIFEST_KEY] = {p.relative_to(folder).as_posix(): p.stat().st_size
                          for p in sorted(folder.rglob("*")) if p.is_file() and p != meta_path}
    meta_path.write_text(json.dumps(meta, sort_keys=True, indent=2) + "\n")


def replace_path(tmp: Path, out: Path) -> None:
    """Move ``tmp`` onto ``out``; an existing ``out`` (file or folder) is set aside first, then deleted. A folder is
    sealed first (:func:`seal`)."""
    if tmp.is_dir() and not tmp.is_symlink():
        seal(tmp)
    old = _tmp_sibling(out, "old")
    if out.exists() or out.is_symlink():
        remove_path(old)
        out.rename(old)
    try:
        tmp.rename(out)
    except BaseException:
        if (old.exists() or old.is_symlink()) and not (out.exists() or out.is_symlink()):
            old.rename(out)  # put the earlier output back
        raise
    if old.exists():
        remove_path(old)
    log.info("wrote %s", out)
