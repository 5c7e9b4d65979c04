"""Regenerate tests/data/kitti/devkit_golden.json from a build of the official KITTI devkit.

    PYTHONPATH=. python tests/evaluation/regenerate_kitti_devkit_golden.py --devkit PATH/evaluate_object

The binary is the devkit's evaluate_object.cpp (devkit_object, the 40-recall-point version) built
with boost (``g++ -O2 -o evaluate_object evaluate_object.cpp``, libboost-dev), with the command line
of the common offline variant: ``evaluate_object GT_DIR RESULT_DIR``, reading the frames of GT_DIR
and RESULT_DIR/data/<frame>.txt and writing RESULT_DIR/stats_<class>_detection{,_ground,_3d}.txt
(one line of 41 precisions per difficulty: easy, moderate, hard). The stock devkit_object main
takes a result id and fixed folders (and the server's copy mails its results), so wrap its evaluation
functions, unchanged, in a main with that command line. The devkit itself is not part of this
repository.

For every case of tests/evaluation/kitti_devkit_cases.py it records the sha256 of the written label
files (so a changed generator is caught) and, per class, metric and difficulty, AP_R40 = mean of
precision[1:41] and AP_R11 = mean of precision[0::4] from the devkit's printed precisions (printed
with 6 decimals, so the golden values carry an error below 1e-6). What the devkit does not evaluate
(no stats file: no qualifying detection of the class) is listed as "Class/metric" in not_evaluated.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import tempfile
from pathlib import Path

from tests.evaluation.kitti_devkit_cases import CASES, CLASSES, write_case

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "kitti" / "devkit_golden.json"
STATS_SUFFIX = {"bbox": "_detection", "bev": "_detection_ground", "3d": "_detection_3d"}
DIFFICULTIES = ("easy", "moderate", "hard")


def case_digest(gt_dir: Path, det_dir: Path) -> str:
    """sha256 over the case's label files, in name order."""
    digest = hashlib.sha256()
    for folder in (gt_dir, det_dir):
        for path in sorted(folder.glob("*.txt")):
            digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def read_stats(path: Path) -> dict[str, dict[str, float]]:
    """AP_R40 and AP_R11 per difficulty from one devkit stats file."""
    rows = [[float(v) for v in line.split()] for line in path.read_text().splitlines() if line.strip()]
    if len(rows) != 3 or any(len(r) != 41 for r in rows):
        raise ValueError(f"{path}: expected 3 lines of 41 precisions, got {[len(r) for r in rows]}")
    return {
        d: {"ap_r40": sum(r[1:]) / 40, "ap_r11": sum(r[0::4]) / 11} for d, r in zip(DIFFICULTIES, rows, strict=True)
    }


def run_devkit(devkit: Path, name: str, root: Path) -> dict:
    gt_dir, det_dir = write_case(name, root)
    done = subprocess.run([str(devkit), str(gt_dir), str(det_dir.parent)], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{devkit} failed on case {name} ({done.returncode}): {done.stdout}{done.stderr}")
    results: dict[str, dict] = {}
    not_evaluated = []
    for cls in CLASSES:
        for metric, suffix in STATS_SUFFIX.items():
            path = det_dir.parent / f"stats_{cls.lower()}{suffix}.txt"
            if path.is_file():
                results.setdefault(cls, {})[metric] = read_stats(path)
            else:
                not_evaluated.append(f"{cls}/{metric}")
    return {"sha256": case_digest(gt_dir, det_dir), "results": results, "not_evaluated": not_evaluated}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devkit", type=Path, required=True, help="the built evaluate_object binary")
    parser.add_argument("--out", type=Path, default=GOLDEN)
    args = parser.parse_args()
    cases = {}
    for name in CASES:
        with tempfile.TemporaryDirectory() as tmp:
            cases[name] = run_devkit(args.devkit.resolve(), name, Path(tmp))
    golden = {
        "source": "KITTI devkit evaluate_object.cpp (boost::geometry overlaps, 41-point precision), "
        "run by tests/evaluation/regenerate_kitti_devkit_golden.py",
        "precision_decimals": 6,
        "cases": cases,
    }
    args.out.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
