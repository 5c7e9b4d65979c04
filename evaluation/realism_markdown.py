"""realism.md of the realism gauge, from its metrics dict (what metrics.json holds) only, with the table helpers of
:mod:`evaluation.markdown`."""

from __future__ import annotations

from typing import Any

from evaluation.markdown import md_table, percent
from evaluation.realism import transmittance

DASH = "-"


def _pct(value: float | None) -> str:
    return percent(value, DASH)


def _num(value: float | None, digits: int = 1) -> str:
    return DASH if value is None else f"{value:.{digits}f}"


def _groups(metrics: dict[str, Any]) -> list[str]:
    """The image groups in row order: each value, then ``all``."""
    values = list(dict.fromkeys(r["group"] for r in metrics["rows"]))
    return [v for v in values if v != "all"] + ["all"]


def summary_table(metrics: dict[str, Any], luma: dict[str, Any] | None) -> list[str]:
    """One line per image group: AP50, recall and precision (%) of each class group at >= 30 px, the mean luma and
    the objects >= 30 px per frame."""
    rows = {(r["class_group"], r["group"]): r for r in metrics["rows"] if r["height_px"] == "30+"}
    classes = list(metrics["class_groups"])
    header = [metrics["group_by"], "images"]
    for c in classes:
        header += [f"{c} AP50", f"{c} R", f"{c} P"]
    header += ["mean luma", *(f"{c} / frame" for c in classes)]
    body = []
    per_frame = metrics["objects_per_frame"]["by_group"]
    for g in _groups(metrics):
        line = [g, str(rows[(classes[0], g)]["images"])]
        for c in classes:
            r = rows[(c, g)]
            line += [_pct(r["ap50"]), _pct(r["recall"]), _pct(r["precision"])]
        line += [_num(luma[g]["mean"]) if luma and g in luma else DASH]
        line += [_num(per_frame[g][c], 2) for c in classes]
        body.append(line)
    return md_table(header, body, "l" + "r" * (len(header) - 1))


def group_table(metrics: dict[str, Any], class_group: str) -> list[str]:
    """Per image group and box height: objects and frames, AP50, recall, precision, recall per object."""
    rows = [r for r in metrics["rows"] if r["class_group"] == class_group]
    header = [metrics["group_by"], "height px", "boxes", "AP50", "recall", "precision", "objects", "found any",
              "found most", "mean share"]
    body = []
    for g in _groups(metrics):
        for r in (r for r in rows if r["group"] == g):
            body.append([g, r["height_px"], str(r["gt"]), _pct(r["ap50"]), _pct(r["recall"]), _pct(r["precision"]),
                         str(r["objects"]), _pct(r["object_recall_any"]), _pct(r["object_recall_most"]),
                         _pct(r["object_mean_share"])])
    return md_table(header, body, "ll" + "r" * (len(header) - 2))


def person_table(metrics: dict[str, Any]) -> list[str]:
    """The people's recall by who they are (annotations' ``person``), per image group and box height."""
    header = [metrics["group_by"], "height px", "person", "boxes", "recall", "objects", "found any", "found most"]
    order = _groups(metrics)
    rows = sorted(metrics.get("people_by_person", []), key=lambda r: order.index(r["group"]))
    body = [[r["group"], r["height_px"], r["person"], str(r["gt"]), _pct(r["recall"]), str(r["objects"]),
             _pct(r["object_recall_any"]), _pct(r["object_recall_most"])] for r in rows]
    return md_table(header, body, "lll" + "r" * (len(header) - 3))


def distance_table(metrics: dict[str, Any], class_group: str = "vehicles") -> list[str]:
    """Recall (%) of ``class_group`` by distance bin per image group (objects of every size; boxes in brackets),
    and each visibility's transmittance at the bin's centre."""
    rows = [r for r in metrics["distance"]["rows"] if r["class_group"] == class_group]
    groups = [g for g in _groups(metrics) if g != "all"]
    visibility = metrics["distance"]["visibility_m"]
    header = ["distance m", *groups, *(f"T {g} (V {v:g} m)" for g, v in visibility.items())]
    cells = {(r["group"], r["bin"]): r for r in rows}
    body = []
    for b in dict.fromkeys(r["bin"] for r in rows):
        line = [b]
        for g in groups:
            r = cells[(g, b)]
            line.append(f"{_pct(r['recall'])} ({r['gt']})")
        lo, hi = next((r["lo_m"], r["hi_m"]) for r in rows if r["bin"] == b)
        centre = lo if hi is None else (lo + hi) / 2
        line += [_num(transmittance(centre, v), 3) for v in visibility.values()]
        body.append(line)
    return md_table(header, body, "l" + "r" * (len(header) - 1))


def realism_markdown(metrics: dict[str, Any], title: str = "Realism report") -> str:
    """realism.md: the summary, one table per class group, recall by distance, the luma, the contact sheets."""
    thr = metrics["score_threshold"]
    luma = metrics.get("luma")
    groups = ", ".join(f"{g}: {'/'.join(c)}" for g, c in metrics["class_groups"].items())
    lines = [
        f"# {title}", "",
        f"A detector's AP50, recall and precision (%) at score >= {thr:g} and IoU >= {metrics['iou_threshold']:g}, "
        f"class-agnostic within each class group ({groups}), per {metrics['group_by']}. Definitions: "
        "evaluation/README.md, \"Realism\".", "",
        f"## Summary: objects >= 30 px per {metrics['group_by']}", "", *summary_table(metrics, luma), "",
        "Mean luma: the mean 8-bit luma (BT.601) of the scored frames. `/ frame`: objects >= 30 px tall per frame.",
    ]
    if luma and "night" in luma and "morning" in luma and luma["morning"]["mean"]:
        ratio = luma["night"]["mean"] / luma["morning"]["mean"]
        lines += ["", f"Night's mean luma is {ratio:.2f} of the morning's ({luma['night']['mean']:.1f} vs "
                      f"{luma['morning']['mean']:.1f})."]
    for group in metrics["class_groups"]:
        lines += ["", f"## {group}", "",
                  "Per box height; *boxes*: object-frames counted; *objects*: distinct tracks; *found any / most*: "
                  "share of objects found in at least one / more than half of their frames; *mean share*: mean over "
                  "objects of the share of their frames found.", "", *group_table(metrics, group)]
    if metrics.get("people_by_person"):
        lines += ["", "## People by who they are", "",
                  "Recall of the people (annotations' `person`: adult, teen, child, wheelchair user); precision has no "
                  "row here, a false detection being nobody.", "", *person_table(metrics)]
    lines += ["", "## Vehicles: recall (%) by distance (objects of every size; object-frames in brackets)", "",
              "T: Koschmieder's transmittance exp(-3.912 d / V) at the bin's centre.", "",
              *distance_table(metrics), "", "![recall by distance](recall_by_distance.png)"]
    missed = metrics.get("missed_objects", {})
    if missed:
        lines += ["", "## Missed objects (>= 30 px, found in none of their frames)", ""]
        lines += md_table(["class group", "missed objects", "shown", "contact sheet"],
                          [[g, str(m["missed"]), str(m["shown"]), f"[{m['sheet']}]({m['sheet']})" if m["sheet"]
                            else DASH] for g, m in missed.items()])
    return "\n".join(lines) + "\n"
