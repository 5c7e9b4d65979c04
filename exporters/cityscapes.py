"""Cityscapes export (semantic and instance segmentation): the ``gtFine`` and ``leftImg8bit`` layout.

Per exported frame, with ``<name>`` = ``<city>_000000_<frame>`` (the record's frame number, 6 digits):

- ``leftImg8bit/<split>/<city>/<name>_leftImg8bit.png``: the camera image (the record's PNG, linked or copied);
- ``gtFine/<split>/<city>/<name>_gtFine_labelIds.png``: uint8 Cityscapes label id per pixel
  (:data:`exporters.cityscapes_labels.CITYSCAPES_OF`);
- ``..._gtFine_instanceIds.png``: uint16, Cityscapes' encoding: the label id where the label has no instances (or the
  pixel shows no object), ``id * 1000 + n`` on the pixels of an object of a label with instances (person, car, truck,
  bus, motorcycle, bicycle), n = 0, 1, ... per label and image in track id order (Cityscapes numbers an image's
  instances of a label from 0);
- ``..._gtFine_color.png``: RGBA, each label's colour (alpha 255), as Cityscapes' own color images.

A "city" is a record: ``<scenario>-s<seed>-<condition>`` with every character outside [A-Za-z0-9-] replaced by '-',
since Cityscapes' file names are ``<city>_<sequence>_<frame>_<type>[_<type2>].<ext>`` split at '_' (cityscapesscripts'
``getCsFileInfo``). One camera per record (``--camera``, default the first); the sequence is always 000000.
``DIR/mapping.txt`` gives per image ``split name scenario seed condition frame timestamp_s`` and
``DIR/instances.txt`` per instance ``split name instance_id track_id class`` (our class), so every Cityscapes
instance leads back to the record's track.
"""

from __future__ import annotations

import logging
import re
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from exporters.base import Exporter, ExportError, ExportOptions
from exporters.cityscapes_labels import CITYSCAPES_OF, COLORS, HAS_INSTANCES, KNOWN_SEMANTIC, LABEL_ID, LABELS
from exporters.mot import camera_of
from exporters.source import ExportSource, RecordSource, safe_name
from exporters.writing import link_or_copy
from pipeline.core.classes import SemanticClass
from pipeline.core.png import write_png
from pipeline.core.record import camera_path

log = logging.getLogger(__name__)

SEQUENCE = "000000"
MAX_INSTANCES = 1000
"""Cityscapes' encoding holds instance numbers 0 .. 999 per label and image."""


def city_of(src: RecordSource) -> str:
    """The record's Cityscapes city: ``<scenario>-s<seed>-<condition>``, only [A-Za-z0-9-] (no '_': it separates the
    parts of a Cityscapes file name)."""
    return re.sub(r"[^A-Za-z0-9-]", "-", f"{src.info.scenario}-s{int(src.info.seed)}-{src.info.condition}")


def image_name(city: str, frame: int) -> str:
    return f"{city}_{SEQUENCE}_{int(frame):06d}"


def encode_frame(semantic: np.ndarray, instance: np.ndarray, where: str
                 ) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, int]]]:
    """One frame's label ids ((H, W) uint8), Cityscapes instance ids ((H, W) uint16) and instances (instance id,
    track id, our semantic value) from the record's semantic ((H, W) uint8) and instance ((H, W) int32 track id)
    images. An unmapped semantic value or more than :data:`MAX_INSTANCES` objects of a label: :class:`ExportError`
    naming ``where``."""
    unknown = ~KNOWN_SEMANTIC[semantic]
    if unknown.any():
        values = sorted(int(v) for v in np.unique(semantic[unknown]))
        raise ExportError(f"{where}: semantic value(s) {values} are no SemanticClass with a Cityscapes label (known: "
                          f"{sorted(c.value for c in CITYSCAPES_OF)})")
    label_ids = LABEL_ID[semantic]
    instance_ids = label_ids.astype(np.uint16)
    objects = HAS_INSTANCES[label_ids] & (instance > 0)
    instances: list[tuple[int, int, int]] = []
    if objects.any():
        # one key per (label, track, our class); sorted, so each label's tracks come in track id order
        keys = (label_ids[objects].astype(np.int64) << 40) | (instance[objects].astype(np.int64) << 8) | semantic[
            objects]
        unique, inverse = np.unique(keys, return_inverse=True)
        label, track, ours = unique >> 40, (unique >> 8) & 0xFFFFFFFF, unique & 0xFF
        if np.any(np.diff(track)[np.diff(label) == 0] == 0):
            raise ExportError(f"{where}: a track's pixels have two semantic classes of one Cityscapes label")
        number = np.arange(len(unique)) - np.searchsorted(label, label)  # rank within the label
        if number.max() >= MAX_INSTANCES:
            raise ExportError(f"{where}: more than {MAX_INSTANCES} objects of one Cityscapes label in one image; "
                              "Cityscapes' instance ids (label id x 1000 + n) hold 1000")
        codes = label * 1000 + number
        instance_ids[objects] = codes[inverse.reshape(-1)]
        instances = [(int(c), int(t), int(o)) for c, t, o in zip(codes, track, ours, strict=True)]
    return label_ids, instance_ids, instances


