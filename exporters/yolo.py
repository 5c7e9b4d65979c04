"""YOLO export in the Ultralytics layout: ``DIR/data.yaml``, ``DIR/images/<split>/``, ``DIR/labels/<split>/``.

Every (record, camera, frame) is one image, named like the COCO export; its label file has one line
per kept object, ``class cx cy w h`` normalised by the image size (6 decimals), and is empty for an
image without objects (a background image). Class indices are those of COCO-trained YOLO models (the
80-class list, 0-based: person 0, bicycle 1, car 2, motorcycle 3, bus 5, truck 7), so such a model is
scored on the export without remapping; ``names`` lists the first 8 (airplane 4 and train 6 stay empty).
YOLO has no ignore regions: objects the filter marks tiny or occluded are dropped (counted).
data.yaml has no ``path`` key, so Ultralytics resolves the split folders next to data.yaml; without a
``val`` split, ``val`` points at the training images (Ultralytics requires one; logged). YOLO files carry
no metadata, so ``DIR/images.csv`` gives each image's split, scenario, seed, condition, camera, frame and
timestamp.
"""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm

from exporters.base import CameraRows, Exporter, ExportOptions
from exporters.filters import KEPT, FilterSummary
from exporters.source import ExportSource, safe_name
from exporters.writing import link_or_copy
from pipeline.core.classes import COCO_CATEGORIES

log = logging.getLogger(__name__)

# The first 8 names of COCO-trained models' 80 classes; COCO ids 1-8 are contiguous, so index = id - 1.
COCO80_NAMES = ("person", "bicycle", "car", "motorcycle", "airplane", "bus", "train", "truck")
CLASS_INDEX = {cid: cid - 1 for cid in sorted(COCO_CATEGORIES)}
"""COCO category id -> YOLO class index."""
assert all(COCO80_NAMES[i] == COCO_CATEGORIES[cid][0] for cid, i in CLASS_INDEX.items())
IMAGES_CSV_COLUMNS = ("image", "split", "scenario", "seed", "condition", "camera", "frame", "timestamp_s")


def label_text(boxes: np.ndarray, classes: np.ndarray, width: int, height: int) -> str:
    """YOLO lines for (N, 4) x1, y1, x2, y2 pixel boxes and (N,) class indices."""
    cx = (boxes[:, 0] + boxes[:, 2]) / 2.0 / width
    cy = (boxes[:, 1] + boxes[:, 3]) / 2.0 / height
    w = (boxes[:, 2] - boxes[:, 0]) / width
    h = (boxes[:, 3] - boxes[:, 1]) / height
    rows = zip(classes, cx, cy, w, h, strict=True)
    return "".join(f"{c} {a:.6f} {b:.6f} {d:.6f} {e:.6f}\n" for c, a, b, d, e in rows)


class YoloExporter(Exporter):
    name = "yolo"
    needs_camera = True

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        summary = FilterSummary()
        counts = {s: 0 for s in source.split_names}
        linked = objects = 0
        rows = io.StringIO()
        table = csv.writer(rows, lineterminator="\n")
        table.writerow(IMAGES_CSV_COLUMNS)
        rows_of = {(id(s), c.name): CameraRows(s, c.name, options, coco_categories=True)
                   for s in source.records for c in s.info.cameras}
        for split in source.split_names:
            (tmp / "images" / safe_name(split)).mkdir(parents=True)
            (tmp / "labels" / safe_name(split)).mkdir(parents=True)
        for item in tqdm(source.frames(), total=source.n_frames(), desc="yolo", unit="frame",
                         disable=not options.progress):
            split = safe_name(item.source.split)
            for cam in item.source.info.cameras:
                stem = f"{item.source.stem}_{safe_name(cam.name)}_{item.frame:06d}"
                src = item.source.record.image_path(cam.name, "rgb", item.frame)
                linked += link_or_copy(src, tmp / "images" / split / f"{stem}.png", link=options.link_images)
                text = ""
                image = f"images/{split}/{stem}.png"
                info = item.source.info
                table.writerow([image, split, info.scenario, int(info.seed), info.condition, cam.name, item.frame,
                                repr(float(item.time_s))])
                labels = rows_of[(id(item.source), cam.name)]
                shown = labels.rows(item.frame, summary)
                keep = shown[labels.reasons[shown] == KEPT]
                if len(keep):
                    classes = np.array([CLASS_INDEX[int(c)] for c in labels.columns["category_id"][keep]], int)
                    text = label_text(labels.boxes[keep], classes, cam.width_px, cam.height_px)
                    objects += len(keep)
                (tmp / "labels" / split / f"{stem}.txt").write_text(text)
                counts[item.source.split] += 1
        data = {"train": f"images/{safe_name(source.split_names[0])}"}
        for split in source.split_names:
            data[split if split in ("train", "val", "test") else safe_name(split)] = f"images/{safe_name(split)}"
        if "val" not in data:
            log.info("no val split: data.yaml's val points at the training images (%s)", data["train"])
            data["val"] = data["train"]
        data["nc"] = len(COCO80_NAMES)
        data["names"] = dict(enumerate(COCO80_NAMES))
        (tmp / "data.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
        (tmp / "images.csv").write_text(rows.getvalue())
        images = sum(counts.values())
        return {"images": images, "images_by_split": counts, "images_linked": int(linked),
                "images_copied": images - int(linked), "objects_written": objects, "objects": summary.to_dict()}


EXPORTER = YoloExporter()
