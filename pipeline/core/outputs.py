"""Output safety: what a stage may replace, one writer per output, and the temporaries of killed runs.

The rule, the same for every stage (:func:`claimed_outputs`):

- An output is never one of the stage's inputs, inside one, or a folder holding one (nor the working
  directory or a folder holding it): replacing it would destroy what the stage reads. An input that lies
  inside a stage output (a folder with a ``meta.json`` naming its stage) stands for that whole folder: an
  evaluation written into the COCO export it scores would change that export. ``--overwrite`` does not lift
  this.
- A folder output may replace nothing, an empty folder, or exactly an earlier output of the same stage: its
  ``meta.json`` names the stage and lists every file the stage wrote there with its size (the manifest,
  :func:`pipeline.core.files.seal`), and the folder holds those files and no other, unchanged in size. A file
  the user put there (notes, a plot), or a file changed since, makes it not the stage's alone. A file output
  may replace a file that carries the stage's own mark (its :attr:`OutputSpec.recognise`: a PNG whose text
  chunk names roadsynth, an MCAP with roadsynth's metadata record, a JSON object with roadsynth's key, a
  results list with roadsynth's sidecar). Anything else -- another program's file of the same kind, a file
  where a folder goes, a folder of other files, a symbolic link -- is replaced only with ``--overwrite``.
- While a stage writes an output it holds an exclusive lock (``flock``) on a hidden sibling
  ``.NAME.lock``; a second writer fails at once, naming the first. The kernel drops the lock when the
  holder dies, even by ``kill -9``, so a later run finds the lock free and removes the temporaries a killed
  run left (``.NAME.tmp-PID``, ``.NAME.old-PID``; see :mod:`pipeline.core.files`). An output set aside for
  replacement (``.old``) when the run died is put back if nothing replaced it.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import logging
import os
import re
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from pipeline.core.files import MANIFEST_KEY, remove_path

log = logging.getLogger(__name__)

OVERWRITE_FLAG = "--overwrite"


class OutputError(ValueError):
    """An output the stage must not replace (without ``--overwrite``); the message starts with the flag and path."""


class OutputBusy(OutputError):
    """Another process is writing the output."""


@dataclass(frozen=True)
class OutputSpec:
    """One output of a stage run.

    Attributes:
        path: where it goes, as given.
        flag: the command-line flag that named it (for messages).
        folder: a folder output (True) or a file (False).
        recognise: for a file output, whether an existing file holds what the stage writes (then it may be
            replaced without ``--overwrite``): returns None when it does, else what it is instead.
        expected: what the stage writes there, in words (for messages).
        resumable: for a folder a stage resumes into (``experiment run``: it is never replaced whole, so it has
            no manifest), why an existing folder of the stage holds something the stage does not write there
            (None: it holds only the stage's); used instead of the manifest.
    """

    path: Path
    flag: str = "--out"
    folder: bool = True
    recognise: Callable[[Path], str | None] | None = None
    expected: str = "a folder"
    resumable: Callable[[Path], str | None] | None = None


# --- recognisers of earlier file outputs -------------------------------------------------------------------

def _starts_with(path: Path, magic: bytes) -> bool:
    with path.open("rb") as fh:
        return fh.read(len(magic)) == magic


MARK = "roadsynth"  # the mark of our own file outputs (a PNG text chunk's value starts with it, a JSON key, ...)
MARK_KEY = "written_by"  # the JSON key (and PNG text keyword "Software" holds the value) that carries it


def png_file(path: Path) -> str | None:
    """None when ``path`` is a PNG image that roadsynth wrote (a ``Software`` text chunk naming roadsynth)."""
    from pipeline.core.png import png_text

    if not _starts_with(path, b"\x89PNG\r\n\x1a\n"):
        return "not a PNG image"
    return None if png_text(path).get("Software", "").startswith(MARK) else "a PNG image roadsynth did not write"


def mcap_file(path: Path) -> str | None:
    """None when ``path`` is an MCAP file that roadsynth's export wrote (its ``roadsynth.export`` metadata)."""
    if not _starts_with(path, b"\x89MCAP"):
        return "not an MCAP file"
    try:
        from mcap.reader import make_reader

        with path.open("rb") as fh:
            names = {m.name for m in make_reader(fh).iter_metadata()}
    except Exception:  # any damage, or another writer's variant: not provably ours
        return "an MCAP file that cannot be read"
    return None if "roadsynth.export" in names else "an MCAP file roadsynth did not write"


def sidecar_path(path: Path) -> Path:
    """The mark of a file output that cannot carry one itself (a COCO results list): a hidden JSON beside it."""
    return path.with_name(f".{path.name}.roadsynth.json")


def marked_sidecar(stage: str) -> Callable[[Path], str | None]:
    """A recogniser of files whose :func:`sidecar_path` says ``stage`` wrote them, with their current size."""

    def recognise(path: Path) -> str | None:
        try:
            mark = json.loads(sidecar_path(path).read_text())
        except (OSError, UnicodeDecodeError, ValueError):
            return f"no {sidecar_path(path).name} beside it says roadsynth wrote it"
        if not isinstance(mark, dict) or mark.get(MARK_KEY) != f"{MARK} {stage}":
            return f"{sidecar_path(path).name} does not say `roadsynth {stage}` wrote it"
        if mark.get("size") != path.stat().st_size:
            return "changed since roadsynth wrote it"
        return None

    return recognise


def write_sidecar(path: Path, stage: str) -> None:
    """Mark ``path`` (written by ``stage``) with :func:`sidecar_path`."""
    sidecar_path(path).write_text(json.dumps({MARK_KEY: f"{MARK} {stage}", "size": path.stat().st_size}) + "\n")


def json_file(top: type, keys: Iterable[str] = (), *, marked: bool = True) -> Callable[[Path], str | None]:
    """A recogniser of JSON files whose top level is a ``top`` (dict or list) holding ``keys`` (a dict's keys, or
    each item's keys of a list); a dict must also carry roadsynth's mark (``MARK_KEY``) unless not ``marked``."""
    keys = tuple(keys) + ((MARK_KEY,) if marked and top is dict else ())

    def recognise(path: Path) -> str | None:
        try:
            data = json.loads(path.read_text())
        except (UnicodeDecodeError, ValueError):
            return "not a JSON file"
        if not isinstance(data, top):
            return f"JSON, but not a {top.__name__}"
        items = data if isinstance(data, list) else [data]
        if any(not isinstance(item, dict) or not all(k in item for k in keys) for item in items):
            return f"JSON without the keys {', '.join(keys)}"
        return None

    return recognise


# --- the rule ----------------------------------------------------------------------------------------------

def output_stage(folder: Path) -> str | None:
    """The stage named by ``folder/meta.json``, or None when there is none (or it is unreadable)."""
    try:
        meta = json.loads((folder / "meta.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    stage = meta.get("stage") if isinstance(meta, dict) else None
    return stage if isinstance(stage, str) else None


def _input_unit(path: Path) -> Path:
    """``path`` resolved, or the stage output folder it lies in (the nearest folder with a stage's meta.json)."""
    real = path.resolve()
    for folder in (real, *real.parents) if real.is_dir() else real.parents:
        if output_stage(folder) is not None:
            return folder
    return real


def _is_within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _clash_with_inputs(spec: OutputSpec, inputs: Sequence[Path]) -> str | None:
    real = Path(spec.path).resolve()
    cwd = Path.cwd().resolve()
    if _is_within(cwd, real):
        return f"{spec.flag} {spec.path}: is the working directory or holds it; pick an output inside it"
    for given in inputs:
        if not (given.exists() or given.is_symlink()):
            continue
        unit = _input_unit(given)
        shown = given if unit == given.resolve() else f"{unit} (the stage output holding {given})"
        if real == unit:
            return f"{spec.flag} {spec.path}: is an input of this stage ({shown}); pick another output"
        if _is_within(real, unit):
            return f"{spec.flag} {spec.path}: is inside an input of this stage ({shown}); pick another output"
        if _is_within(unit, real):
            return f"{spec.flag} {spec.path}: holds an input of this stage ({shown}); pick another output"
    return None


def _not_the_stages(folder: Path) -> str | None:
    """Why ``folder`` (whose meta.json names a stage) holds more than what that stage wrote there, by its manifest
    (:func:`pipeline.core.files.seal`); None when it holds exactly those files."""
    meta = json.loads((folder / "meta.json").read_text())
    listed = meta.get(MANIFEST_KEY)
    if not isinstance(listed, dict):
        return "its meta.json lists no files (an older roadsynth wrote it): nothing shows that all it holds is ours"
    extra, changed = [], []
    for path in sorted(folder.rglob("*")):
        if (path.name == "meta.json" and path.parent == folder) or path.is_dir():
            continue
        rel = path.relative_to(folder).as_posix()
        if rel not in listed:
            extra.append(rel)
        elif path.is_symlink() or path.stat().st_size != listed[rel]:
            changed.append(rel)
    if not extra and not changed:
        return None
    parts = []
    if extra:
        parts.append(f"it also holds {_some(extra)}, which the stage did not write")
    if changed:
        parts.append(f"{_some(changed)} changed since the stage wrote {'it' if len(changed) == 1 else 'them'}")
    return " and ".join(parts)


def _some(names: list[str], shown: int = 3) -> str:
    more = f" and {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more


def _not_replaceable(spec: OutputSpec, stage: str) -> str | None:
    """Why the existing ``spec.path`` is not an output this stage may replace without --overwrite (None: it may)."""
    path = Path(spec.path)
    hint = f"pass {OVERWRITE_FLAG} to replace it, or choose another {spec.flag}"
    head = f"{spec.flag} {path}:"
    if not (path.exists() or path.is_symlink()):
        return None
    if path.is_symlink():
        return f"{head} is a symbolic link; expected {spec.expected}; {hint}"
    if spec.folder:
        if not path.is_dir():
            return f"{head} is a file; expected {spec.expected} (`roadsynth {stage}` writes a folder); {hint}"
        if not any(path.iterdir()):
            return None
        found = output_stage(path)
        if found == stage:
            unlisted = (spec.resumable or _not_the_stages)(path)
            if unlisted is None:
                return None
            return f"{head} is an earlier `roadsynth {stage}` output, but {unlisted}; {hint}"
        why = ("it has no meta.json" if not (path / "meta.json").exists() else
               "its meta.json is unreadable or names no stage" if found is None else
               f"its meta.json says it is a `roadsynth {found}` output")
        return f"{head} is a non-empty folder that is not an earlier `roadsynth {stage}` output ({why}); {hint}"
    if path.is_dir():
        return f"{head} is a folder; expected {spec.expected} (a file path); {hint}"
    if not path.is_file():
        return f"{head} is not a regular file; expected {spec.expected}; {hint}"
    why = spec.recognise(path) if spec.recognise is not None else "an existing file"
    if why is None:
        return None
    return (f"{head} is an existing file that `roadsynth {stage}` did not write ({why}; expected {spec.expected}); "
            f"{hint}")


def check_inputs(specs: Sequence[OutputSpec], inputs: Iterable[Path | None]) -> None:
    """Raise :class:`OutputError` when an output of ``specs`` is, holds or lies in an input (or the working
    directory), or names no file or folder of its own."""
    given = [Path(p) for p in inputs if p is not None]
    for spec in specs:
        if Path(spec.path).name in ("", ".", ".."):
            raise OutputError(f"{spec.flag} {spec.path}: expected {spec.expected} with a name of its own, not the "
                              "current or a parent folder")
        problem = _clash_with_inputs(spec, given)
        if problem:
            raise OutputError(problem)


def check_replaceable(specs: Sequence[OutputSpec], stage: str) -> None:
    """Raise :class:`OutputError` when an output of ``specs`` exists and is not one ``stage`` may replace."""
    for spec in specs:
        problem = _not_replaceable(spec, stage)
        if problem:
            raise OutputError(problem)


# --- the lock and stale temporaries ------------------------------------------------------------------------

def lock_path(out: Path) -> Path:
    """The lock file of the output ``out``: a hidden sibling."""
    return out.with_name(f".{out.name}.lock")


_HELD: set[tuple[int, str]] = set()  # (pid, lock file) this process holds; a forked child holds none of them


@contextlib.contextmanager
def output_lock(out: Path, stage: str, flag: str = "--out") -> Iterator[None]:
    """Hold the exclusive lock of ``out`` for the block; :class:`OutputBusy` at once when another process holds it.

    The lock file is removed (while still locked) at the end; a process that opened it just before finds, once it
    has the lock, that the file it locked is no longer the one at the path, and tries again. A process that holds
    the lock already (the CLI, around a stage function that takes it too) just enters the block.
    """
    given = out
    path = lock_path(Path(os.path.abspath(out)))
    key = (os.getpid(), str(path))
    if key in _HELD:
        yield
        return
    created: list[Path] = []
    try:
        created = _make_parents(path.parent)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:  # name the user's output, not our lock file
        for folder in created:
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise OutputError(f"{flag} {given}: cannot write there ({exc.strerror or exc}); choose another {flag}") \
            from None
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
                raise
            holder = _read_holder(path)
            raise OutputBusy(f"{flag} {given}: another process is writing it ({holder}, lock {path}); wait for it to "
                             f"finish or choose another {flag}") from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # unlinked by its last holder after we opened it: lock the new one
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    _HELD.add(key)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} roadsynth {stage}\n".encode())
        yield
    finally:
        _HELD.discard(key)
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
        os.close(fd)
        for folder in created:  # folders made for an output that was not written
            with contextlib.suppress(OSError):
                folder.rmdir()


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; return those created, deepest first."""
    missing = []
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    for made in reversed(missing):
        with contextlib.suppress(FileExistsError):
            made.mkdir()
    return missing


def _read_holder(path: Path) -> str:
    try:
        pid, _, what = path.read_text().strip().partition(" ")
    except OSError:
        return "an unknown process"
    return f"{what or 'a process'}, pid {pid}" if pid else "a process that is starting"


def _temporaries(out: Path, tag: str) -> list[Path]:
    pattern = re.compile(rf"\.{re.escape(out.name)}\.{tag}-\d+")
    if not out.parent.is_dir():
        return []
    return sorted(p for p in out.parent.iterdir() if pattern.fullmatch(p.name))


def clean_stale_temporaries(out: Path) -> None:
    """Remove what killed runs left beside ``out`` (call with the lock held): temporaries, and outputs set aside
    for a replacement that never came -- put back where ``out`` is missing, else removed."""
    out = Path(os.path.abspath(out))
    set_aside = _temporaries(out, "old")
    if set_aside and not (out.exists() or out.is_symlink()):
        newest = max(set_aside, key=lambda p: p.lstat().st_mtime)
        newest.rename(out)
        log.warning("%s: put back the earlier output a killed run had set aside (%s)", out, newest.name)
        set_aside.remove(newest)
    for stale in [*set_aside, *_temporaries(out, "tmp")]:
        log.info("removing %s, left by a run that was killed", stale)
        remove_path(stale)


@contextlib.contextmanager
def claimed_outputs(specs: Sequence[OutputSpec], *, stage: str, inputs: Iterable[Path | None],
                    overwrite: bool = False) -> Iterator[None]:
    """Check ``specs`` against the rule (see the module docstring), lock every output, remove stale temporaries
    beside them; the block then writes them. Everything is checked before anything is removed."""
    check_inputs(specs, inputs)
    with contextlib.ExitStack() as stack:
        for spec in specs:
            stack.enter_context(output_lock(spec.path, stage, spec.flag))
        if not overwrite:
            check_replaceable(specs, stage)
        for spec in specs:
            clean_stale_temporaries(spec.path)
        yield
