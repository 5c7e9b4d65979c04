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

from exporters.filters import HIDDEN, IN_CYCLE, NO_CATEGORY, FilterSummary, ObjectFilter
from exporters.source import ExportSource, RecordSource
from exporters.splits import SplitSpec
from exporters.writing import atomic_dir, atomic_file, atomic_named_dir, write_json
from pipeline.core.classes import RIDER
from pipeline.core.record import RecordInfo

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


def _float_columns(labels: pd.DataFrame, columns: list[str]) -> np.ndarray:
    """(N, len(columns)) float64 of nullable label columns, NaN for nulls."""
    return labels[columns].astype("float64").to_numpy(dtype=np.float64, na_value=np.nan).reshape(-1, len(columns))


def cycle_boxes_2d(labels: pd.DataFrame, mode: BoxMode, width: int, height: int) -> np.ndarray:
    """(N, 4) float64 a ridden cycle's box without its rider in the chosen mode (tight; or amodal clipped to the
    ``width`` x ``height`` image), NaN on other rows and where its cycle does not show."""
    if mode is BoxMode.TIGHT:
        return _float_columns(labels, ["cycle_x1", "cycle_y1", "cycle_x2", "cycle_y2"])
    box = np.clip(_float_columns(labels, [f"cycle_amodal_{k}" for k in ("x1", "y1", "x2", "y2")]), 0.0,
                  [width, height, width, height])
    return np.where((box[:, 2:] > box[:, :2]).all(axis=1)[:, None], box, np.nan)


def boxes_2d(labels: pd.DataFrame, mode: BoxMode) -> np.ndarray:
    """(N, 4) float64 x1, y1, x2, y2 (pixels, x2 = last covered column + 1) of the chosen box; NaN where none."""
    cols = ["x1", "y1", "x2", "y2"] if mode is BoxMode.TIGHT else [
        "amodal_clip_x1", "amodal_clip_y1", "amodal_clip_x2", "amodal_clip_y2"]
    return labels[cols].astype("float64").to_numpy(dtype=np.float64, na_value=np.nan).reshape(-1, 4)


class CameraRows:
    """One camera's label rows of one record as NumPy columns, for the image exporters (COCO, KITTI, YOLO): the
    filter's verdicts and the chosen 2D boxes are computed once for the whole table, and :meth:`rows` gives a
    frame's rows. Per-row and per-frame pandas calls cost more than the exports' own work.

    Attributes:
        reasons: (N,) the filter's verdict per row (:data:`exporters.filters.REASONS`).
        boxes: (N, 4) the ``options.box`` 2D box per row (:func:`boxes_2d`; where riders have rows of their own, a
            ridden cycle's box without its rider, :func:`cycle_boxes_2d`).
        amodal: (N, 4) the unclipped amodal box, NaN where none (where riders have rows of their own, a ridden
            cycle's without its rider).
        ridden: (N,) bool the row is a bicycle or motorcycle boxed without its rider (``riders``; its ``cycle_*``
            boxes given).
        columns: the label columns by name: ints as stored, floats as float64 with NaN for nulls, ``cls``,
            ``model`` and ``person`` as str.
    """

    INTS = ("track_id", "category_id", "visible_px", "lidar_points")
    FLOATS = ("occlusion", "truncation", "distance_m", "sensor_x_m", "sensor_y_m", "sensor_z_m", "length_m",
              "width_m", "height_m", "sensor_yaw_rad")

    def __init__(self, source: RecordSource, camera: str, options: ExportOptions,
                 coco_categories: bool = False, riders: bool = True) -> None:
        """``coco_categories``: the format's categories are COCO's (COCO, YOLO), so the rows of a class without one
        (category_id 0: strollers) are ``no_category``, left out of :meth:`rows` and counted. ``riders`` False: the
        format's cycle box holds its rider (KITTI's Cyclist), so a rider's row is ``in_cycle``, left out and
        counted; otherwise (``riders`` True) a ridden cycle is boxed without its rider, as COCO's and MOT's annotators
        box a bicycle beside the person on it, and where only its rider shows it is ``hidden``."""
        labels = source.labels[source.labels["sensor"] == camera]  # sorted by (frame, track_id)
        self.where = f"{source.record.root}: camera {camera}"
        self.mode = options.box
        self.reasons = options.filter.classify(labels)
        if coco_categories:
            self.reasons[(labels["category_id"].to_numpy() == 0) & (self.reasons != HIDDEN)] = NO_CATEGORY
        if not riders:
            self.reasons[(labels["cls"].to_numpy() == RIDER) & (self.reasons != HIDDEN)] = IN_CYCLE
        self.boxes = boxes_2d(labels, options.box)
        self.amodal = _float_columns(labels, ["amodal_x1", "amodal_y1", "amodal_x2", "amodal_y2"])
        cycle_amodal = _float_columns(labels, [f"cycle_amodal_{k}" for k in ("x1", "y1", "x2", "y2")])
        self.ridden = np.isfinite(cycle_amodal).all(axis=1) & riders
        if riders and self.ridden.any():
            cam = next(c for c in source.info.cameras if c.name == camera)
            cycle = cycle_boxes_2d(labels, options.box, cam.width_px, cam.height_px)
            self.boxes[self.ridden], self.amodal[self.ridden] = cycle[self.ridden], cycle_amodal[self.ridden]
            self.reasons[self.ridden & ~np.isfinite(cycle).all(axis=1)] = HIDDEN
        self.columns: dict[str, np.ndarray] = {c: labels[c].to_numpy(dtype=object) for c in ("cls", "model", "person")}
        self.columns |= {c: labels[c].to_numpy() for c in self.INTS}
        self.columns |= {c: labels[c].astype("float64").to_numpy(na_value=np.nan) for c in self.FLOATS}
        frames = labels["frame"].to_numpy(dtype=np.int64)
        cuts = np.flatnonzero(np.diff(frames)) + 1
        starts, ends = np.concatenate([[0], cuts]), np.concatenate([cuts, [len(frames)]])
        self._span = {int(frames[lo]): (int(lo), int(hi)) for lo, hi in zip(starts, ends, strict=True) if hi > lo}

    def rows(self, frame: int, summary: FilterSummary) -> np.ndarray:
        """Indices of ``frame``'s rows that are neither hidden, without a category nor a rider left in its cycle (in
        track id order), after
        counting all its rows in ``summary``. Raises :class:`ExportError` for a shown object without a box: never
        dropped silently."""
        lo, hi = self._span.get(int(frame), (0, 0))
        summary.add(self.reasons[lo:hi], self.columns["cls"][lo:hi])
        rows = lo + np.flatnonzero(~np.isin(self.reasons[lo:hi], (HIDDEN, NO_CATEGORY, IN_CYCLE)))
        boxless = rows[~np.all(np.isfinite(self.boxes[rows]), axis=1)]
        if len(boxless):
            raise ExportError(f"{self.where}, frame {frame}, track {int(self.columns['track_id'][boxless[0]])}: "
                              f"visible object without a {self.mode.value} 2D box")
        return rows


