"""Locating and running SUMO's own tools (netconvert, netgenerate, duarouter, randomTrips).

The eclipse-sumo wheel installs the binaries next to the Python interpreter and SUMO's tools under
the ``sumo`` package (``sumo.SUMO_HOME``). SUMO stamps the generation time into the XML header of
every file it writes; :func:`strip_timestamp` removes it so the same inputs give the same bytes.
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

log = logging.getLogger(__name__)

_TIMESTAMP = re.compile(rb"<!-- generated on \S+ by Eclipse SUMO")
# How SUMO's XML reader places an error: " In file 'NAME'" then " At line/column L/C."
_LOCATION = re.compile(r"In file '(?P<file>[^']+)'(?:\s*At line/column (?P<line>\d+)/(?P<column>\d+))?")


class SumoToolError(RuntimeError):
    """A SUMO tool failed; the message carries the end of its output, with the user's paths for ours.

    Attributes (None where the error is not a tool's run): ``location``, the input file (the user's path) and, when
    the tool gives them, its line and column, e.g. ``map.osm, line 11, column 16``; ``detail``, the message without
    that location."""

    def __init__(self, message: str, *, location: str | None = None, detail: str | None = None) -> None:
        super().__init__(message)
        self.location = location
        self.detail = message if detail is None else detail


def sumo_home() -> Path:
    """SUMO_HOME of the installed eclipse-sumo wheel (or the environment's SUMO_HOME)."""
    try:
        import sumo  # the eclipse-sumo wheel's package

        return Path(sumo.SUMO_HOME)
    except ImportError:
        env = os.environ.get("SUMO_HOME")
        if env:
            return Path(env)
        raise SumoToolError("SUMO not found: install the eclipse-sumo wheel (pip install eclipse-sumo)") from None


def binary(name: str) -> str:
    """Path of a SUMO binary: next to this interpreter first, then on PATH, then in SUMO_HOME/bin."""
    here = Path(sys.executable).parent / name
    if here.is_file():
        return str(here)
    found = shutil.which(name)
    if found:
        return found
    candidate = sumo_home() / "bin" / name
    if candidate.is_file():
        return str(candidate)
    raise SumoToolError(f"SUMO binary {name!r} not found next to {sys.executable}, on PATH or in SUMO_HOME/bin")


def tool_script(relative: str) -> Path:
    """A script under SUMO_HOME/tools, e.g. ``randomTrips.py``."""
    path = sumo_home() / "tools" / relative
    if not path.is_file():
        raise SumoToolError(f"SUMO tool {relative!r} not found under {path.parent}")
    return path


def run_tool(args: list[str], cwd: Path, inputs: Mapping[str, Path] | None = None) -> str:
    """Run a SUMO tool in ``cwd`` (so written headers carry relative paths); raise with its output on failure.

    ``inputs`` maps the paths the tool is given for the user's files (copies in ``cwd``, relative to it or
    absolute) to the user's own paths: a failure names the user's file (and its line and column where the tool
    gives them), not our temporary copy.
    """
    log.debug("running %s (in %s)", " ".join(args), cwd)
    env = {**os.environ, "SUMO_HOME": str(sumo_home())}
    proc = subprocess.run(args, cwd=cwd, capture_output=True, text=True, env=env, check=False)
    if proc.returncode != 0:
        raise tool_error(Path(args[0]).name, proc.returncode, proc.stdout + proc.stderr, cwd, inputs or {})
    return proc.stdout + proc.stderr


def user_paths(text: str, cwd: Path, inputs: Mapping[str, Path]) -> str:
    """``text`` with each of our paths of ``inputs`` (as given, and absolute under ``cwd``) replaced by the user's."""
    pairs = []
    for ours, theirs in inputs.items():
        pairs += [(str(Path(cwd) / ours), str(theirs)), (str(ours), str(theirs))]
    for ours, theirs in sorted(pairs, key=lambda p: -len(p[0])):  # the longer (absolute) form first
        text = text.replace(ours, theirs)
    return text


def tool_error(tool: str, code: int, output: str, cwd: Path, inputs: Mapping[str, Path]) -> SumoToolError:
    """The error of a failed run: the end of its output (our paths of ``inputs`` made the user's), its first
    ``Error:`` line, and the file, line and column SUMO names (``In file '...'`` / ``At line/column L/C``)."""
    text = user_paths(output, cwd, inputs)
    tail = text.strip().splitlines()[-15:]
    first = next((line.strip()[len("Error:"):].strip() for line in text.splitlines()
                  if line.strip().startswith("Error:")), None)
    where = _LOCATION.search(text)
    location = None
    if where:
        location = where["file"] + (f", line {where['line']}, column {where['column']}" if where["line"] else "")
    detail = f"{tool} failed (exit {code})" + (f": {first}" if first else "") + "\n" + "\n".join(tail)
    return SumoToolError(f"{location}: {detail}" if location else detail, location=location, detail=detail)


def run_python_tool(script: str, args: list[str], cwd: Path) -> str:
    return run_tool([sys.executable, str(tool_script(script)), *args], cwd)


def strip_timestamp(path: Path) -> None:
    """Remove the generation time SUMO writes into an XML header (in place)."""
    data = path.read_bytes()
    new = _TIMESTAMP.sub(b"<!-- generated by Eclipse SUMO", data, count=1)
    if new != data:
        path.write_bytes(new)
