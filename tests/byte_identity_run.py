"""The fixed tiny run of the byte-identity test (tests/test_byte_identity.py), and what it compares.

simulate (highway, seed 3, 200 vehicles, 90 s warm-up, 0.3 s recorded) -> render (a 320x240 camera and a
32-channel LiDAR, the default rig's radar left out: a rig without radars; night, fog and morning, two frames each) ->
export (COCO of all records, KITTI and YOLO of the night record) -> evaluate (the COCO ground truth against
detections made from it by a fixed shift and score, grouped by condition). MCAP and rosbag2 are left out: they
embed each record's meta.json (command line, paths). Everything goes through the CLI
(``pipeline.stages.cli.main``), so the test holds whatever the stages' insides become.

Two comparisons, because bytes and values promise different things:

- **Bytes, within one install** (:func:`file_digests`): the run made twice on this machine, the second time with
  the render split over two worker processes, gives the same bytes in every file (``meta.json`` left out: it holds
  the command line, temporary paths and versions). That is docs/design.md's promise, "same config and seed, same
  bytes", and it is safe to assert anywhere: both runs use the same processor and the same libraries.
- **Values, against the golden file, on any install** (:func:`summaries`, :func:`compare`): bytes are *not*
  compared across installs. Embree's ray-triangle tests, numpy's SIMD maths (the LiDAR's exp), BLAS kernels,
  zlib's deflate (PNG), pyarrow's Parquet writer and matplotlib all choose bytes that depend on the processor or a
  library's version, so a fresh install may write other bytes for the same values. What is stored and compared
  is the content: every table's rows (small tables in full, LiDAR sweeps as counts and quantiles), images decoded
  (RGB as 16x16-pixel block means, label images as pixel counts per value, depth as quantiles), JSON and text
  parsed, with the tolerances of :func:`tolerance` (one pixel for a tight box edge, two 8-bit levels for a block
  mean, ...): wide enough for last-bit rounding on another machine, far narrower than any change a refactor
  could make by mistake.

Regenerate the golden file (after a change that is meant to alter outputs, saying so in the commit):
``PYTHONPATH=. python tests/byte_identity_run.py --write``.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd

GOLDEN = Path(__file__).resolve().parent / "data" / "byte_identity_golden.json.gz"  # gzip: some 700 kB of JSON
CONDITIONS = ("night", "fog", "morning")  # morning: the daylight look (sky model, soft shadows)
QUANTILES = (0.0, 0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99, 1.0)
BLOCK_PX = 16  # RGB images are compared as the means of BLOCK_PX x BLOCK_PX pixel blocks
FULL_TABLE_ROWS = 2000  # tables up to this many rows are stored in full; longer ones (LiDAR sweeps) as summaries


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
    """Detections made from the ground truth: every box shifted by 5% of its size and grown by 5% (IoU 0.75 with
    its object, far from the thresholds 0.7 and 0.8), score by id; every third object missed and one false
    positive per image, so precision and recall are not 1."""
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


def run(root: Path, *, render_workers: int = 1) -> dict[str, Path]:
    """The fixed tiny run under ``root``; returns the output folders by name."""
    sim = root / "sim"
    _cli("simulate", "--scenario", "highway", "--seed", "3", "--out", str(sim), "--vehicles", "200",
         "--duration", "0.3", "--warmup", "90", "--no-progress")
    rig = _small_rig(root / "tiny_rig.yaml")
    outs = {"sim": sim}
    for condition in CONDITIONS:
        outs[f"record-{condition}"] = root / "records" / f"highway-3-{condition}"
        _cli("render", "--sim", str(sim), "--condition", condition, "--rig", str(rig), "--out",
             str(outs[f"record-{condition}"]), "--frames", "2", "--workers", str(render_workers), "--no-progress")
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


def _output_files(root: Path) -> list[Path]:
    return [p for p in sorted(root.rglob("*")) if p.is_file() and p.name != "meta.json"]


def file_digests(root: Path) -> dict[str, str]:
    """SHA-256 of every file under ``root`` by relative path, ``meta.json`` left out."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in _output_files(root)}


# --- what a file holds, independent of how its bytes were written ---------------------------------------------

