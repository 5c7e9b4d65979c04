"""The fixed tiny run of the byte-identity test (tests/test_byte_identity.py) and its two kinds of digest.

simulate (highway, seed 3, 200 vehicles, 90 s warm-up, 0.3 s recorded) -> render (a 320x240 camera and a
32-channel LiDAR, the default rig's radar left out: a rig without radars; night, fog and morning, two frames each) ->
export (COCO of all records, KITTI and YOLO of the night record) -> evaluate (the COCO ground truth against
detections made from it by a fixed shift and
score, grouped by condition). MCAP and rosbag2 are left out: they embed each record's meta.json (command
line, paths). Everything goes through the CLI (``pipeline.stages.cli.main``), so the test holds whatever
the stages' insides become.

Two digests per output tree:

- ``files``: SHA-256 of every file's bytes (``meta.json`` left out: it holds the command line, temporary
  paths and versions). docs/dataset.md: these are meant to be the same on any x86-64 with the same package
  versions, but a library's own SIMD code (Embree's ray-triangle tests, for one) may round differently on
  another instruction set, so the test compares them only on a processor with the same instruction-set
  features as the one that wrote the golden file.
- ``fingerprint``: SHA-256 of a canonical JSON of what does not depend on last-bit rounding: the simulation's
  trajectories rounded to 1e-4 (SUMO's own arithmetic), every label row with floats rounded to 0.01, the
  number of LiDAR points per (frame, sensor), the exports' annotation counts and the metrics rounded to 1e-3.
  The test always compares these.

Regenerate the golden file (after a change that is meant to alter outputs, saying so in the commit):
``PYTHONPATH=. python tests/byte_identity_run.py --write``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

GOLDEN = Path(__file__).resolve().parent / "data" / "byte_identity_golden.json"
CONDITIONS = ("night", "fog", "morning")  # morning: the daylight look (sky model, soft shadows)
ISA_FLAGS = ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512vl", "avx512bw", "avx512dq")


def cpu_features() -> list[str]:
    """The instruction-set features (of :data:`ISA_FLAGS`) this processor has, from /proc/cpuinfo."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return []
    for line in text.splitlines():
        if line.startswith("flags"):
            flags = set(line.split(":", 1)[1].split())
            return [f for f in ISA_FLAGS if f in flags]
    return []


def _cli(*argv: str) -> None:
    from pipeline.stages.cli import main

    code = main([*argv])
    if code != 0:
        raise RuntimeError(f"roadsynth {' '.join(argv)} exited with {code}")


def _small_rig(path: Path) -> Path:
    import yaml

    from tests.conftest import REPO

    data = yaml.safe_load((REPO / "configs" / "rigs" / "default.yaml").read_text())
    data["name"] = "tiny"
    data.pop("radars", None)  # the run of a rig without radars: its bytes must not change when radars exist
    data["cameras"][0].update(width_px=320, height_px=240)
    data["lidars"][0].update(channels=32, horizontal_resolution_deg=0.4)
    path.write_text(yaml.safe_dump(data))
    return path


def _detections(gt_json: Path, out: Path) -> Path:
    """Detections made from the ground truth: every box shifted by 5% of its size and grown by 5%, score by id;
    every third object missed and one false positive per image, so precision and recall are not 1."""
    gt = json.loads(gt_json.read_text())
    dets = []
    for ann in gt["annotations"]:
        if ann.get("iscrowd", 0) or ann["id"] % 3 == 0:
            continue
        x, y, w, h = ann["bbox"]
        dets.append({"image_id": ann["image_id"], "category_id": ann["category_id"],
                     "bbox": [x + 0.05 * w, y + 0.05 * h, w * 1.05, h * 1.05], "score": 0.5 + (ann["id"] % 7) / 14})
    for image in gt["images"]:
        dets.append({"image_id": image["id"], "category_id": 3, "bbox": [10.0, 10.0, 20.0, 15.0], "score": 0.3})
    out.write_text(json.dumps(dets))
    return out


