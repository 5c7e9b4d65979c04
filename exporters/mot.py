"""MOTChallenge export: one sequence folder per record, ``DIR/<split>/<seq>/{seqinfo.ini, img1/, gt/gt.txt}``.

A sequence is one record seen by one camera (``--camera``, default the record's first), named
``<scenario>_s<seed>_<condition>_<camera>``; its frames are numbered 1 .. n in the record's order (img1/000001.png,
...). ``DIR/seqmaps/<split>.txt`` lists each split's sequences (TrackEval's seqmap: a ``name`` header, one sequence a
line) and ``DIR/mapping.txt`` gives, per exported frame, ``split sequence mot_frame scenario seed condition frame
timestamp_s``.

gt.txt, one object a line (MOT16/17 ground truth): ``frame, id, bb_left, bb_top, bb_width, bb_height, considered,
class, visibility``:

- ``id`` is the record's track id (stable over the run);
- the box is the ``--box`` 2D box in our continuous pixel coordinates (x2 = last covered column + 1), written as
  COCO's ``x, y, w, h``: the same numbers as the COCO export's ``bbox`` (MOTChallenge's own files count pixels from
  1; IoU-based evaluation does not depend on it);
- ``class`` by :data:`MOT_CLASS` (MOT has no van, truck or bus class: they are ``car``, 3);
- ``visibility`` = 1 - our occlusion fraction (visible / unoccluded pixels);
- objects the filter marks tiny or occluded are written with ``considered`` 0 and class 8 (``distractor``), so that
  MOTChallenge evaluation (TrackEval) neither counts them as missed nor a tracker's box on them as a false positive,
  as COCO's crowd regions and KITTI's DontCare; hidden objects are not written.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from exporters.base import CameraRows, Exporter, ExportError, ExportOptions
from exporters.filters import KEPT, FilterSummary
from exporters.source import ExportSource, RecordSource, safe_name
from exporters.writing import link_or_copy
from pipeline.core.record import CameraInfo

log = logging.getLogger(__name__)

MOT_CLASS = {"pedestrian": 1, "rider": 2, "car": 3, "van": 3, "truck": 3, "bus": 3, "bicycle": 4, "motorcycle": 5,
             "stroller": 6}
"""Our class -> MOTChallenge class id (1 pedestrian, 2 person on vehicle: a rider, 3 car, 4 bicycle, 5 motorbike,
6 non-motorized vehicle: a stroller; MOT16's classes)."""
IGNORE_CLASS = 8
"""MOT's ``distractor`` class: what tiny and occluded objects are written as (with ``considered`` 0)."""


def camera_of(src: RecordSource, options: ExportOptions) -> CameraInfo:
    """The camera a record's sequence is taken from; :class:`ExportError` naming the record when it has none."""
    info, root = src.info, src.record.root
    if not info.cameras:
        raise ExportError(f"{root}: the record has no camera; a tracking sequence is one camera's images")
    try:
        return info.camera(options.camera) if options.camera else info.cameras[0]
    except KeyError as exc:
        raise ExportError(f"{root}: {exc.args[0]}") from None


def check_classes(src: RecordSource, known: dict[str, Any], fmt: str) -> None:
    unknown = sorted(set(src.labels["cls"]) - set(known))
    if unknown:
        raise ExportError(f"{src.record.root}: classes {unknown} have no {fmt} class (known: {sorted(known)})")


def gt_lines(table: CameraRows, rows: np.ndarray, mot_frame: int) -> str:
    """gt.txt lines of one frame's shown rows (``CameraRows.rows``)."""
    col = table.columns
    kept = table.reasons[rows] == KEPT
    classes = np.array([MOT_CLASS[c] for c in col["cls"][rows]], np.int64)
    classes[~kept] = IGNORE_CLASS
    visibility = np.clip(1.0 - np.nan_to_num(col["occlusion"][rows], nan=0.0), 0.0, 1.0)
    boxes = table.boxes[rows]
    return "".join(
        f"{mot_frame},{tid},{x1:.2f},{y1:.2f},{x2 - x1:.2f},{y2 - y1:.2f},{int(k)},{c},{v:.4f}\n"
        for tid, (x1, y1, x2, y2), k, c, v in zip(col["track_id"][rows], boxes, kept, classes, visibility, strict=True))


def seqinfo(name: str, cam: CameraInfo, length: int, rate_hz: float) -> str:
    return (f"[Sequence]\nname={name}\nimDir=img1\nframeRate={rate_hz:g}\nseqLength={length}\n"
            f"imWidth={cam.width_px}\nimHeight={cam.height_px}\nimExt=.png\n")


class MotExporter(Exporter):
    name = "mot"

    def check(self, source: ExportSource, options: ExportOptions) -> None:
        for src in source.records:
            camera_of(src, options)
            check_classes(src, MOT_CLASS, "MOTChallenge")

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        summary = FilterSummary()
        seqmaps: dict[str, list[str]] = {s: [] for s in source.split_names}
        mapping, linked, frames = [], 0, 0
        progress = tqdm(total=source.n_frames(), desc="mot", unit="frame", disable=not options.progress)
        for src in source.records:
            cam = camera_of(src, options)
            table = CameraRows(src, cam.name, options)
            split = safe_name(src.split)
            seq = f"{src.stem}_{safe_name(cam.name)}"
            seq_dir = tmp / split / seq
            (seq_dir / "gt").mkdir(parents=True)
            (seq_dir / "img1").mkdir()
            lines = []
            for index, row in enumerate(src.frames.itertuples(index=False), start=1):
                frame = int(row.frame)
                image = src.record.image_path(cam.name, "rgb", frame)
                linked += link_or_copy(image, seq_dir / "img1" / f"{index:06d}.png", link=options.link_images)
                lines.append(gt_lines(table, table.rows(frame, summary), index))
                mapping.append(f"{split} {seq} {index} {safe_name(src.info.scenario)} {int(src.info.seed)} "
                               f"{safe_name(src.info.condition)} {frame} {float(row.time_s):.6f}\n")
                progress.update()
            (seq_dir / "gt" / "gt.txt").write_text("".join(lines))
            (seq_dir / "seqinfo.ini").write_text(seqinfo(seq, cam, len(src.frames), float(src.info.frame_rate_hz)))
            seqmaps[src.split].append(seq)
            frames += len(src.frames)
        progress.close()
        (tmp / "seqmaps").mkdir()
        for split, seqs in seqmaps.items():
            (tmp / "seqmaps" / f"{safe_name(split)}.txt").write_text("name\n" + "".join(f"{s}\n" for s in seqs))
        (tmp / "mapping.txt").write_text("".join(mapping))
        return {"frames": frames, "sequences": {s: len(v) for s, v in seqmaps.items()}, "images_linked": int(linked),
                "images_copied": frames - int(linked), "classes": dict(MOT_CLASS), "ignore_class": IGNORE_CLASS,
                "objects": summary.to_dict()}


EXPORTER = MotExporter()
