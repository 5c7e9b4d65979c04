"""report.md: the paper-style table (rows = groups, columns = precision and recall per IoU threshold),
per-class and per-bin tables, the COCO and KITTI summaries, the error breakdown and the ignored counts.
Reads only the metrics dict (and the KITTI summary text)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    import numpy as np


class EvaluationData(Protocol):
    """What the report and the writers (:mod:`evaluation.outputs`) read of an evaluation; the results of
    :func:`evaluation.evaluate` (:class:`evaluation.api.Evaluation`) are one. A protocol rather than an import of
    that class, so that evaluation's modules import one way (api -> outputs -> report), without a circle."""

    @property
    def metrics(self) -> dict[str, Any]: ...
    @property
    def curves(self) -> list[dict[str, Any]]: ...
    @property
    def coco_precision(self) -> np.ndarray | None: ...
    @property
    def kitti_markdown(self) -> str | None: ...


def _pct(value: float | None) -> str:
    return "–" if value is None or value < 0 else f"{100 * value:.1f}"


def _md_table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return lines + ["| " + " | ".join(row) + " |" for row in rows]


def _pr_table(rows: list[dict[str, Any]], key: str, ious: list[float], recall_only: bool = False) -> list[str]:
    labels = list(dict.fromkeys(r[key] for r in rows))
    cells = {(r[key], r["iou"]): r for r in rows}
    header = [key]
    for t in ious:
        header += [f"R@{t:g}"] if recall_only else [f"P@{t:g}", f"R@{t:g}"]
    body = []
    for label in labels:
        line = [str(label)]
        for t in ious:
            r = cells.get((label, t))
            vals = [] if recall_only else [_pct(r and r["precision"])]
            line += [*vals, _pct(r and r["recall"])]
        body.append(line)
    return _md_table(header, body)


def _table_section(table: dict[str, Any]) -> list[str]:
    rows, ious = table["rows"], table["iou_thresholds"]
    plain = [r for r in rows if ":" not in r["group"] or r["group"] == "all"]
    binned = [r for r in rows if r not in plain]
    out = [f"## Precision and recall (%) by IoU threshold, score >= {table['score_threshold']:g}", ""]
    out += [*_pr_table([r for r in plain if r["class"] == "all"], "group", ious), ""]
    out += ["### Per class (all images)", ""]
    out += [*_pr_table([r for r in plain if r["group"] == "all"], "class", ious), ""]
    if binned:
        out += ["### Recall (%) by ground-truth distance and occlusion (all classes)", ""]
        out += [*_pr_table([r for r in binned if r["class"] == "all"], "group", ious, recall_only=True), ""]
    best = table.get("f1_optimal", [])
    if best:
        out += ["### F1-optimal score threshold", ""]
        out += [
            *_md_table(
                ["group", "IoU", "score threshold", "precision", "recall", "F1"],
                [
                    [
                        b["group"],
                        f"{b['iou']:g}",
                        "–" if b["score_threshold"] is None else f"{b['score_threshold']:.4g}",
                        _pct(b["precision"]),
                        _pct(b["recall"]),
                        _pct(b["f1"]),
                    ]
                    for b in best
                ],
            ),
            "",
        ]
    return out


def _coco_section(coco: dict[str, Any]) -> list[str]:
    out = ["## COCO AP/AR (pycocotools-identical)", ""]
    out += _md_table(["stat", "value"], [[n, f"{v:.4f}"] for n, v in zip(coco["names"], coco["stats"], strict=True)])
    out += ["", "### Per class", ""]
    out += _md_table(
        ["class", "AP", "AP50", "AP75", "AR100", "GT", "detections"],
        [
            [
                name,
                _pct(c["ap"]),
                _pct(c["ap50"]),
                _pct(c["ap75"]),
                _pct(c["ar100"]),
                str(c["num_gt"]),
                str(c["num_dt"]),
            ]
            for name, c in coco["per_class"].items()
        ],
    )
    return [*out, ""]


def _errors_section(errors: dict[str, Any]) -> list[str]:
    out = [f"## Errors at IoU {errors['iou']:g} (score >= {errors['score_threshold']:g})", ""]
    kinds = list(errors["counts"])
    out += _md_table(
        ["class", *kinds],
        [["all", *(str(errors["counts"][k]) for k in kinds)]]
        + [[name, *(str(c[k]) for k in kinds)] for name, c in errors["per_class"].items()],
    )
    return [*out, ""]


def _count(value: Any) -> str:
    """An ignored count, or counts by id (``id 10: 3, id 44: 1``)."""
    if isinstance(value, dict):
        return ", ".join(f"id {k}: {v}" for k, v in value.items()) or "none"
    return str(value)


def report_markdown(evaluation: EvaluationData) -> str:
    """The Markdown report of an evaluation."""
    m = evaluation.metrics
    out = ["# Detection evaluation", ""]
    sections = (("table", _table_section), ("coco", _coco_section), ("errors", _errors_section))
    for name, render in sections:
        if "skipped" in m[name]:
            out += [f"## {name}", "", f"Skipped: {m[name]['skipped']}.", ""]
        else:
            out += render(m[name])
    out += ["## KITTI", ""]
    if "skipped" in m["kitti"]:
        out += [f"Skipped: {m['kitti']['skipped']}.", ""]
    else:
        out += [evaluation.kitti_markdown or "", ""]
    out += ["## Ignored and skipped items", ""]
    out += _md_table(["item", "count"], [[k, _count(v)] for k, v in sorted(m["ignored"].items())])
    return "\n".join(out) + "\n"
