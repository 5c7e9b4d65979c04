"""Export options, the exporter base class and the registry of formats by name.

An :class:`Exporter` subclass writes one format into a temporary location (:meth:`Exporter.write`);
the base class opens and checks the records first (a missing record or another schema version fails
before anything is written), writes atomically, and adds ``export.json`` (options, records, the run ->
split assignment, counts) and, when given, ``meta.json`` to folder outputs. File outputs (MCAP) embed
the same description themselves.
"""

from __future__ import annotations

import contextlib
import enum
import importlib
import logging
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd

from exporters.filters import ObjectFilter
from exporters.io import atomic_dir, atomic_file, atomic_named_dir, write_json
from exporters.source import ExportSource
from exporters.splits import SplitSpec

log = logging.getLogger(__name__)


class ExportError(ValueError):
    """The records cannot be exported in the asked format; the message says why and what would work."""


class BoxMode(str, enum.Enum):
    """Which 2D box an annotation carries."""

    TIGHT = "tight"
    """Bounding box of the visible pixels (the instance mask): what a detector can see. Default."""
    AMODAL = "amodal"
    """The object's full projection (occluded parts included), clipped to the image."""


class Compression(str, enum.Enum):
    """Chunk compression of MCAP output (rosbag2: zstd or none)."""

    ZSTD = "zstd"
    LZ4 = "lz4"
    NONE = "none"


@dataclass(frozen=True)
class ExportOptions:
    """Everything an export depends on besides its input records.

    Attributes:
        box: 2D box mode of COCO/KITTI/YOLO annotations and of MCAP/rosbag2 image boxes.
        splits: run -> split assignment rule; ``None`` puts everything in one split.
        filter: thresholds deciding which objects are annotations and which ignore regions.
        compression: MCAP / rosbag2 chunk compression.
        camera: the camera exported to KITTI (default: the first of each record).
        lidar: the LiDAR exported to KITTI's velodyne (default: the first of each record).
        link_images: hard-link images where possible (copy otherwise); False always copies.
        progress: show a progress bar.
    """

    box: BoxMode = BoxMode.TIGHT
    splits: SplitSpec | None = None
    filter: ObjectFilter = field(default_factory=ObjectFilter)
    compression: Compression = Compression.ZSTD
    camera: str | None = None
    lidar: str | None = None
    link_images: bool = True
    progress: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "box": self.box.value, "splits": None if self.splits is None else self.splits.to_dict(),
            "filter": self.filter.to_dict(), "compression": self.compression.value, "camera": self.camera,
            "lidar": self.lidar,
        }


def boxes_2d(labels: pd.DataFrame, mode: BoxMode) -> np.ndarray:
    """(N, 4) float64 x1, y1, x2, y2 (pixels, x2 = last covered column + 1) of the chosen box; NaN where none."""
    cols = ["x1", "y1", "x2", "y2"] if mode is BoxMode.TIGHT else [
        "amodal_clip_x1", "amodal_clip_y1", "amodal_clip_x2", "amodal_clip_y2"]
    return labels[cols].astype("float64").to_numpy(dtype=np.float64, na_value=np.nan).reshape(-1, 4)


class Exporter(ABC):
    """One output format. Subclasses set :attr:`name` and implement :meth:`write`."""

    name: ClassVar[str]
    writes_file: ClassVar[bool] = False  # True: ``out`` is one file; False: a folder
    creates_own_dir: ClassVar[bool] = False  # True: write() gets a folder path that does not exist yet

    def check(self, source: ExportSource, options: ExportOptions) -> None:  # noqa: B027 - optional hook
        """Raise :class:`ExportError` before writing when the records do not suit the format."""

    def companions(self, source: ExportSource, out: Path) -> dict[Path, str]:
        """Small text files that go next to a file export (``writes_file``), written and moved into place
        with it (e.g. an MCAP's Foxglove layout): path -> content. None by default."""
        return {}

    @abstractmethod
    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        """Write the export into ``tmp`` (a folder, or the file path for file formats); return counts."""

    def export(self, datasets: Sequence[Path], out: Path, options: ExportOptions | None = None,
               meta: dict[str, Any] | None = None) -> dict[str, Any]:
        """Export the records ``datasets`` to ``out`` atomically; returns the export description with counts."""
        options = options or ExportOptions()
        source = ExportSource(datasets, options.splits)
        self.check(source, options)
        description = {"format": self.name, "options": options.to_dict(), **source.describe()}
        atomic = atomic_file if self.writes_file else atomic_named_dir if self.creates_own_dir else atomic_dir
        with contextlib.ExitStack() as companions:
            # Entered first, so they move into place after ``out`` and are removed if anything fails.
            for path, text in (self.companions(source, Path(out)) if self.writes_file else {}).items():
                companions.enter_context(atomic_file(path)).write_text(text)
            with atomic(Path(out)) as tmp:
                counts = self.write(source, tmp, options, description, meta)
                description = {**description, "counts": counts}
                if not self.writes_file:
                    write_json(tmp / "export.json", description)
                    if meta is not None:
                        write_json(tmp / "meta.json", meta)
        return description


# Formats by name -> module defining ``EXPORTER``; modules load on first use (mcap, rosbags are heavy).
_FORMATS: dict[str, str] = {}


def register_format(name: str, module: str) -> None:
    """Add a format; a name registered twice is an error."""
    if name in _FORMATS:
        raise KeyError(f"export format {name!r} is already registered (by {_FORMATS[name]})")
    _FORMATS[name] = module


for _name in ("coco", "kitti", "yolo", "mcap", "rosbag2"):
    register_format(_name, f"exporters.{_name}")


def formats() -> list[str]:
    return list(_FORMATS)


def get_exporter(name: str) -> Exporter:
    """The exporter of format ``name``; unknown names fail listing the known ones."""
    if name not in _FORMATS:
        raise KeyError(f"unknown export format {name!r}; known formats: {', '.join(_FORMATS)}")
    exporter = importlib.import_module(_FORMATS[name]).EXPORTER
    if exporter.name != name:
        raise KeyError(f"module {_FORMATS[name]} exports format {exporter.name!r}, registered as {name!r}")
    return exporter