def _plain(value):
    """A JSON-able value: numpy scalars and arrays as Python numbers and lists (floats to 8 decimals); non-finite
    floats as strings."""
    if isinstance(value, (float, np.floating)):  # 8 decimals: far below every tolerance, and a shorter file
        return round(float(value), 8) + 0.0 if np.isfinite(value) else str(float(value))
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (np.ndarray, list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in sorted(value.items())}
    return value if value is None or isinstance(value, (int, str)) else str(value)


def _quantiles(values: np.ndarray) -> list[float]:
    values = np.asarray(values, np.float64)
    values = values[np.isfinite(values)]
    return [float(q) for q in np.quantile(values, QUANTILES)] if len(values) else []


def _counts(values: np.ndarray) -> dict[str, int]:
    keys, counts = np.unique(np.asarray(values), return_counts=True)
    return {str(k): int(c) for k, c in zip(keys, counts, strict=True)}


def _table(df: pd.DataFrame) -> dict:
    """Small tables column by column in full; long ones (LiDAR sweeps) as the row count, float columns'
    quantiles and integer columns' counts per value."""
    if len(df) <= FULL_TABLE_ROWS:
        return {"rows": len(df), "columns": {name: _plain(df[name].tolist()) for name in df.columns}}
    summary = {}
    for name in df.columns:
        col = df[name].to_numpy()
        summary[name] = ({"quantiles": _quantiles(col)} if np.issubdtype(col.dtype, np.floating)
                         else {"counts": _counts(col)})
    return {"rows": len(df), "summary": summary}


def _points_bin(path: Path) -> dict:
    """A KITTI velodyne file: float32 x, y, z, intensity."""
    points = np.fromfile(path, np.float32).reshape(-1, 4)
    return {"rows": len(points), "summary": {name: {"quantiles": _quantiles(points[:, k])}
                                             for k, name in enumerate(("x", "y", "z", "intensity"))}}


def _image(path: Path) -> dict:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path}: not an image OpenCV can read")
    kind = path.parent.name
    out = {"shape": list(img.shape), "dtype": str(img.dtype)}
    if kind in ("instance", "semantic"):
        out["pixels_per_value"] = _counts(img)
    elif kind == "depth":  # uint16, metres x 256; 0 and 65535 invalid
        valid = img[(img > 0) & (img < 65535)].astype(np.float64) / 256.0
        out.update(valid_px=int(valid.size), depth_m=_quantiles(valid))
    else:  # colour: the mean of each block (and each channel), and of the whole image
        h, w = img.shape[:2]
        hb, wb = h // BLOCK_PX, w // BLOCK_PX
        blocks = img[: hb * BLOCK_PX, : wb * BLOCK_PX].astype(np.float64)
        blocks = blocks.reshape(hb, BLOCK_PX, wb, BLOCK_PX, -1).mean(axis=(1, 3))
        out.update(mean=float(img.mean()), block_means=np.round(blocks, 3).tolist())
    return out


def _tokens(text: str, separators: str = r"[\s,]+") -> list[str]:
    """The tokens between ``separators``, as written (:func:`compare` reads the numbers among them)."""
    return re.split(separators, text.strip())


def _number(token: str) -> tuple[float, int | None] | None:
    """A token's value and the digits it was printed with after the point (None: not a finite number)."""
    try:
        value = float(token)
    except ValueError:
        return None
    if not np.isfinite(value):
        return None
    decimals = len(token.split("e")[0].split(".")[1]) if "." in token and "e" not in token.lower() else None
    return value, decimals


def summarise(path: Path) -> dict:
    """What ``path`` holds, by its kind (see the module docstring)."""
    suffix = path.suffix
    if suffix == ".parquet":
        return _table(pd.read_parquet(path))
    if suffix == ".png":
        return _image(path)
    if suffix == ".bin":
        return _points_bin(path)
    if suffix == ".json":
        data = json.loads(path.read_text())
        if isinstance(data, dict) and isinstance(data.get("annotations"), list):  # COCO: masks by their area alone
            for ann in data["annotations"]:  # (an RLE string changes wholly when one edge pixel flips)
                if isinstance(ann.get("segmentation"), dict):
                    ann["segmentation"].pop("counts", None)
        return {"json": _plain(data)}
    if suffix in (".xml", ".sumocfg"):  # SUMO's files: their text without the comments (tool, version, date)
        return {"tokens": _tokens(re.sub(r"<!--.*?-->", "", path.read_text(), flags=re.DOTALL), r'[\s,"=<>/:]+')}
    return {"tokens": _tokens(path.read_text())}