# Each label id's RGBA colour (alpha 255) as one 32-bit word: one gather per pixel instead of three.
_RGBA_WORDS = np.concatenate([COLORS.astype(np.uint8), np.full((len(COLORS), 1), 255, np.uint8)], axis=1).view(
    np.uint32).reshape(-1)


def color_image(label_ids: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8 RGBA: each pixel's label colour, alpha 255."""
    return _RGBA_WORDS[label_ids].view(np.uint8).reshape(*label_ids.shape, 4)


WRITE_THREADS = 2
WAITING_FRAMES = 4  # frames whose images may wait to be written


@dataclass
class _Counts:
    """What the export wrote, summed over its frames (for export.json, mapping.txt and instances.txt)."""

    cities: dict[str, list[str]]
    pixels: np.ndarray = field(default_factory=lambda: np.zeros(256, np.int64))
    mapping: list[str] = field(default_factory=list)
    instance_lines: list[str] = field(default_factory=list)
    linked: int = 0
    frames: int = 0
    n_instances: int = 0


class CityscapesExporter(Exporter):
    name = "cityscapes"
    needs_camera = True

    def check(self, source: ExportSource, options: ExportOptions) -> None:
        cities: dict[str, Path] = {}
        for src in source.records:
            camera_of(src, options)
            city = city_of(src)
            if city in cities:
                raise ExportError(f"{cities[city]} and {src.record.root} are both Cityscapes city {city!r} (names "
                                  "keep only letters, digits and '-'); rename a scenario or condition")
            cities[city] = src.record.root

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        cities: dict[str, list[str]] = {s: [] for s in source.split_names}
        progress = tqdm(total=source.n_frames(), desc="cityscapes", unit="frame", disable=not options.progress)
        # PNG deflate releases the GIL: the images of one frame are written on threads while the next is read and
        # mapped (each file's bytes are its own, so the order of the writes changes nothing). At most a few frames
        # wait, and an error of any write ends the export.
        pool = ThreadPoolExecutor(max_workers=WRITE_THREADS, thread_name_prefix="cityscapes")
        pending: deque = deque()
        counts = _Counts(cities)
        try:
            self._frames(source, tmp, options, pool, pending, progress, counts)
            while pending:
                pending.popleft().result()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
            progress.close()
        pixels, mapping, instance_lines = counts.pixels, counts.mapping, counts.instance_lines
        linked, frames, n_instances = counts.linked, counts.frames, counts.n_instances
        (tmp / "mapping.txt").write_text("".join(mapping))
        (tmp / "instances.txt").write_text("".join(instance_lines))
        return {"frames": frames, "cities": cities, "images_linked": int(linked), "images_copied": frames - int(linked),
                "instances": n_instances, "classes": {c.name.lower(): n for c, n in CITYSCAPES_OF.items()},
                "pixels_by_label": {label.name: int(pixels[label.id]) for label in LABELS if pixels[label.id]}}

    @staticmethod
    def _frames(source: ExportSource, tmp: Path, options: ExportOptions, pool: ThreadPoolExecutor, pending: deque,
                progress, counts: _Counts) -> None:
        cities = counts.cities
        for src in source.records:
            cam, city, split = camera_of(src, options), city_of(src), safe_name(src.split)
            gt_dir, image_dir = tmp / "gtFine" / split / city, tmp / "leftImg8bit" / split / city
            gt_dir.mkdir(parents=True)
            for row in src.frames.itertuples(index=False):
                frame = int(row.frame)
                name = image_name(city, frame)
                semantic = camera_path(src.record.root, cam.name, "semantic", frame)
                where = f"{semantic} (frame {frame}, camera {cam.name})"
                label_ids, instance_ids, instances = encode_frame(
                    src.record.semantic(cam.name, frame), src.record.instance(cam.name, frame), where)
                pending.extend([
                    pool.submit(write_png, gt_dir / f"{name}_gtFine_labelIds.png", label_ids),
                    pool.submit(write_png, gt_dir / f"{name}_gtFine_instanceIds.png", instance_ids),
                    pool.submit(write_png, gt_dir / f"{name}_gtFine_color.png", color_image(label_ids), "sub")])
                while len(pending) > 3 * WAITING_FRAMES:
                    pending.popleft().result()
                counts.linked += link_or_copy(src.record.image_path(cam.name, "rgb", frame),
                                              image_dir / f"{name}_leftImg8bit.png", link=options.link_images)
                counts.pixels += np.bincount(label_ids.reshape(-1), minlength=256)
                counts.instance_lines += [f"{split} {name} {code} {track} {SemanticClass(ours).name.lower()}\n"
                                          for code, track, ours in instances]
                counts.n_instances += len(instances)
                counts.mapping.append(f"{split} {name} {safe_name(src.info.scenario)} {int(src.info.seed)} "
                                      f"{safe_name(src.info.condition)} {frame} {float(row.time_s):.6f}\n")
                counts.frames += 1
                progress.update()
            cities[src.split].append(city)


EXPORTER = CityscapesExporter()