def run(root: Path) -> dict[str, Path]:
    """The fixed tiny run under ``root``; returns the output folders by name."""
    sim = root / "sim"
    _cli("simulate", "--scenario", "highway", "--seed", "3", "--out", str(sim), "--vehicles", "200",
         "--duration", "0.3", "--warmup", "90", "--no-progress")
    rig = _small_rig(root / "tiny_rig.yaml")
    outs = {"sim": sim}
    for condition in CONDITIONS:
        outs[f"record-{condition}"] = root / "records" / f"highway-3-{condition}"
        _cli("render", "--sim", str(sim), "--condition", condition, "--rig", str(rig), "--out",
             str(outs[f"record-{condition}"]), "--frames", "2", "--workers", "1", "--no-progress")
    records = [str(outs[f"record-{c}"]) for c in CONDITIONS]
    outs["coco"] = root / "coco"
    _cli("export", *[a for r in records for a in ("--dataset", r)], "--format", "coco", "--out", str(outs["coco"]),
         "--copy-images", "--no-progress")
    for fmt in ("kitti", "yolo"):
        outs[fmt] = root / fmt
        _cli("export", "--dataset", records[0], "--format", fmt, "--out", str(outs[fmt]), "--copy-images",
             "--no-progress")
    gt = next(outs["coco"].glob("annotations*.json"))
    dets = _detections(gt, root / "detections.json")
    outs["eval"] = root / "eval"
    _cli("evaluate", "--gt", str(gt), "--detections", str(dets), "--out", str(outs["eval"]), "--group-by",
         "condition")
    return outs


def file_digests(root: Path) -> dict[str, str]:
    """SHA-256 of every file under ``root`` by relative path, ``meta.json`` left out."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != "meta.json"}


def _rounded_table(path: Path, decimals: int) -> list:
    df = pd.read_parquet(path)
    cols = []
    for name in df.columns:
        col = df[name]
        if pd.api.types.is_float_dtype(col):
            values = [None if not np.isfinite(v) else round(float(v), decimals) + 0.0 for v in col]
        elif pd.api.types.is_integer_dtype(col) or pd.api.types.is_bool_dtype(col):
            values = [int(v) for v in col]
        else:
            values = [_plain(v, decimals) for v in col]
        cols.append([name, values])
    return cols


def _plain(value, decimals: int):
    """A JSON-able value with floats rounded (lists and arrays of them too)."""
    if isinstance(value, (float, np.floating)):
        return None if not np.isfinite(value) else round(float(value), decimals) + 0.0
    if isinstance(value, (np.ndarray, list, tuple)):
        return [_plain(v, decimals) for v in value]
    if isinstance(value, (np.integer, bool, np.bool_)):
        return int(value)
    if isinstance(value, dict):
        return {k: _plain(v, decimals) for k, v in sorted(value.items())}
    return value if value is None or isinstance(value, (int, str)) else str(value)


def fingerprint(name: str, root: Path) -> str:
    """SHA-256 of the rounded content of one output tree (see the module docstring)."""
    if name == "sim":
        content = _rounded_table(root / "trajectories.parquet", 4)
    elif name.startswith("record-"):
        lidar = {}
        for path in sorted(root.rglob("*.parquet")):
            if path.name != "labels.parquet" and "lidar" in str(path.relative_to(root)):
                lidar[str(path.relative_to(root))] = len(pd.read_parquet(path, columns=[]))
        content = {"labels": _rounded_table(root / "labels.parquet", 2), "lidar_points": lidar}
    elif name == "eval":
        content = _plain(json.loads((root / "metrics.json").read_text()), 3)
    else:  # an export: how many files, and the annotations of JSON and text label files by count
        files = sorted(p for p in root.rglob("*") if p.is_file() and p.name != "meta.json")
        counts = {}
        for p in files:
            rel = str(p.relative_to(root))
            if p.suffix == ".json":
                data = json.loads(p.read_text())
                counts[rel] = len(data.get("annotations", [])) if isinstance(data, dict) else len(data)
            elif p.suffix == ".txt":
                counts[rel] = len(p.read_text().splitlines())
            else:
                counts[rel] = None
        content = counts
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def digests(outs: dict[str, Path]) -> dict:
    return {"cpu_features": cpu_features(),
            "files": {name: file_digests(path) for name, path in outs.items()},
            "fingerprint": {name: fingerprint(name, path) for name, path in outs.items()}}


def main(argv: list[str] | None = None) -> int:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"write {GOLDEN}")
    parser.add_argument("--keep", type=Path, help="run in this folder (kept) instead of a temporary one")
    args = parser.parse_args(argv)
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        result = digests(run(args.keep))
    else:
        with tempfile.TemporaryDirectory() as tmp:
            result = digests(run(Path(tmp)))
    text = json.dumps(result, indent=1, sort_keys=True) + "\n"
    if args.write:
        GOLDEN.write_text(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
