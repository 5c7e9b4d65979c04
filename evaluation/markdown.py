"""Markdown tables of evaluation results, and report.md of an evaluation.

The table helpers (:func:`md_table`, :func:`percent`, :func:`pr_table`) are the one Markdown table
implementation of the project: the evaluate stage's report.md (:func:`report_markdown`), the KITTI summary
and the report stage's report.md (``pipeline/stages/report.py``) are all built from them. Everything here
reads only the metrics dict (what metrics.json holds) and the KITTI summary text, never the inputs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

UNDEFINED = "–"  # an undefined share (no detections, no ground truth) in the evaluate stage's report


def percent(value: float | None, undefined: str = UNDEFINED, *, decimals: int = 1) -> str:
    """A share as a percentage with ``decimals`` decimals; ``undefined`` where it is None or negative (COCO's -1)."""
    return undefined if value is None or value < 0 else f"{100 * value:.{decimals}f}"


def md_table(header: Sequence[str], rows: Sequence[Sequence[str]], align: str | None = None) -> list[str]:
    """The lines of a Markdown table: header, rule, one line per row (cells already text).

    ``align`` has one letter per column, ``l`` (the rule ``---``: the renderer's default, left) or ``r``
    (``---:``, right-aligned); None leaves every column at the default.
    """
    align = align or "l" * len(header)
    if len(align) != len(header) or set(align) - {"l", "r"}:
        raise ValueError(f"align {align!r}: expected one of l, r per column ({len(header)} columns)")
    rule = "|" + "|".join("---:" if a == "r" else "---" for a in align) + "|"
    return ["| " + " | ".join(header) + " |", rule, *("| " + " | ".join(row) + " |" for row in rows)]


def pr_table(rows: Sequence[dict[str, Any]], key: str, ious: Sequence[float], *, recall_only: bool = False,
             label: str | None = None, undefined: str = UNDEFINED) -> list[str]:
    """Precision and recall (%) per IoU threshold of the metrics.json table rows, one line per value of
    ``rows[i][key]`` in first-seen order; columns ``P@t R@t`` per threshold (``R@t`` only with
    ``recall_only``). ``label`` heads the first column (default: ``key``); a missing or undefined cell is
    ``undefined``."""
    labels = list(dict.fromkeys(r[key] for r in rows))
    cells = {(r[key], r["iou"]): r for r in rows}
    header = [key if label is None else label]
    for t in ious:
        header += [f"R@{t:g}"] if recall_only else [f"P@{t:g}", f"R@{t:g}"]
    body = []
    for name in labels:
        line = [str(name)]
        for t in ious:
            r = cells.get((name, t))
            vals = [] if recall_only else [percent(r and r["precision"], undefined)]
            line += [*vals, percent(r and r["recall"], undefined)]
        body.append(line)
    return md_table(header, body)


def _table_section(table: dict[str, Any]) -> list[str]:
    rows, ious = table["rows"], table["iou_thresholds"]
    plain = [r for r in rows if ":" not in r["group"] or r["group"] == "all"]
    binned = [r for r in rows if r not in plain]
    out = [f"## Precision and recall (%) by IoU threshold, score >= {table['score_threshold']:g}", ""]
    out += [*pr_table([r for r in plain if r["class"] == "all"], "group", ious), ""]
    out += ["### Per class (all images)", ""]
    out += [*pr_table([r for r in plain if r["group"] == "all"], "class", ious), ""]
    if binned:
        out += ["### Recall (%) by ground-truth distance and occlusion (all classes)", ""]
        out += [*pr_table([r for r in binned if r["class"] == "all"], "group", ious, recall_only=True), ""]
    best = table.get("f1_optimal", [])
    if best:
        out += ["### F1-optimal score threshold", ""]
        out += [
            *md_table(
                ["group", "IoU", "score threshold", "precision", "recall", "F1"],
                [
                    [
                        b["group"],
                        f"{b['iou']:g}",
                        UNDEFINED if b["score_threshold"] is None else f"{b['score_threshold']:.4g}",
                        percent(b["precision"]),
                        percent(b["recall"]),
                        percent(b["f1"]),
                    ]
                    for b in best
                ],
            ),
            "",
        ]
    return out


def _coco_section(coco: dict[str, Any]) -> list[str]:
    out = ["## COCO AP/AR (pycocotools-identical)", ""]
    out += md_table(["stat", "value"], [[n, f"{v:.4f}"] for n, v in zip(coco["names"], coco["stats"], strict=True)])
    out += ["", "### Per class", ""]
    out += md_table(
        ["class", "AP", "AP50", "AP75", "AR100", "GT", "detections"],
        [
            [
                name,
                percent(c["ap"]),
                percent(c["ap50"]),
                percent(c["ap75"]),
                percent(c["ar100"]),
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
    out += md_table(
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


def report_markdown(metrics: dict[str, Any], kitti_markdown: str | None) -> str:
    """report.md of an evaluation: the paper-style table (rows = groups, columns = precision and recall per IoU
    threshold), per-class and per-bin tables, the COCO and KITTI summaries, the error breakdown and the ignored
    counts, from the metrics dict (metrics.json) and the KITTI summary text."""
    m = metrics
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
        out += [kitti_markdown or "", ""]
    out += ["## Ignored and skipped items", ""]
    out += md_table(["item", "count"], [[k, _count(v)] for k, v in sorted(m["ignored"].items())])
    return "\n".join(out) + "\n"
