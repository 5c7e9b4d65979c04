"""``roadsynth export``: canonical records to COCO, KITTI, YOLO, MCAP (Foxglove), rosbag2, nuScenes, Cityscapes, ...

A thin adapter over :mod:`exporters`: options from the command line, the format from the registry.
The exporter writes atomically itself (temporary sibling, then rename) and adds ``meta.json`` to
folder outputs (MCAP: a metadata record); its ``command`` entry is informational, so only that differs
between two exports of the same records with the same options.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from pipeline.core.outputs import OutputSpec, json_file, mcap_file
from pipeline.stages.common import command_line, config_hash, int_at_least, software_versions

INPUT_ARGS = ("dataset",)
HELP = ("export dataset records to COCO, KITTI, KITTI tracking, KITTI depth, MOTChallenge, YOLO, MCAP (Foxglove), "
        "rosbag2, nuScenes or Cityscapes")
log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from exporters.base import BoxMode, Compression, formats
    from exporters.filters import DEFAULT_MAX_OCCLUSION, DEFAULT_MIN_VISIBLE_PX

    parser.add_argument("--dataset", type=Path, action="append", required=True, metavar="DIR",
                        help="a dataset record (from `roadsynth render`), or a folder of records; repeat to "
                        "merge several")
    parser.add_argument("--format", required=True, choices=formats(), help="output format")
    parser.add_argument("--out", type=Path, required=True, metavar="PATH",
                        help="output folder (a .mcap file for --format mcap); replaced atomically")
    parser.add_argument("--box", choices=[m.value for m in BoxMode], default=BoxMode.TIGHT.value,
                        help="2D box: visible pixels (tight) or full projection clipped to the image (amodal)")
    parser.add_argument("--splits", metavar="SPEC",
                        help="splits by whole runs: fractions 'train=0.8,val=0.2' or runs "
                        "'val=highway:3+urban:1,train=*' (default: one split)")
    parser.add_argument("--min-visible-px", type=int_at_least(0), default=None, metavar="N",
                        help=f"objects with fewer visible pixels become ignore regions "
                        f"(default: {DEFAULT_MIN_VISIBLE_PX})")
    parser.add_argument("--max-occlusion", type=float, default=None, metavar="F",
                        help=f"objects more occluded than F become ignore regions (default: {DEFAULT_MAX_OCCLUSION})")
    parser.add_argument("--compression", choices=[c.value for c in Compression],
                        help=f"MCAP/rosbag2 chunk compression (default: {Compression.ZSTD.value})")
    parser.add_argument("--camera", help="KITTI, KITTI tracking, KITTI depth, MOT, Cityscapes: the camera exported "
                        "as image_2 / the sequence / the city's images (default: the first)")
    parser.add_argument("--lidar", help="KITTI, KITTI tracking, KITTI depth: the LiDAR exported as velodyne / "
                        "projected into velodyne_raw (default: the first)")
    parser.add_argument("--copy-images", action="store_true", help="copy images instead of hard-linking them")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def outputs(args: argparse.Namespace) -> list[OutputSpec]:
    """A folder; for a format written as one file (MCAP), that file and its Foxglove layout beside it."""
    from exporters.base import get_exporter

    if not get_exporter(args.format).writes_file:
        return [OutputSpec(args.out)]
    from exporters.foxglove_layout import layout_path

    return [OutputSpec(args.out, folder=False, recognise=mcap_file, expected="an MCAP file"),
            OutputSpec(layout_path(args.out), flag="--out's layout", folder=False,
                       recognise=_layout_beside_our_mcap(Path(args.out)), expected="a Foxglove layout JSON file")]


def _layout_beside_our_mcap(mcap: Path):
    """A Foxglove layout is ours when the MCAP it sits beside is (a layout file has no room for a mark of ours:
    Foxglove reads it)."""
    layout = json_file(dict, ("configById", "layout"), marked=False)

    def recognise(path: Path) -> str | None:
        why = layout(path)
        if why is not None:
            return why
        if not mcap.is_file() or mcap_file(mcap) is not None:
            return f"a Foxglove layout not beside an MCAP file roadsynth wrote ({mcap.name})"
        return None

    return recognise


def options_from_args(args: argparse.Namespace):
    from exporters.base import BoxMode, Compression, ExportOptions
    from exporters.filters import DEFAULT_MAX_OCCLUSION, DEFAULT_MIN_VISIBLE_PX, ObjectFilter
    from exporters.splits import SplitSpec

    return ExportOptions(
        box=BoxMode(args.box), splits=SplitSpec.parse(args.splits) if args.splits else None,
        filter=ObjectFilter(
            min_visible_px=DEFAULT_MIN_VISIBLE_PX if args.min_visible_px is None else args.min_visible_px,
            max_occlusion=DEFAULT_MAX_OCCLUSION if args.max_occlusion is None else args.max_occlusion),
        compression=Compression(args.compression or Compression.ZSTD.value), camera=args.camera, lidar=args.lidar,
        link_images=not args.copy_images, progress=not args.no_progress)


def expand_datasets(paths: list[Path]) -> list[Path]:
    """Each path is a record, or a folder whose sub-folders are records (taken in sorted order)."""
    from pipeline.core.record import RECORD_FILE

    out: list[Path] = []
    for path in paths:
        if (path / RECORD_FILE).is_file() or not path.is_dir():
            out.append(path)  # a record, or something the exporter will reject with a clear message
            continue
        records = sorted(p for p in path.iterdir() if (p / RECORD_FILE).is_file())
        if not records:
            raise FileNotFoundError(f"{path}: neither a dataset record ({RECORD_FILE}) nor a folder of records")
        out.extend(records)
    return out


_FILTERED = ("coco", "kitti", "yolo", "mcap", "rosbag2", "kitti-tracking", "mot")
# Options that only some formats read: given for another format, they would be ignored without a word.
_FORMAT_OPTIONS = {"camera": ("kitti", "kitti-tracking", "kitti-depth", "mot", "cityscapes"),
                   "lidar": ("kitti", "kitti-tracking", "kitti-depth"),
                   "compression": ("mcap", "rosbag2"),
                   "copy_images": ("coco", "kitti", "yolo", "kitti-tracking", "kitti-depth", "mot", "nuscenes",
                                   "cityscapes"),
                   # the camera object filter; nuScenes annotates objects in 3D whatever the cameras see, Cityscapes
                   # every pixel
                   "min_visible_px": _FILTERED, "max_occlusion": _FILTERED}


def _check_applicable(args: argparse.Namespace) -> None:
    for name, formats in _FORMAT_OPTIONS.items():
        if getattr(args, name) not in (None, False) and args.format not in formats:
            flag = "--" + name.replace("_", "-")
            raise ValueError(f"{flag} applies to --format {', '.join(formats)} only, not {args.format}")


def export_records(fmt: str, datasets: list[Path], out: Path, options) -> dict:
    """Export the records ``datasets`` to ``out`` in format ``fmt`` with ``options`` (an ExportOptions), with the
    export's meta.json; returns the exporter's description (counts). Used by this stage and ``roadsynth
    experiment``'s merge."""
    from exporters.base import get_exporter

    config = {"format": fmt, "datasets": sorted(str(d) for d in datasets), **options.to_dict()}
    meta = {"stage": "export", "versions": software_versions(), "config": config, "config_hash": config_hash(config),
            "seed": None, "command": command_line()}
    return get_exporter(fmt).export(datasets, out, options, meta=meta)


def main(args: argparse.Namespace) -> int:
    from pipeline.core.processes import keep_freed_memory

    _check_applicable(args)
    keep_freed_memory()  # this process ends with the export: keep freed buffers mapped (pipeline.core.processes)
    args.dataset = expand_datasets(args.dataset)
    options = options_from_args(args)
    description = export_records(args.format, args.dataset, args.out, options)
    objects = description["counts"].get("objects", {}).get("total", {})
    log.info("exported %d record(s) to %s (%s); objects %s", len(description["records"]), args.out, args.format,
             ", ".join(f"{k} {v}" for k, v in objects.items()))
    return 0
