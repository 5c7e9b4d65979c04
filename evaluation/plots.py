"""PNG renderings of the plot data in ``plots/`` (matplotlib, Agg backend; reads only the saved files)."""

from __future__ import annotations

import csv
import json
import logging
from collections import defaultdict
from pathlib import Path

log = logging.getLogger(__name__)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _float(text: str) -> float:
    return float(text) if text != "" else float("nan")


def _read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def render_pngs(plots: Path) -> list[Path]:
    """Render every known plot data file in ``plots`` to PNG beside it; returns the PNGs written."""
    plt = _pyplot()
    written = []
    for path in sorted(plots.glob("pr_iou*.json")):
        points = json.loads(path.read_text())
        by_group: dict[str, list[dict]] = defaultdict(list)
        for p in points:
            by_group[p["group"]].append(p)
        fig, ax = plt.subplots(figsize=(5, 4))
        for group, pts in by_group.items():
            ax.plot([p["recall"] for p in pts], [p["precision"] for p in pts], label=group)
        ax.set(xlabel="recall", ylabel="precision", xlim=(0, 1), ylim=(0, 1.02), title=path.stem.replace("_", " "))
        ax.legend(fontsize="small")
        written.append(_save(plt, fig, path.with_suffix(".png")))
    table = plots / "table.csv"
    if table.exists():
        rows = _read_csv(table)
        fig, ax = plt.subplots(figsize=(5, 4))
        for group in dict.fromkeys(r["group"] for r in rows):
            sel = [r for r in rows if r["group"] == group]
            iou = [_float(r["iou"]) for r in sel]
            ax.plot(iou, [_float(r["precision"]) for r in sel], "o-", label=f"{group} precision")
            ax.plot(iou, [_float(r["recall"]) for r in sel], "s--", label=f"{group} recall")
        ax.set(xlabel="IoU threshold", ylabel="value", ylim=(0, 1.02), title="precision and recall by IoU")
        ax.legend(fontsize="x-small")
        written.append(_save(plt, fig, table.with_suffix(".png")))
    coco = plots / "coco_pr.csv"
    if coco.exists():
        rows = _read_csv(coco)
        fig, ax = plt.subplots(figsize=(5, 4))
        for name in dict.fromkeys(r["iou"] for r in rows):
            sel = [r for r in rows if r["iou"] == name]
            ax.plot([_float(r["recall"]) for r in sel], [_float(r["precision"]) for r in sel], label=f"IoU {name[3:]}")
        ax.set(xlabel="recall", ylabel="interpolated precision", xlim=(0, 1), ylim=(0, 1.02), title="COCO")
        ax.legend(fontsize="small")
        written.append(_save(plt, fig, coco.with_suffix(".png")))
    return written


def _save(plt, fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
