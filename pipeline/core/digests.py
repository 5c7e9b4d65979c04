"""Content digests of input files and folders, recorded in ``meta.json`` so a later stage can check
that it reads the very inputs an earlier stage used (paths move and get reused; content does not lie)."""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["path_sha256"]

_CHUNK = 1 << 20


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        while chunk := f.read(_CHUNK):
            digest.update(chunk)
    return digest.hexdigest()


def path_sha256(path: str | Path) -> str:
    """sha256 hex digest of a file's bytes, or of a folder: every file's relative path and digest, in
    path order (so a KITTI label directory has one digest too).

    Raises:
        FileNotFoundError: ``path`` does not exist.
    """
    path = Path(path)
    if path.is_file():
        return _file_sha256(path)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: not found")
    digest = hashlib.sha256()
    for file in sorted(p for p in path.rglob("*") if p.is_file()):
        digest.update(f"{file.relative_to(path).as_posix()}\0{_file_sha256(file)}\n".encode())
    return digest.hexdigest()
