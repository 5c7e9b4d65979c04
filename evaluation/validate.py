"""Strict, vectorised extraction of JSON columns with errors that name the file, the entry and the field.

Every helper first tries a fast path (one list comprehension, one ``np.array``) and only walks the
entries one by one to find the first offending entry when the fast path fails, so validation stays cheap
on a million detections while the message stays exact.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np


class InputError(ValueError):
    """Bad evaluation input; the message names the file, the entry (section and index) and the field."""


_MISSING = object()


def where(path: str, section: str, index: int) -> str:
    """``"gt.json: annotations[12]"``: the location prefix of every message."""
    return f"{path}: {section}[{index}]"


def _first_bad(entries: Sequence[Any], field: str, path: str, section: str, check, expected: str, *,
               optional: bool = False) -> InputError:
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict):
            return InputError(f"{where(path, section, i)}: expected a JSON object, got {type(entry).__name__}")
        value = entry.get(field, _MISSING)
        if value is _MISSING and optional:
            continue
        if value is _MISSING:
            return InputError(f"{where(path, section, i)}: missing field '{field}' (expected {expected})")
        if not check(value):
            return InputError(f"{where(path, section, i)}: field '{field}' is {value!r} (expected {expected})")
    return InputError(f"{path}: {section}: field '{field}': invalid values (expected {expected})")


_INT64 = (-(2**63), 2**63 - 1)
_FLOAT_MAX = sys.float_info.max


def _is_int(v: Any) -> bool:
    """A JSON integer that fits int64 (JSON itself allows any size)."""
    return type(v) is int and _INT64[0] <= v <= _INT64[1]


def is_number(v: Any) -> bool:
    """A finite JSON number that fits a float64 (an integer beyond ~1.8e308 does not; comparing is exact)."""
    return (type(v) is float and math.isfinite(v)) or (type(v) is int and -_FLOAT_MAX <= v <= _FLOAT_MAX)


def _is_box(v: Any) -> bool:
    return type(v) is list and len(v) == 4 and all(is_number(x) for x in v) and v[2] >= 0 and v[3] >= 0


def _values(entries: Sequence[Any], field: str, path: str, section: str, expected: str, default: Any) -> list[Any]:
    try:
        if default is _MISSING:
            return [e[field] for e in entries]
        return [e.get(field, default) for e in entries]
    except (KeyError, TypeError, AttributeError):
        raise _first_bad(entries, field, path, section, lambda v: True, expected) from None


def _array(values: list[Any], empty: np.ndarray) -> np.ndarray | None:
    """``np.array(values)`` (``empty`` when there are none), or None where numpy cannot make one array of them (a
    list among numbers: 'inhomogeneous shape'): the caller then names the first offending entry."""
    if not values:
        return empty
    try:
        return np.array(values)
    except (ValueError, TypeError, OverflowError):
        return None


def int_column(entries: Sequence[Any], field: str, path: str, section: str, *, nonzero: bool = True) -> np.ndarray:
    """(N,) int64 of a required integer field; 0 is refused when ``nonzero`` (pycocotools reads 0 as 'none')."""
    expected = "a non-zero 64-bit integer" if nonzero else "a 64-bit integer"
    values = _values(entries, field, path, section, expected, _MISSING)
    arr = _array(values, np.zeros(0, np.int64))
    if arr is None or arr.dtype.kind != "i" or arr.ndim != 1 or bool in set(map(type, values)):
        raise _first_bad(entries, field, path, section, _is_int, expected)
    arr = arr.astype(np.int64, copy=False)
    if nonzero and (arr == 0).any():
        raise _first_bad(entries, field, path, section, lambda v: _is_int(v) and v != 0, expected)
    return arr


def number_column(
    entries: Sequence[Any],
    field: str,
    path: str,
    section: str,
    *,
    default: Any = _MISSING,
    minimum: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(N,) float64 of a finite numeric field and its (N,) bool presence mask.

    A missing field (or JSON ``null``) is an error unless ``default`` is given, in which case it is marked
    absent in the mask. ``minimum`` refuses smaller values.
    """
    expected = "a finite number" + (f" >= {minimum:g}" if minimum is not None else "")
    values = _values(entries, field, path, section, expected, None if default is not _MISSING else _MISSING)
    present = np.array([v is not None for v in values], dtype=bool) if values else np.zeros(0, bool)
    if default is _MISSING and not present.all():
        raise _first_bad(entries, field, path, section, lambda v: v is not None, expected)
    filled = [v if v is not None else 0.0 for v in values] if not present.all() else values
    arr = _array(filled, np.zeros(0))

    def ok(v: Any) -> bool:
        return v is None or (is_number(v) and (minimum is None or v >= minimum))

    optional = default is not _MISSING
    if arr is None or arr.dtype.kind not in "if" or arr.ndim != 1 or bool in set(map(type, values)):
        if not all(map(ok, values)):
            raise _first_bad(entries, field, path, section, ok, expected, optional=optional)
        arr = np.array(filled, dtype=np.float64)  # numbers all, but an integer beyond int64 made numpy keep objects
    arr = arr.astype(np.float64, copy=False)
    bad = ~np.isfinite(arr)
    if minimum is not None:
        bad |= arr < minimum
    if bad.any():
        raise _first_bad(entries, field, path, section, ok, expected, optional=optional)
    return arr, present


