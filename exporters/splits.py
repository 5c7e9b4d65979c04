"""Train/val/test splits assigned by whole runs: a run is (scenario, seed), whatever its conditions.

Frames of one run are near-duplicates (the same traffic, a tenth of a second apart; the same traffic
under morning and night), so they must never straddle splits. A :class:`SplitSpec` is either

- fractions, ``train=0.8,val=0.1,test=0.1`` (summing to 1): runs are ordered by the sha256 of
  ``"<scenario>:<seed>"`` (deterministic, independent of the order records are given in) and cut into
  consecutive groups whose sizes are the fractions of the run count, rounded by largest remainder; or
- explicit runs, ``val=highway:3,test=urban:1+urban:2,train=*``: each split lists its runs joined by
  ``+``; ``*`` (at most one split) takes every run not listed. Without ``*`` every run must be listed.

The assignment (run -> split) is written into every export (``export.json`` or MCAP metadata).
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field

import numpy as np

log = logging.getLogger(__name__)

Run = tuple[str, int]  # (scenario, seed)
REST = "*"


class SplitError(ValueError):
    """A split specification that cannot be parsed or applied; the message names the offending part."""


def run_name(run: Run) -> str:
    return f"{run[0]}:{run[1]}"


def _parse_run(text: str, spec: str) -> Run:
    scenario, sep, seed = text.rpartition(":")
    if not sep or not scenario or not seed.lstrip("-").isdigit():
        raise SplitError(f"--splits {spec!r}: run {text!r} is not SCENARIO:SEED (e.g. highway:3)")
    return scenario, int(seed)


@dataclass(frozen=True)
class SplitSpec:
    """Either ``fractions`` (split -> fraction) or ``runs`` (split -> runs, or ``None`` for the rest)."""

    fractions: dict[str, float] = field(default_factory=dict)
    runs: dict[str, tuple[Run, ...] | None] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if bool(self.fractions) == bool(self.runs):
            raise SplitError("a split specification gives either fractions or runs, not both or neither")
        if self.fractions:
            if any(not np.isfinite(f) or f < 0 for f in self.fractions.values()):
                raise SplitError(f"split fractions must be >= 0: {self.fractions}")
            if abs(sum(self.fractions.values()) - 1.0) > 1e-6:
                raise SplitError(f"split fractions must sum to 1, got {sum(self.fractions.values()):g}")
        if sum(v is None for v in self.runs.values()) > 1:
            raise SplitError(f"only one split may take the remaining runs ({REST})")

    @property
    def names(self) -> list[str]:
        return list(self.fractions or self.runs)

    @classmethod
    def parse(cls, spec: str) -> SplitSpec:
        """Parse ``name=value,...`` where every value is a fraction, or every value lists runs."""
        items = [item.strip() for item in spec.split(",") if item.strip()]
        pairs = []
        for item in items:
            name, sep, value = item.partition("=")
            if not sep or not name.strip() or not value.strip():
                raise SplitError(f"--splits {spec!r}: {item!r} is not NAME=VALUE")
            pairs.append((name.strip(), value.strip()))
        names = [name for name, _ in pairs]
        if not pairs or len(set(names)) != len(names):
            raise SplitError(f"--splits {spec!r}: give each split once, e.g. train=0.8,val=0.2")
        try:
            return cls(fractions={name: float(value) for name, value in pairs})
        except ValueError as exc:
            if isinstance(exc, SplitError):
                raise SplitError(f"--splits {spec!r}: {exc}") from None
        runs = {name: None if value == REST else tuple(_parse_run(r, spec) for r in value.split("+"))
                for name, value in pairs}
        return cls(runs=runs)

    def to_dict(self) -> dict:
        if self.fractions:
            return {"fractions": dict(self.fractions)}
        return {"runs": {k: REST if v is None else [run_name(r) for r in v] for k, v in self.runs.items()}}

    def assign(self, runs: list[Run]) -> dict[Run, str]:
        """Split of every run in ``runs``; raises :class:`SplitError` for unlisted or unknown runs."""
        unique = sorted(set(runs))
        return self._assign_fractions(unique) if self.fractions else self._assign_runs(unique)

    def _assign_fractions(self, runs: list[Run]) -> dict[Run, str]:
        ordered = sorted(runs, key=lambda r: hashlib.sha256(run_name(r).encode()).hexdigest())
        ideal = np.array(list(self.fractions.values())) * len(ordered)
        counts = np.floor(ideal).astype(int)
        # Largest remainder; ties go to the split named first.
        for i in sorted(range(len(ideal)), key=lambda i: -(ideal[i] - counts[i]))[: len(ordered) - counts.sum()]:
            counts[i] += 1
        out, start = {}, 0
        for name, count in zip(self.fractions, counts, strict=True):
            for run in ordered[start:start + count]:
                out[run] = name
            start += count
            if count == 0:
                log.warning("split %r gets no run (%d runs, fractions %s)", name, len(ordered), self.fractions)
        return out

    def _assign_runs(self, runs: list[Run]) -> dict[Run, str]:
        out: dict[Run, str] = {}
        given = set(runs)
        for name, listed in self.runs.items():
            for run in listed or ():
                if run not in given:
                    raise SplitError(f"--splits names run {run_name(run)} ({name}), which is not among the "
                                     f"exported records ({', '.join(run_name(r) for r in runs)})")
                if run in out:
                    raise SplitError(f"--splits puts run {run_name(run)} in both {out[run]} and {name}")
                out[run] = name
        rest = [name for name, listed in self.runs.items() if listed is None]
        for run in runs:
            if run not in out:
                if not rest:
                    raise SplitError(f"run {run_name(run)} is in no split; list it or add a split NAME={REST}")
                out[run] = rest[0]
        return out
