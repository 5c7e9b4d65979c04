"""Reading MOTChallenge 2D box files: ground truth (``gt/gt.txt``) and tracker results (``<seq>.txt``).

Formats (MOTChallenge, MOT16 paper and TrackEval's ``MotChallenge2DBox`` reader), one box per line, comma-separated
(a line without a comma: whitespace-separated; an empty field is an error, never skipped):

- ground truth: ``frame, id, bb_left, bb_top, bb_width, bb_height, considered, class[, visibility]``:
  ``considered`` 0 marks a box not to evaluate; ``class`` is a MOT class id (:data:`MOT_CLASSES`).
- tracker results: ``frame, id, bb_left, bb_top, bb_width, bb_height, conf[, x, y, z]``; the class is not read
  (tracker output is class-agnostic).

Frames are 1-based and lie in ``1 .. seqLength`` (``seqinfo.ini`` beside ``gt/``, or the last ground-truth frame
when there is none). Validation is strict (:class:`evaluation.validate.InputError`): the message names the file,
the line and the field. An empty results file is a tracker that output nothing.
"""

from __future__ import annotations

import configparser
import dataclasses
from pathlib import Path

import numpy as np

from evaluation.validate import InputError

MOT_CLASSES = {1: "pedestrian", 2: "person_on_vehicle", 3: "car", 4: "bicycle", 5: "motorbike", 6: "non_mot_vehicle",
               7: "static_person", 8: "distractor", 9: "occluder", 10: "occluder_on_ground", 11: "occluder_full",
               12: "reflection", 13: "crowd"}
"""MOTChallenge class ids (MOT16/17/20 ground truth)."""
DISTRACTOR_CLASSES = (2, 7, 8, 12)
"""Classes whose boxes a tracker may cover unpunished (MOT17's distractors: TrackEval removes tracker boxes matched
to them)."""
GT_FIELDS = ("frame", "id", "bb_left", "bb_top", "bb_width", "bb_height", "considered", "class", "visibility")
RESULT_FIELDS = ("frame", "id", "bb_left", "bb_top", "bb_width", "bb_height", "conf")
MAX_INT = 2**31 - 1  # frames and ids are 32-bit in MOT tools


@dataclasses.dataclass(frozen=True)
class MotBoxes:
    """The boxes of one sequence from one file.

    Attributes:
        source: the file read (for messages).
        length: frames of the sequence (1 .. length).
        frame: (N,) int64 1-based frame.
        ids: (N,) int64 track id (>= 0), unique within a frame.
        boxes: (N, 4) float64 ``bb_left, bb_top, bb_width, bb_height`` (pixels).
        considered: (N,) bool ground truth's evaluation flag (all True for tracker results).
        classes: (N,) int64 MOT class id (ground truth; -1 for tracker results).
    """

    source: str
    length: int
    frame: np.ndarray
    ids: np.ndarray
    boxes: np.ndarray
    considered: np.ndarray
    classes: np.ndarray