def summaries(outs: dict[str, Path]) -> dict[str, dict[str, dict]]:
    """:func:`summarise` of every output file (``meta.json`` left out), by output name and relative path."""
    return {name: {str(p.relative_to(root)): summarise(p) for p in _output_files(root)}
            for name, root in outs.items()}


# --- comparison with stated tolerances --------------------------------------------------------------------------

PX_COUNT = (3.0, 0.02)  # pixel and point counts: 3 plus 2 %: a silhouette's edge pixels may flip on another machine
TIGHT_BOX_PX = 1.0  # a tight box edge is a pixel boundary: one pixel may flip where a ray grazes a silhouette
LABEL_COLUMNS = {
    "x1": (TIGHT_BOX_PX, 0.0), "y1": (TIGHT_BOX_PX, 0.0), "x2": (TIGHT_BOX_PX, 0.0), "y2": (TIGHT_BOX_PX, 0.0),
    "visible_px": PX_COUNT, "unoccluded_px": PX_COUNT, "lidar_points": PX_COUNT,
    "occlusion": (0.02, 0.0), "truncation": (0.02, 0.0),
}
COCO_KEYS = {"bbox": (2 * TIGHT_BOX_PX, 0.0),  # [x, y, w, h]: both edges of w or h may flip
             "area": PX_COUNT, "visible_px": PX_COUNT, "lidar_points": PX_COUNT,
             "occlusion": (0.02, 0.0), "truncation": (0.02, 0.0)}
KITTI_LABEL_COLUMNS = {1: (0.02, 0.0), 2: (1.0, 0.0), 4: (TIGHT_BOX_PX, 0.0), 5: (TIGHT_BOX_PX, 0.0),
                       6: (TIGHT_BOX_PX, 0.0), 7: (TIGHT_BOX_PX, 0.0)}  # truncation, occlusion level, 2D box
VALUES = (1e-6, 1e-6)  # everything else computed (poses, 3D boxes, projections, metrics): last-bit rounding only


def tolerance(rel: str, key: str, column: int | None = None) -> tuple[float, float]:
    """The (absolute, relative) tolerance of a value: ``key`` is the column or JSON key holding it, ``column`` a
    text token's index on its line. A value passes when ``|value - golden| <= abs + rel * |golden|``."""
    if "lidars/" in rel or rel.endswith(".bin"):  # LiDAR sweeps: counts and quantiles over some 25,000 points
        return {"rows": (3.0, 0.005), "counts": PX_COUNT, "intensity": (0.01, 0.01)}.get(key, (0.02, 0.0))
    if rel.endswith(".png"):
        return {"block_means": (2.0, 0.0), "mean": (0.5, 0.0), "pixels_per_value": PX_COUNT,
                "valid_px": PX_COUNT, "depth_m": (0.05, 0.0)}.get(key, (0.0, 0.0))
    if rel == "labels.parquet":
        return LABEL_COLUMNS.get(key, VALUES)
    if rel.startswith("annotations") or rel == "export.json":
        return COCO_KEYS.get(key, (2.0, 0.0) if key in ("hidden", "kept", "occluded", "tiny") else VALUES)
    if "label_2/" in rel and column is not None:
        return KITTI_LABEL_COLUMNS.get(column, VALUES)
    if rel.startswith("labels/") and column is not None and column > 0:  # YOLO: box in units of the image size
        return (TIGHT_BOX_PX / 240.0, 0.0)
    if rel.startswith(("metrics", "plots/")) or rel == "report.md":
        return (1e-3, 0.0)
    return VALUES


def _close(value, golden, tol: tuple[float, float]) -> bool:
    return abs(value - golden) <= tol[0] + tol[1] * abs(golden)


