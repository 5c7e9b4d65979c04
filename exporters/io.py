"""Atomic output writing and image placement shared by the exporters.

An export is written into a temporary sibling of its destination (``.<name>.tmp-<pid>``) and renamed
into place only when complete, so a failure leaves the destination as it was and nothing half-written.
Images are hard-linked from the record when the file system allows it (same device, links permitted),
copied otherwise; either way the bytes are the record's.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path
from typing import Any

from pipeline.core.files import atomic_dir, atomic_file, atomic_named_dir

log = logging.getLogger(__name__)
__all__ = ["atomic_dir", "atomic_file", "atomic_named_dir", "dumps_json", "link_or_copy", "write_json"]


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
