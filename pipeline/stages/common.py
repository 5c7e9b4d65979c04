"""What every stage shares: atomic output folders, ``meta.json``, and config hashing.

A stage writes into a temporary sibling of its output and renames it into place only when it has
finished, so a crash never leaves a half-written folder that DVC would hash.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import logging
import math
import sys
import zlib
from collections.abc import Callable, Iterator
from importlib import metadata
from pathlib import Path
from typing import Any

from pipeline.core.files import atomic_dir

log = logging.getLogger(__name__)


def _non_finite(data: Any, where: str = "") -> Iterator[tuple[str, float]]:
    """(key path, value) of every inf or NaN float in nested dicts and lists."""
    if isinstance(data, float) and not math.isfinite(data):
        yield where or "(top level)", data
    elif isinstance(data, dict):
        for key, value in data.items():
            yield from _non_finite(value, f"{where}.{key}" if where else str(key))
    elif isinstance(data, (list, tuple)):
        for i, value in enumerate(data):
            yield from _non_finite(value, f"{where}[{i}]")


def _dumps(data: Any, source: str, **kwargs: Any) -> str:
    """json.dumps that refuses inf and NaN (``Infinity`` and ``NaN`` are not JSON) and names the key."""
    try:
        return json.dumps(data, allow_nan=False, **kwargs)
    except ValueError:
        bad = next(_non_finite(data), None)
        if bad is None:
            raise
        raise ValueError(f"{source}: {bad[0]} is {bad[1]!r}; JSON holds only finite numbers") from None


def canonical_json(data: Any) -> str:
    """JSON with sorted keys and no insignificant whitespace: the input of :func:`config_hash`."""
    return _dumps(data, "config", sort_keys=True, separators=(",", ":"), ensure_ascii=True)


def config_hash(data: Any) -> str:
    """sha256 hex digest of the canonical JSON of ``data``."""
    return hashlib.sha256(canonical_json(data).encode()).hexdigest()


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def software_versions() -> dict[str, str | None]:
    """Versions of roadsynth and the engines that shape its outputs."""
    return {
        "roadsynth": _version("roadsynth"),
        "sumo": _version("eclipse-sumo"),
        "libsumo": _version("libsumo"),
        "open3d": _version("open3d-cpu") or _version("open3d"),
        "numpy": _version("numpy"),
        "pyarrow": _version("pyarrow"),
        "opencv": _version("opencv-python-headless") or _version("opencv-python"),  # post effects, image noise
        "zlib": zlib.ZLIB_RUNTIME_VERSION,  # the bytes of the records' PNG files (pipeline.core.png)
        "numba": _version("numba"),  # compiles the render's per-pixel passes (pipeline.core.jit)
    }


def write_json(path: Path, data: Any) -> None:
    """Write JSON deterministically (sorted keys, two-space indent, trailing newline); inf or NaN
    anywhere is an error naming the file and the key, never ``Infinity`` or ``NaN`` in the file."""
    path.write_text(_dumps(data, str(path), sort_keys=True, indent=2) + "\n")


def write_meta(
    out_dir: Path, *, stage: str, config: dict[str, Any], seed: int | None, argv: list[str] | None = None
) -> dict[str, Any]:
    """Write ``meta.json``: versions, the resolved config, its hash, the seed and the command line.

    The command line (:func:`command_line`) is informational and excluded from the config hash so that the same
    config and seed give the same hash anywhere.
    """
    meta = {
        "stage": stage,
        "versions": software_versions(),
        "config": config,
        "config_hash": config_hash(config),
        "seed": seed,
        "command": command_line(argv),
    }
    write_json(out_dir / "meta.json", meta)
    return meta


def command_line(argv: list[str] | None = None) -> list[str]:
    """``argv`` (default ``sys.argv``) with the program as its bare name: the absolute path of the venv's
    ``roadsynth`` script would make outputs differ between two checkouts of the same pipeline."""
    argv = list(sys.argv if argv is None else argv)
    return [Path(argv[0]).name, *argv[1:]] if argv else []


@contextlib.contextmanager
def atomic_output_dir(out_dir: Path) -> Iterator[Path]:
    """Yield a temporary sibling of ``out_dir``; rename it into place when the block succeeds.

    On an exception the temporary folder is removed and ``out_dir`` is left as it was. Whether ``out_dir`` may be
    replaced at all is the CLI's check (:mod:`pipeline.core.outputs`), made before the stage runs.
    """
    out_dir = Path(out_dir)
    with atomic_dir(out_dir) as tmp:
        yield tmp


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer >= ``minimum`` (argparse names the flag in its error)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {value}")
        return value

    parse.__name__ = f"integer >= {minimum}"
    return parse


def run_seed(text: str) -> int:
    """An argparse ``type`` for a run seed (:func:`pipeline.core.config.base.run_seed_problem`)."""
    from pipeline.core.config.base import run_seed_problem

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    problem = run_seed_problem(value)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return value


def float_list(text: str) -> list[float]:
    """An argparse ``type`` for list flags: comma-separated numbers (``0.5,0.7``); with ``nargs="+"`` and
    :class:`Flatten`, space-separated ones too (``0.5 0.7``), as the other list flags take commas."""
    try:
        return [float(item) for item in text.split(",") if item.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas or spaces, got {text!r}") from None


class Flatten(argparse.Action):
    """Store the items of the lists an ``nargs="+"`` list type (:func:`float_list`) gives, as one list."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        setattr(namespace, self.dest, [item for chunk in values for item in chunk])