def sensors_text(info: RecordInfo) -> str:
    """The sensors of a record by kind, for messages: ``cameras [front], LiDARs [top], radars []``."""
    return (f"cameras [{', '.join(c.name for c in info.cameras)}], LiDARs [{', '.join(x.name for x in info.lidars)}], "
            f"radars [{', '.join(r.name for r in info.radars)}]")


def check_contents(source: ExportSource, fmt: str, needs_camera: bool) -> None:
    """Refuse, naming the record, one that would add nothing to a ``fmt`` export: a record without frames, or
    without a camera where the format is made of camera images (``needs_camera``). Exporting it would write an
    export (or a part of one) with no images or no frames, and say nothing."""
    for src in source.records:
        root = src.record.root
        if not len(src.frames):
            raise ExportError(f"{root}: the record has no frames ({root / 'frames.parquet'} has no rows); a {fmt} "
                              "export of it would be empty")
        if needs_camera and not src.info.cameras:
            raise ExportError(f"{root}: the record has no camera ({sensors_text(src.info)}); a {fmt} export is "
                              "made of camera images, so it would hold none of this record's frames (render it with "
                              "a rig that has a camera, or export it as mcap or rosbag2)")


class Exporter(ABC):
    """One output format. Subclasses set :attr:`name` and implement :meth:`write`."""

    name: ClassVar[str]
    writes_file: ClassVar[bool] = False  # True: ``out`` is one file; False: a folder
    creates_own_dir: ClassVar[bool] = False  # True: write() gets a folder path that does not exist yet
    needs_camera: ClassVar[bool] = False
    """True for formats made of camera images: a record without a camera is refused (:func:`check_contents`).
    Every format refuses a record without frames."""

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
        check_contents(source, self.name, self.needs_camera)
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


for _name in ("coco", "kitti", "yolo", "mcap", "rosbag2", "nuscenes"):
    register_format(_name, f"exporters.{_name}")
register_format("mot", "exporters.mot")
register_format("kitti-tracking", "exporters.kitti_tracking")
register_format("cityscapes", "exporters.cityscapes")
register_format("kitti-depth", "exporters.kitti_depth")


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