def box_column(entries: Sequence[Any], path: str, section: str) -> np.ndarray:
    """(N, 4) float64 ``x, y, w, h`` from the required ``bbox`` field: finite numbers, ``w, h >= 0``."""
    expected = "[x, y, width, height] of finite numbers with width, height >= 0"
    values = _values(entries, "bbox", path, section, expected, _MISSING)
    try:
        arr = np.array(values, dtype=None) if values else np.zeros((0, 4))
    except (ValueError, TypeError):
        raise _first_bad(entries, "bbox", path, section, _is_box, expected) from None
    if arr.dtype.kind not in "if" or arr.shape != (len(values), 4):
        if not all(map(_is_box, values)):
            raise _first_bad(entries, "bbox", path, section, _is_box, expected)
        arr = np.array(values, dtype=np.float64)  # numbers all, but an integer beyond int64 made numpy keep objects
    arr = arr.astype(np.float64, copy=False)
    if not np.isfinite(arr).all() or (arr[:, 2:] < 0).any():
        raise _first_bad(entries, "bbox", path, section, _is_box, expected)
    return arr


def check_unique(ids: np.ndarray, field: str, path: str, section: str) -> None:
    """Refuse duplicate ids, naming both entries."""
    if len(ids) == 0:
        return
    order = np.argsort(ids, kind="stable")
    dup = np.nonzero(ids[order][1:] == ids[order][:-1])[0]
    if len(dup):
        first, second = sorted((int(order[dup[0]]), int(order[dup[0] + 1])))
        raise InputError(
            f"{where(path, section, second)}: duplicate {field} {int(ids[second])} (also at {section}[{first}])"
        )


def lookup(ids: np.ndarray, known: np.ndarray, field: str, path: str, section: str, what: str) -> np.ndarray:
    """(N,) int64 index of each id in the sorted ``known`` ids; unknown ids are an error naming the entry."""
    idx = np.searchsorted(known, ids)
    idx_clipped = np.minimum(idx, max(len(known) - 1, 0))
    found = (idx < len(known)) & (known[idx_clipped] == ids) if len(known) else np.zeros(len(ids), bool)
    if not found.all():
        bad = np.nonzero(~found)[0]
        raise InputError(
            f"{where(path, section, int(bad[0]))}: field '{field}' is {int(ids[bad[0]])}, not an id of the "
            f"ground truth's {what} ({len(bad)} entries have unknown {field}s)"
        )
    return idx_clipped.astype(np.int64)