def _compare(result, golden, where: str, rel: str, key: str, problems: list[str]) -> None:
    if isinstance(golden, dict):
        if not isinstance(result, dict) or set(result) != set(golden):
            got = sorted(result) if isinstance(result, dict) else type(result).__name__
            problems.append(f"{where}: keys {got}, expected {sorted(golden)}")
            return
        for k in golden:
            inner = k if k not in ("quantiles", "columns", "summary", "json", "tokens") else key
            if key == "pixels_per_value" or key == "counts":  # a count per value: the tolerance of counts
                inner = key
            _compare(result[k], golden[k], f"{where}.{k}", rel, inner, problems)
        return
    if isinstance(golden, list):
        if not isinstance(result, list) or len(result) != len(golden):
            got = len(result) if isinstance(result, list) else type(result).__name__
            problems.append(f"{where}: {got} items, expected {len(golden)}")
            return
        for i, (r, g) in enumerate(zip(result, golden, strict=True)):
            _compare(r, g, f"{where}[{i}]", rel, key, problems)
        return
    if isinstance(golden, bool) or isinstance(result, bool) or isinstance(golden, str) or golden is None:
        if result != golden:
            problems.append(f"{where}: {result!r}, expected {golden!r}")
        return
    if not isinstance(result, (int, float)):
        problems.append(f"{where}: {result!r}, expected the number {golden}")
        return
    tol = tolerance(rel, key)
    if not _close(result, golden, tol):
        problems.append(f"{where}: {result}, expected {golden} within {tol[0]:g} + {tol[1]:g}·|x|")


def compare(result: dict[str, dict[str, dict]], golden: dict[str, dict[str, dict]]) -> list[str]:
    """Every difference between two :func:`summaries` beyond :func:`tolerance`, one line each (empty: equal)."""
    problems: list[str] = []
    for name in sorted(set(golden) | set(result)):
        files_g, files_r = golden.get(name, {}), result.get(name, {})
        for rel in sorted(set(files_g) - set(files_r)):
            problems.append(f"{name}/{rel}: missing")
        for rel in sorted(set(files_r) - set(files_g)):
            problems.append(f"{name}/{rel}: not in the golden file")
        for rel in sorted(set(files_g) & set(files_r)):
            g, r = files_g[rel], files_r[rel]
            if "tokens" in g and "tokens" in r:
                _compare_tokens(r["tokens"], g["tokens"], f"{name}/{rel}", rel, problems)
            else:
                _compare(r, g, f"{name}/{rel}", rel, "", problems)
    return problems


def _compare_tokens(result: list[str], golden: list[str], where: str, rel: str, problems: list[str]) -> None:
    """Text files token by token: words exactly, numbers within :func:`tolerance` (at least one unit of the last
    digit printed: a printed number may round the other way); a token's column is its index on its line."""
    if len(result) != len(golden):
        problems.append(f"{where}: {len(result)} tokens, expected {len(golden)}")
        return
    width = _line_width(rel)
    for i, (r, g) in enumerate(zip(result, golden, strict=True)):
        number_g, number_r = _number(g), _number(r)
        if number_g is None or number_r is None:
            if r != g:
                problems.append(f"{where}[token {i}]: {r!r}, expected {g!r}")
            continue
        atol, rtol = tolerance(rel, "", i % width if width else None)
        if number_g[1] is not None:
            atol = max(atol, 10.0 ** -number_g[1] * (1 + 1e-9))
        if not _close(number_r[0], number_g[0], (atol, rtol)):
            problems.append(f"{where}[token {i}]: {r}, expected {g} within {atol:g} + {rtol:g}·|x|")


def _line_width(rel: str) -> int | None:
    """Tokens per line of the label files whose columns have their own tolerances."""
    if "label_2/" in rel:
        return 15  # KITTI: type, truncated, occluded, alpha, 2D box (4), dimensions (3), location (3), rotation_y
    if rel.startswith("labels/") and rel.endswith(".txt"):
        return 5  # YOLO: class, x_centre, y_centre, width, height
    return None


def main(argv: list[str] | None = None) -> int:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"write {GOLDEN}")
    parser.add_argument("--keep", type=Path, help="run in this folder (kept) instead of a temporary one")
    args = parser.parse_args(argv)
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        result = summaries(run(args.keep))
    else:
        with tempfile.TemporaryDirectory() as tmp:
            result = summaries(run(Path(tmp)))
    text = json.dumps(result, sort_keys=True, separators=(",", ":")) + "\n"
    if args.write:
        GOLDEN.write_bytes(gzip.compress(text.encode(), compresslevel=9, mtime=0))
    else:
        sys.stdout.write(text)
    return 0


def read_golden() -> dict:
    """The golden summaries (:data:`GOLDEN`)."""
    return json.loads(gzip.decompress(GOLDEN.read_bytes()))


if __name__ == "__main__":
    raise SystemExit(main())
