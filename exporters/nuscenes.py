"""nuScenes v1.0-style export: the devkit's JSON tables, LiDAR ``.pcd.bin``, radar ``.pcd`` and camera images.

Layout (``NuScenes(version="v1.0-roadsynth", dataroot=OUT)`` loads it)::

    OUT/v1.0-roadsynth/{scene,sample,sample_data,ego_pose,calibrated_sensor,sensor,log,map,category,attribute,
                        visibility,instance,sample_annotation}.json
    OUT/v1.0-roadsynth/splits.json      split -> scene names (the devkit's custom splits), plus "all"
    OUT/samples/<CHANNEL>/<scene>__<CHANNEL>__<timestamp_us>.{png,pcd.bin,pcd}
    OUT/maps/roadsynth-blank.png        the map stub (one blank mask for every log)

One scene (and one log) per record, named ``<scenario>_s<seed>_<condition>``; every frame of the record is a sample
(a key frame of every sensor: the record renders all sensors at the frame's instant, so a frame's sample_data share
one ego pose). Objects: every (frame, track) any sensor's labels list, one instance per track and record, annotations
linked prev/next along the track so the devkit's ``box_velocity`` gives our tracks' velocities. Conventions, tokens
and the class mapping: :mod:`exporters.nuscenes_tables`; file layouts: :mod:`exporters.nuscenes_files`. The
camera object filter (``--min-visible-px``, ``--max-occlusion``) does not apply: nuScenes annotates objects in 3D
whatever the cameras see, and the visibility token carries what they see.
"""

from __future__ import annotations

import logging
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from exporters import nuscenes_tables as nt
from exporters.base import Exporter, ExportError, ExportOptions
from exporters.nuscenes_files import lidar_array, radar_pcd
from exporters.source import ExportSource, RecordSource
from exporters.writing import dumps_json, link_or_copy
from pipeline.core.classes import RIDER, Person
from pipeline.core.png import encode_png

log = logging.getLogger(__name__)

TABLES = ("category", "attribute", "visibility", "instance", "sensor", "calibrated_sensor", "ego_pose", "log", "scene",
          "sample", "sample_data", "sample_annotation", "map")
MAP_FILE = "maps/roadsynth-blank.png"
EXTENSION = {"camera": "png", "lidar": "pcd.bin", "radar": "pcd"}


def _chain(rows: list[dict]) -> None:
    """Link ``rows`` (in time order) through their ``prev`` and ``next`` tokens."""
    for i, row in enumerate(rows):
        row["prev"] = rows[i - 1]["token"] if i > 0 else ""
        row["next"] = rows[i + 1]["token"] if i + 1 < len(rows) else ""


