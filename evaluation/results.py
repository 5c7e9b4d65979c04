"""The results of an evaluation (:class:`Evaluation`, what :func:`evaluation.evaluate` returns) and how they
are written: ``metrics.json`` (dvc metrics), ``plots/`` (dvc plots data + PNG), ``report.md``.

Plots read only the saved curve data (the render step never recomputes a metric):

- ``plots/pr_iou{T}.json`` and ``plots/pr_iou{T}_{group}.csv``: the PR curve per IoU threshold and
  group (columns ``score, precision, recall, tp, fp, f1``; one point per distinct score, subsampled);
- ``plots/table.csv``: precision and recall by IoU threshold per group (class ``all``);
- ``plots/coco_pr.csv``: COCO's interpolated precision at the 101 recall thresholds, all classes averaged,
  at IoU 0.5, 0.75 and 0.5:0.95 (area ``all``, the largest max_dets);
- PNG renderings of the same data (matplotlib, Agg), when asked (``png``; the CLI's ``--png``).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from evaluation.markdown import report_markdown

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """Results of :func:`evaluation.evaluate`.

    Attributes:
        metrics: the content of metrics.json (keys table, coco, kitti, errors, ignored).
        curves: PR curve data per group and IoU threshold (what plots read), empty without the table.
        coco_precision: (T, R, K, A, M) float64 pycocotools-layout precision, or None without COCO.
        kitti_markdown: the KITTI summary for the report, or None.
    """

    metrics: dict[str, Any]
    curves: list[dict[str, Any]]
    coco_precision: np.ndarray | None
    kitti_markdown: str | None

    def write(self, out_dir: str | Path, *, png: bool = True) -> None:
        """Write metrics.json, plots/ (data; PNG renderings too with ``png``) and report.md into ``out_dir``.

        PNG rendering imports matplotlib (about half a second), so it happens only when asked.
        """
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "metrics.json").write_text(json.dumps(_clean(self.metrics), indent=2, sort_keys=True) + "\n")
        plots = out_dir / "plots"
        plots.mkdir(exist_ok=True)
        write_plot_data(self, plots)
        if png:
            from evaluation.plots import render_pngs

            render_pngs(plots)
        (out_dir / "report.md").write_text(report_markdown(self.metrics, self.kitti_markdown))
        log.info("wrote metrics.json, plots/ and report.md to %s", out_dir)


def _clean(value: Any) -> Any:
    """JSON-safe copy: NaN/inf become null, numpy scalars become Python numbers."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "_"


def _write_csv(path: Path, header: list[str], rows: list[list[Any]]) -> None:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows([["" if v is None else v for v in row] for row in rows])


def write_plot_data(evaluation: Evaluation, plots: Path) -> list[Path]:
    """Write the CSV/JSON plot data; returns the files written."""
    written = []
    keys = ["score", "precision", "recall", "tp", "fp", "f1"]
    by_iou: dict[float, list[dict[str, Any]]] = {}
    for curve in evaluation.curves:
        by_iou.setdefault(curve["iou"], []).append(curve)
        path = plots / f"pr_iou{curve['iou']:.2f}_{_slug(curve['group'])}.csv"
        _write_csv(path, keys, [list(p) for p in zip(*(curve[k] for k in keys), strict=True)])
        written.append(path)
    for iou, curves in by_iou.items():
        path = plots / f"pr_iou{iou:.2f}.json"
        points = [{"group": c["group"], **{k: c[k][i] for k in keys}} for c in curves for i in range(len(c["score"]))]
        path.write_text(json.dumps(_clean(points), indent=1) + "\n")
        written.append(path)
    table = evaluation.metrics.get("table", {})
    if "rows" in table:
        rows = [[r["group"], r["iou"], r["precision"], r["recall"], r["f1"]] for r in table["rows"]
                if r["class"] == "all"]
        _write_csv(plots / "table.csv", ["group", "iou", "precision", "recall", "f1"], rows)
        written.append(plots / "table.csv")
    if evaluation.coco_precision is not None:
        written.append(_write_coco_pr(evaluation.coco_precision, plots / "coco_pr.csv"))
    return written


def _coco_curve(precision: np.ndarray, t: slice | list[int]) -> np.ndarray:
    """(R,) mean over defined (> -1) entries of precision[t, :, :, area all, largest max_dets], NaN if none."""
    p = precision[t, :, :, 0, -1]  # (T', R, K)
    p = p.transpose(1, 0, 2).reshape(p.shape[1], -1)  # (R, T'*K)
    defined = p > -1
    total = np.where(defined, p, 0.0).sum(axis=1)
    count = defined.sum(axis=1)
    return np.where(count > 0, total / np.maximum(count, 1), np.nan)


def _write_coco_pr(precision: np.ndarray, path: Path) -> Path:
    recall = np.linspace(0.0, 1.0, precision.shape[1])
    curves = {"iou0.50": _coco_curve(precision, [0]), "iou0.75": _coco_curve(precision, [5]),
              "iou0.50:0.95": _coco_curve(precision, slice(None))}
    rows = [[name, float(r), None if np.isnan(p) else float(p)]
            for name, curve in curves.items() for r, p in zip(recall, curve, strict=True)]
    _write_csv(path, ["iou", "recall", "precision"], rows)
    return path
