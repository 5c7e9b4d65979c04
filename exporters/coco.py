"""COCO instances export: ``DIR/annotations.json`` (``annotations_<split>.json`` with splits), ``DIR/images/``.

Every (record, camera, frame) is one image, its RGB PNG hard-linked (or copied) as
``images/<scenario>_s<seed>_<condition>_<camera>_<frame:06d>.png``. Image and annotation ids start at
1 and are unique across split files. Category ids are COCO's own (car 3, truck 8, ...; van counts as car
and keeps ``subclass`` "van").

Per annotation: ``bbox`` [x, y, w, h] of the tight box (``--box amodal``: the amodal box clipped to
the image), ``area`` = visible mask area (pixels), ``segmentation`` = RLE of the visible mask taken
from the instance image (pycocotools), ``iscrowd``; extra fields ``track_id``, ``subclass``,
``occlusion`` and ``truncation`` (fractions), ``distance_m``, ``bbox_amodal`` (unclipped [x, y, w, h]),
``box3d_camera`` (``center_m`` x, y, z and ``size_m`` length, width, height in the camera's OpenCV
frame; ``rotation_y_rad``: KITTI's rotation about the camera's +y), ``lidar_points``, ``visible_px``,
``camera``. Objects the filter marks tiny or occluded are crowd regions (``iscrowd`` 1,
``ignore_reason``): COCO evaluation neither rewards nor punishes detections on them.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pycocotools import mask as mask_utils
from tqdm import tqdm

from exporters.base import BoxMode, Exporter, ExportError, ExportOptions, boxes_2d
from exporters.filters import HIDDEN, KEPT, FilterSummary
from exporters.io import link_or_copy, write_json
from exporters.source import ExportSource, FrameItem, safe_name
from pipeline.core.classes import COCO_CATEGORIES

log = logging.getLogger(__name__)


def _r(value: float, digits: int = 4) -> float:
    return round(float(value), digits)


def xywh(box: np.ndarray) -> list[float]:
    """[x, y, w, h] of a continuous (x1, y1, x2, y2) box."""
    return [_r(box[0]), _r(box[1]), _r(box[2] - box[0]), _r(box[3] - box[1])]


def categories() -> list[dict[str, Any]]:
    return [{"id": cid, "name": name, "supercategory": sup} for cid, (name, sup) in sorted(COCO_CATEGORIES.items())]


def rle_of(mask: np.ndarray) -> dict[str, Any]:
    """COCO RLE ({"size": [H, W], "counts": str}) of an (H, W) bool mask."""
    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(s) for s in rle["size"]], "counts": rle["counts"].decode("ascii")}


class CocoExporter(Exporter):
    name = "coco"

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        images: dict[str, list] = {s: [] for s in source.split_names}
        annotations: dict[str, list] = {s: [] for s in source.split_names}
        summary = FilterSummary()
        linked = copied = 0
        labels_of = {(id(s), c.name): s.sensor_labels(c.name) for s in source.records for c in s.info.cameras}
        for item in tqdm(source.frames(), total=source.n_frames(), desc="coco", unit="frame",
                         disable=not options.progress):
            for cam in item.source.info.cameras:
                file_name = f"{item.source.stem}_{safe_name(cam.name)}_{item.frame:06d}.png"
                src = item.source.record.image_path(cam.name, "rgb", item.frame)
                if link_or_copy(src, tmp / "images" / file_name, link=options.link_images):
                    linked += 1
                else:
                    copied += 1
                image_id = sum(len(v) for v in images.values()) + 1
                images[item.source.split].append({
                    "id": image_id, "file_name": file_name, "width": int(cam.width_px), "height": int(cam.height_px),
                    "camera": cam.name, **item.source.attributes(item.frame, item.time_s),
                })
                labels = labels_of[(id(item.source), cam.name)].get(item.frame)
                if labels is None or labels.empty:
                    continue
                first_id = sum(len(v) for v in annotations.values()) + 1
                anns = self._annotations(item, cam.name, labels, image_id, first_id, options, summary)
                annotations[item.source.split] += anns
        for split in source.split_names:
            name = "annotations.json" if source.splits is None else f"annotations_{safe_name(split)}.json"
            coco = {"info": {"description": "roadsynth export", "version": "1", "contributor": "roadsynth",
                             "url": "", "split": split},
                    "licenses": [], "images": images[split], "annotations": annotations[split],
                    "categories": categories()}
            write_json(tmp / name, coco, indent=None)
        return {"images": sum(len(v) for v in images.values()),
                "annotations": sum(len(v) for v in annotations.values()),
                "images_linked": linked, "images_copied": copied, "objects": summary.to_dict()}

    def _annotations(self, item: FrameItem, camera: str, labels: pd.DataFrame, image_id: int, first_id: int,
                     options: ExportOptions, summary: FilterSummary) -> list[dict[str, Any]]:
        reasons = options.filter.classify(labels)
        summary.add(reasons, labels["cls"].to_numpy())
        rows = np.flatnonzero(reasons != HIDDEN)
        if not len(rows):
            return []
        instance = item.source.record.instance(camera, item.frame)
        boxes = boxes_2d(labels, options.box)
        amodal = labels[["amodal_x1", "amodal_y1", "amodal_x2", "amodal_y2"]].astype("float64").to_numpy(
            na_value=np.nan)
        out = []
        for i in rows:
            row = labels.iloc[i]
            if not np.all(np.isfinite(boxes[i])):
                raise ExportError(f"{item.source.record.root}: frame {item.frame}, camera {camera}, track "
                                  f"{row.track_id}: visible object without a {options.box.value} 2D box")
            mask = instance == int(row.track_id)
            rle = rle_of(mask)
            ann = {
                "id": first_id + len(out), "image_id": image_id, "category_id": int(row.category_id),
                "bbox": xywh(boxes[i]), "area": float(mask_utils.area(rle)), "segmentation": rle,
                "iscrowd": 0 if reasons[i] == KEPT else 1,
                "track_id": int(row.track_id), "subclass": str(row.cls), "camera": camera,
                "occlusion": _r(row.occlusion, 6), "truncation": _r(row.truncation, 6),
                "distance_m": _r(row.distance_m), "visible_px": int(row.visible_px),
                "bbox_amodal": xywh(amodal[i]) if np.all(np.isfinite(amodal[i])) else None,
                "box3d_camera": {"center_m": [_r(row.sensor_x_m), _r(row.sensor_y_m), _r(row.sensor_z_m)],
                                 "size_m": [_r(row.length_m), _r(row.width_m), _r(row.height_m)],
                                 "rotation_y_rad": _r(row.sensor_yaw_rad, 6)},
                "lidar_points": int(row.lidar_points),
            }
            if reasons[i] != KEPT:
                ann["ignore_reason"] = str(reasons[i])
            if options.box is BoxMode.AMODAL:
                ann["bbox_mode"] = "amodal"
            out.append(ann)
        return out


EXPORTER = CocoExporter()