class NuScenesExporter(Exporter):
    name = "nuscenes"

    def check(self, source: ExportSource, options: ExportOptions) -> None:
        if nt.ALL_SPLIT in source.split_names:
            raise ExportError(f"--splits: the split name {nt.ALL_SPLIT!r} is reserved in a nuScenes export (its "
                              "splits.json lists every scene under it); name the split otherwise")
        for src in source.records:
            root = src.record.root
            if not src.info.lidars:
                raise ExportError(f"{root}: nuScenes needs a LiDAR (its first becomes LIDAR_TOP, which the devkit's "
                                  "renderer and detection evaluation read); the record has none")
            channels = Counter(ch for _, _, ch in nt.record_channels(src))
            clash = sorted(ch for ch, n in channels.items() if n > 1)
            if clash:
                raise ExportError(f"{root}: sensors map to the same nuScenes channel {', '.join(clash)} "
                                  f"({', '.join(f'{k} {n} -> {c}' for k, n, c in nt.record_channels(src))})")
            unknown = sorted(set(src.labels["cls"]) - set(nt.CATEGORY) - {RIDER})
            if unknown:
                raise ExportError(f"{root}: labels.parquet field cls has classes {unknown} without a nuScenes "
                                  f"category (known: {sorted(nt.CATEGORY)})")
            persons = sorted(set(src.labels["person"]) - {p.value for p in Person} - {""})
            if persons:
                raise ExportError(f"{root}: labels.parquet field person has values {persons}; expected one of "
                                  f"{sorted(p.value for p in Person)} or empty")

    def write(self, source: ExportSource, tmp: Path, options: ExportOptions, description: dict[str, Any],
              meta: dict[str, Any] | None) -> dict[str, Any]:
        tables: dict[str, list[dict]] = {name: [] for name in TABLES}
        tables |= nt.static_tables()
        sensors: dict[str, dict] = {}
        splits: dict[str, list[str]] = {s: [] for s in source.split_names}
        counts: Counter = Counter()
        progress = tqdm(total=source.n_frames(), desc="nuscenes", unit="frame", disable=not options.progress)
        for src in source.records:
            self._record(src, tmp, options, tables, sensors, counts, progress)
            splits[src.split].append(src.stem)
        progress.close()
        tables["sensor"] = [sensors[ch] for ch in sorted(sensors)]
        linked, images = counts.pop("_images_linked", 0), counts.pop("_images", 0)
        riders = counts.pop("_riders", 0)
        tables["map"] = [{"token": nt.token("map", MAP_FILE), "category": "semantic_prior", "filename": MAP_FILE,
                          "log_tokens": [row["token"] for row in tables["log"]]}]
        (tmp / "maps").mkdir()
        (tmp / MAP_FILE).write_bytes(encode_png(np.zeros((8, 8), np.uint8)))
        version = tmp / nt.VERSION
        version.mkdir()
        for name in TABLES:
            (version / f"{name}.json").write_text(dumps_json(tables[name], indent=None))
        splits[nt.ALL_SPLIT] = [row["name"] for row in tables["scene"]]
        (version / "splits.json").write_text(dumps_json(splits))
        return {"version": nt.VERSION, "scenes": len(tables["scene"]), "samples": len(tables["sample"]),
                "sample_data": len(tables["sample_data"]), "annotations": len(tables["sample_annotation"]),
                "instances": len(tables["instance"]), "annotations_by_class": dict(sorted(counts.items())),
                "objects": {"total": {"annotated": len(tables["sample_annotation"]), "riders_in_cycle_boxes": riders}},
                "images_linked": int(linked), "images_copied": int(images - linked),
                "splits": {s: len(v) for s, v in splits.items()}}

    def _record(self, src: RecordSource, tmp: Path, options: ExportOptions, tables: dict[str, list[dict]],
                sensors: dict[str, dict], counts: Counter, progress: tqdm) -> None:
        stem, info, record = src.stem, src.info, src.record
        frames = src.frames
        frame_ids = [int(f) for f in frames["frame"]]
        time_us = {f: round(float(t) * 1e6) for f, t in zip(frame_ids, frames["time_s"], strict=True)}
        log_token, scene_token = nt.token("log", stem), nt.token("scene", stem)
        tables["log"].append({"token": log_token, "logfile": stem, "vehicle": "roadsynth-ego", "date_captured": "",
                              "location": info.scenario})
        samples = [{"token": nt.token("sample", stem, f), "timestamp": time_us[f], "scene_token": scene_token}
                   for f in frame_ids]
        _chain(samples)
        tables["sample"] += samples
        sample_of = {f: s["token"] for f, s in zip(frame_ids, samples, strict=True)}
        tables["scene"].append({
            "token": scene_token, "log_token": log_token, "nbr_samples": len(samples), "name": stem,
            "first_sample_token": samples[0]["token"] if samples else "",
            "last_sample_token": samples[-1]["token"] if samples else "",
            "description": f"roadsynth scenario {info.scenario}, seed {info.seed}, condition {info.condition}"})
        yaw = frames["ego_yaw_rad"].to_numpy(dtype=np.float64)
        quats = nt.quat_yaw(yaw).tolist()
        xyz = frames[["ego_x_m", "ego_y_m", "ego_z_m"]].to_numpy(dtype=np.float64).tolist()
        poses = {f: nt.token("ego_pose", stem, f) for f in frame_ids}
        tables["ego_pose"] += [{"token": poses[f], "timestamp": time_us[f], "translation": xyz[i],
                                "rotation": quats[i]} for i, f in enumerate(frame_ids)]
        cameras = {c.name: c for c in info.cameras}
        for cam in info.cameras:
            if np.any(np.abs(cam.distortion) > 0):
                log.warning("%s: camera %s has lens distortion %s, which nuScenes' calibrated_sensor cannot hold: "
                            "the devkit projects its boxes as through a pinhole", record.root, cam.name,
                            cam.distortion)
        radars = {r.name: r for r in info.radars}
        per_sensor: dict[str, list[dict]] = {}
        for kind, name, ch in nt.record_channels(src):
            sensors[ch] = {"token": nt.token("sensor", ch), "channel": ch, "modality": kind}
            sensor = cameras.get(name) or radars.get(name) or next(x for x in info.lidars if x.name == name)
            t = sensor.T_array
            cs_token = nt.token("calibrated_sensor", stem, ch)
            tables["calibrated_sensor"].append({
                "token": cs_token, "sensor_token": sensors[ch]["token"], "translation": t[:3, 3].tolist(),
                "rotation": nt.quat_wxyz(t[:3, :3]),
                "camera_intrinsic": cameras[name].K_array.tolist() if kind == "camera" else []})
            (tmp / "samples" / ch).mkdir(parents=True, exist_ok=True)
            width, height = (cameras[name].width_px, cameras[name].height_px) if kind == "camera" else (0, 0)
            per_sensor[name] = [{
                "token": nt.token("sample_data", stem, ch, f), "sample_token": sample_of[f],
                "ego_pose_token": poses[f], "calibrated_sensor_token": cs_token, "timestamp": time_us[f],
                "fileformat": EXTENSION[kind].split(".")[0], "is_key_frame": True, "height": height, "width": width,
                "filename": f"samples/{ch}/{stem}__{ch}__{time_us[f]}.{EXTENSION[kind]}"} for f in frame_ids]
            _chain(per_sensor[name])
            tables["sample_data"] += per_sensor[name]
        kinds = {name: kind for kind, name, _ in nt.record_channels(src)}
        for i, f in enumerate(frame_ids):
            for name, rows in per_sensor.items():
                path = tmp / rows[i]["filename"]
                if kinds[name] == "camera":
                    counts["_images"] += 1
                    counts["_images_linked"] += link_or_copy(record.image_path(name, "rgb", f), path,
                                                             link=options.link_images)
                elif kinds[name] == "lidar":
                    lidar_array(record.point_columns(name, f)).tofile(path)
                else:
                    path.write_bytes(radar_pcd(record.radar_columns(name, f), radars[name].velocity_resolution_mps))
            progress.update(1)
        obj = nt.objects(src)
        riders = src.labels.loc[src.labels["cls"] == RIDER, ["frame", "track_id"]]
        counts["_riders"] += len(riders.drop_duplicates())
        anns, instances, _ = nt.annotation_tables(stem, obj, time_us, sample_of)
        tables["sample_annotation"] += anns
        tables["instance"] += instances
        counts.update(nt.categories(obj["cls"].to_numpy(), obj["person"].to_numpy()).tolist())


EXPORTER = NuScenesExporter()
