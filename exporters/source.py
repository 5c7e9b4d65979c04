"""The records of one export, opened, checked, ordered and assigned to splits.

Records are read only through :mod:`pipeline.core.record`. They are ordered by (scenario, seed,
condition), frames by number, so the output does not depend on the order of ``--dataset`` arguments.
Two records of the same (scenario, seed, condition) are an error. Every image keeps its scenario, seed,
condition, frame and timestamp (:class:`FrameItem`).
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property
from itertools import pairwise
from pathlib import Path

import pandas as pd

from exporters.splits import Run, SplitSpec, run_name
from pipeline.core.record import DatasetRecord, RecordError

DEFAULT_SPLIT = "train"


def safe_name(text: str) -> str:
    """``text`` with every character outside [A-Za-z0-9._-] replaced by '_' (file names, topic names)."""
    return re.sub(r"[^A-Za-z0-9._-]", "_", text)


class RecordSource:
    """One opened record and its split."""

    def __init__(self, record: DatasetRecord, split: str) -> None:
        self.record = record
        self.split = split
        self.info = record.info

    @property
    def run(self) -> Run:
        return self.info.scenario, int(self.info.seed)

    @property
    def key(self) -> tuple[str, int, str]:
        return self.info.scenario, int(self.info.seed), self.info.condition

    @property
    def stem(self) -> str:
        """File-name stem unique to this record: ``<scenario>_s<seed>_<condition>``."""
        return safe_name(f"{self.info.scenario}_s{self.info.seed}_{self.info.condition}")

    @cached_property
    def frames(self) -> pd.DataFrame:
        return self.record.frames.sort_values("frame", kind="stable").reset_index(drop=True)

    @cached_property
    def _hold_ns(self) -> dict[int, int]:
        times = [round(float(t) * 1e9) for t in self.frames["time_s"]]
        frames = [int(f) for f in self.frames["frame"]]
        if len(times) < 2:
            rate = float(self.info.frame_rate_hz)
            return dict.fromkeys(frames, round(1e9 / rate) if rate > 0 else 0)
        gaps = [b - a for a, b in pairwise(times)]
        return dict(zip(frames, [*gaps, gaps[-1]], strict=True))

    def hold_ns(self, frame: int) -> int:
        """How long ``frame``'s world state holds, in simulation nanoseconds: until the record's next frame (the
        last frame as long as the one before it; a lone frame 1 / ``frame_rate_hz``). The lifetime of the 3D
        boxes logged with it, so they neither vanish between frames nor linger past the next ones."""
        return self._hold_ns[int(frame)]

    @cached_property
    def labels(self) -> pd.DataFrame:
        return self.record.labels.sort_values(["frame", "sensor", "track_id"], kind="stable").reset_index(drop=True)

    @cached_property
    def meta_text(self) -> str | None:
        """The record's meta.json, verbatim, or None when it has none."""
        path = self.record.root / "meta.json"
        return path.read_text() if path.is_file() else None

    def attributes(self, frame: int, time_s: float) -> dict:
        """What every exported image carries about its origin."""
        return {"scenario": self.info.scenario, "seed": int(self.info.seed), "condition": self.info.condition,
                "frame": int(frame), "timestamp_s": float(time_s)}


@dataclass(frozen=True)
class FrameItem:
    """One frame of one record."""

    source: RecordSource
    frame: int
    time_s: float
    row: tuple  # the frames.parquet row as a named tuple (ego pose: ego_x_m, ..., ego_yaw_rad)


class ExportSource:
    """The records of an export; fails on missing records, other schema versions and duplicates."""

    def __init__(self, roots: Sequence[Path], splits: SplitSpec | None = None) -> None:
        if not roots:
            raise RecordError("no dataset record given (pass --dataset DIR at least once)")
        records = []
        for root in roots:
            root = Path(root)
            if not root.exists():
                raise RecordError(f"{root}: dataset record not found (no such folder)")
            records.append(DatasetRecord(root))
        records.sort(key=lambda r: (r.info.scenario, int(r.info.seed), r.info.condition))
        keys = [(r.info.scenario, int(r.info.seed), r.info.condition) for r in records]
        for a, b, ka, kb in zip(records, records[1:], keys, keys[1:], strict=False):
            if ka == kb:
                raise RecordError(f"{a.root} and {b.root} are the same run and condition {ka}; export each once")
        self.splits = splits
        runs = [(r.info.scenario, int(r.info.seed)) for r in records]
        self.assignment: dict[Run, str] = splits.assign(runs) if splits else dict.fromkeys(runs, DEFAULT_SPLIT)
        self.records = [RecordSource(r, self.assignment[run]) for r, run in zip(records, runs, strict=True)]

    @property
    def split_names(self) -> list[str]:
        return self.splits.names if self.splits else [DEFAULT_SPLIT]

    def frames(self, split: str | None = None) -> Iterator[FrameItem]:
        """Every frame of every record (of ``split`` when given), in export order."""
        for src in self.records:
            if split is not None and src.split != split:
                continue
            for row in src.frames.itertuples(index=False):
                yield FrameItem(src, int(row.frame), float(row.time_s), row)

    def n_frames(self, split: str | None = None) -> int:
        return sum(len(s.frames) for s in self.records if split is None or s.split == split)

    def describe(self) -> dict:
        """Records and the run -> split assignment, for ``export.json`` / MCAP metadata."""
        return {
            "records": [{"scenario": s.info.scenario, "seed": int(s.info.seed), "condition": s.info.condition,
                         "split": s.split, "frames": len(s.frames), "schema_version": s.info.schema_version}
                        for s in self.records],
            "splits": {"spec": None if self.splits is None else self.splits.to_dict(),
                       "runs": {run_name(r): s for r, s in sorted(self.assignment.items())}},
        }
