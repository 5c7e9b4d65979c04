"""Benchmark: how full our frames are. Reads rendered records only (frames.parquet, labels.parquet).

Prints, per record and then per (scenario, condition): frames, vehicles (car/van/truck/bus) with a tight box
>= 30 px tall per frame (mean, and the share of frames with at least 2), the number of distinct vehicles that
are >= 30 px tall in some frame (one car waiting ahead at a red light fills many frames: ../shared/REALISM.md),
cyclists and pedestrians >= 30 px per frame, the distinct pedestrians >= 30 px and >= 60 px (twice the height) tall
in some frame, and the near-duplicate frame rate (definitions: pipeline/core/scene_content.py). Targets: at least 2
vehicles >= 30 px per urban frame on average (issue 23); at least 20 distinct people >= 30 px in an urban morning run
of 60 frames, some >= 60 px (issue 40).

    python bench/bench_scene_content.py RECORD [RECORD ...] [--min-height 30] [--camera front]

Make a record with e.g.
    roadsynth simulate --scenario urban --seed 11 --out /tmp/x/sim
    roadsynth render --sim /tmp/x/sim --condition morning --frames 60 --out /tmp/x/rec
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pandas as pd

from pipeline.core.scene_content import VEHICLE_CLASSES, near_duplicate_rate, tall_counts
from pipeline.core.tables import read_parquet


def measure(record: Path, min_height_px: float, camera: str | None) -> dict[str, object]:
    info = json.loads((record / "record.json").read_text())
    frames = read_parquet(record / "frames.parquet")
    labels = read_parquet(record / "labels.parquet")
    camera = camera or info["cameras"][0]["name"]
    counts = tall_counts(frames, labels, min_height_px)
    counts = counts[counts["sensor"] == camera]
    cam = labels[(labels["sensor"] == camera) & labels["visible"] & labels["cls"].isin(VEHICLE_CLASSES)]
    distinct = cam.loc[(cam["y2"] - cam["y1"]) >= min_height_px, "track_id"].nunique()
    people = labels[(labels["sensor"] == camera) & labels["visible"] & (labels["cls"] == "pedestrian")]
    tall_people = people.loc[(people["y2"] - people["y1"]) >= min_height_px, "track_id"]
    taller_people = people.loc[(people["y2"] - people["y1"]) >= 2.0 * min_height_px, "track_id"]
    ego_travel = float(frames.sort_values("frame")[["ego_x_m", "ego_y_m"]].diff().pow(2).sum(axis=1).pow(0.5).sum())
    return {"record": f"{record.parent.name}/{record.name}", "scenario": info["scenario"], "seed": info["seed"],
            "condition": info["condition"],
            "frames": len(frames), "veh_per_frame": counts["vehicles"].mean(),
            "frames_ge2_veh": (counts["vehicles"] >= 2).mean(), "distinct_veh": distinct,
            "cyc_per_frame": counts["cycles"].mean(),
            "ped_per_frame": counts["pedestrians"].mean(), "distinct_ped": tall_people.nunique(),
            "distinct_ped_2x": taller_people.nunique(),
            "near_dup_rate": near_duplicate_rate(frames, labels, camera), "ego_travel_m": ego_travel}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", type=Path, nargs="+")
    parser.add_argument("--min-height", type=float, default=30.0, help="tight box height threshold, px")
    parser.add_argument("--camera", help="camera name (default: the record's first)")
    args = parser.parse_args()
    rows = pd.DataFrame([measure(r, args.min_height, args.camera) for r in args.records])
    pd.set_option("display.width", 200)
    print(f"objects with a tight box >= {args.min_height:g} px tall, per frame")
    print(rows.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    if len(rows) > 1:
        # Frame-weighted means over the records of each (scenario, condition).
        w = rows.assign(**{c: rows[c] * rows["frames"] for c in
                           ("veh_per_frame", "frames_ge2_veh", "cyc_per_frame", "ped_per_frame")})
        w["dups"] = rows["near_dup_rate"] * (rows["frames"] - 1)
        g = w.groupby(["scenario", "condition"]).sum(numeric_only=True)
        runs = rows.groupby(["scenario", "condition"]).size()
        out = pd.DataFrame({"records": runs, "frames": g["frames"], "distinct_veh": g["distinct_veh"],
                            "distinct_ped": g["distinct_ped"], "distinct_ped_2x": g["distinct_ped_2x"]})
        for c in ("veh_per_frame", "frames_ge2_veh", "cyc_per_frame", "ped_per_frame"):
            out[c] = g[c] / g["frames"]
        out["near_dup_rate"] = g["dups"] / (g["frames"] - runs)
        print("\nby scenario and condition (frame-weighted)")
        print(out.reset_index().to_string(index=False, float_format=lambda v: f"{v:.3f}"))


if __name__ == "__main__":
    main()