def _parse(path: Path, fields: tuple[str, ...], required: int) -> np.ndarray:
    """(N, required) float64 of the file's lines; InputError naming the file, line and field."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        values = [v.strip() for v in line.split(",")] if "," in line else line.split()
        if len(values) < required:
            raise InputError(f"{path}, line {number}: {len(values)} values, expected at least {required} "
                             f"({', '.join(fields[:required])})")
        row = []
        for name, value in zip(fields[:required], values, strict=False):
            try:
                number_value = float(value)
            except ValueError:
                raise InputError(f"{path}, line {number}: {name} {value!r} is not a number") from None
            if not np.isfinite(number_value):
                raise InputError(f"{path}, line {number}: {name} {value!r} is not finite")
            row.append(number_value)
        rows.append(row)
    return np.array(rows, dtype=np.float64).reshape(-1, required)


def _check(path: Path, table: np.ndarray, length: int | None) -> int:
    """Checks shared by both kinds of file; returns the sequence length."""
    frame, ids, wh = table[:, 0], table[:, 1], table[:, 4:6]
    for name, column, low in (("frame", frame, 1), ("id", ids, 0)):
        bad = np.flatnonzero((column != np.round(column)) | (column < low) | (column > MAX_INT))
        if len(bad):
            raise InputError(f"{path}, box {bad[0] + 1}: {name} {column[bad[0]]:g} is not an integer from {low} to "
                             f"{MAX_INT}")
    bad = np.flatnonzero(np.any(wh < 0, axis=1))
    if len(bad):
        raise InputError(f"{path}, box {bad[0] + 1}: bb_width and bb_height must be >= 0, got {wh[bad[0]].tolist()}")
    if length is None:
        length = int(frame.max()) if len(frame) else 0
    late = np.flatnonzero(frame > length)
    if len(late):
        raise InputError(f"{path}, box {late[0] + 1}: frame {int(frame[late[0]])} is beyond the sequence's "
                         f"{length} frames")
    pairs = frame.astype(np.int64) * (2 ** 32) + ids.astype(np.int64)
    unique, counts = np.unique(pairs, return_counts=True)
    if np.any(counts > 1):
        i = int(np.flatnonzero(counts > 1)[0])
        raise InputError(f"{path}: frame {unique[i] >> 32} has id {unique[i] & (2 ** 32 - 1)} more than once")
    return length


def read_gt_file(path: Path, length: int | None = None) -> MotBoxes:
    """One ground-truth file (``gt.txt``); ``length`` from seqinfo.ini, else the last frame."""
    path = Path(path)
    table = _parse(path, GT_FIELDS, 8)
    length = _check(path, table, length)
    considered, classes = table[:, 6], table[:, 7]
    bad = np.flatnonzero((considered != 0) & (considered != 1))
    if len(bad):
        raise InputError(f"{path}, box {bad[0] + 1}: considered {considered[bad[0]]:g} is not 0 or 1")
    bad = np.flatnonzero(~np.isin(classes, list(MOT_CLASSES)))
    if len(bad):
        raise InputError(f"{path}, box {bad[0] + 1}: class {classes[bad[0]]:g} is not a MOT class id "
                         f"({', '.join(f'{k} {v}' for k, v in MOT_CLASSES.items())})")
    return MotBoxes(str(path), length, table[:, 0].astype(np.int64), table[:, 1].astype(np.int64), table[:, 2:6],
                    considered == 1, classes.astype(np.int64))


def read_results_file(path: Path, length: int) -> MotBoxes:
    """One tracker results file of a sequence of ``length`` frames (an empty file: no output)."""
    path = Path(path)
    table = _parse(path, RESULT_FIELDS, 7)
    _check(path, table, length)
    n = len(table)
    return MotBoxes(str(path), length, table[:, 0].astype(np.int64), table[:, 1].astype(np.int64), table[:, 2:6],
                    np.ones(n, bool), np.full(n, -1, np.int64))


def _seq_length(seq_dir: Path) -> int | None:
    ini = seq_dir / "seqinfo.ini"
    if not ini.is_file():
        return None
    parser = configparser.ConfigParser()
    try:
        parser.read(ini, encoding="utf-8")
        value = parser["Sequence"]["seqLength"]
    except (configparser.Error, KeyError, UnicodeDecodeError):
        raise InputError(f"{ini}: no [Sequence] seqLength") from None
    if not value.strip().isdigit() or int(value) > MAX_INT:
        raise InputError(f"{ini}: seqLength {value!r} is not an integer from 0 to {MAX_INT}")
    return int(value)


def read_gt(path: Path) -> dict[str, MotBoxes]:
    """Ground truth by sequence name, sorted: a ``gt.txt`` file (its sequence is the folder above ``gt/``), a
    sequence folder (``SEQ/gt/gt.txt``), or a folder of sequence folders (a MOTChallenge split)."""
    path = Path(path)
    if path.is_file():
        seq_dir = path.parent.parent if path.parent.name == "gt" else path.parent
        name = seq_dir.name if path.parent.name == "gt" else path.stem
        return {name: read_gt_file(path, _seq_length(seq_dir))}
    if not path.is_dir():
        raise InputError(f"{path}: not found (expected a MOT gt.txt, a sequence folder or a folder of sequences)")
    if (path / "gt" / "gt.txt").is_file():
        return {path.name: read_gt_file(path / "gt" / "gt.txt", _seq_length(path))}
    seqs = sorted(p for p in path.iterdir() if (p / "gt" / "gt.txt").is_file())
    if not seqs:
        raise InputError(f"{path}: no MOT sequence (no gt/gt.txt in it or in its sub-folders)")
    return {p.name: read_gt_file(p / "gt" / "gt.txt", _seq_length(p)) for p in seqs}


def read_results(path: Path, gt: dict[str, MotBoxes]) -> dict[str, MotBoxes]:
    """Tracker results for every sequence of ``gt``: a folder of ``<seq>.txt`` files (TrackEval's layout), or one
    file when the ground truth has one sequence."""
    path = Path(path)
    if path.is_file():
        if len(gt) != 1:
            raise InputError(f"{path}: one results file for {len(gt)} sequences; give a folder with one "
                             f"<sequence>.txt per sequence ({', '.join(gt)})")
        (name, boxes), = gt.items()
        return {name: read_results_file(path, boxes.length)}
    if not path.is_dir():
        raise InputError(f"{path}: tracker results not found (expected a MOT results file or a folder of them)")
    missing = [name for name in gt if not (path / f"{name}.txt").is_file()]
    if missing:
        raise InputError(f"{path}: no results file for sequence(s) {', '.join(f'{m}.txt' for m in missing)} "
                         "(a tracker with no output writes an empty file)")
    return {name: read_results_file(path / f"{name}.txt", boxes.length) for name, boxes in gt.items()}
