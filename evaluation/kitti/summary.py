"""Markdown summary of a result of :func:`evaluation.kitti.evaluate_kitti`."""

from __future__ import annotations

from evaluation.markdown import md_table, percent

__all__ = ["kitti_summary_markdown"]

_METRIC_NAMES = {"bbox": "2D", "bev": "BEV", "3d": "3D", "aos": "AOS"}
_DIFFICULTIES = ("easy", "moderate", "hard")


def kitti_summary_markdown(result: dict) -> str:
    """A Markdown table: one row per (class, metric), AP_R40 and AP_R11 (percent) per difficulty.

    Args:
        result: the dict returned by evaluate_kitti.

    Returns:
        Markdown text ending with a newline.
    """
    settings = result["settings"]
    counts = result["counts"]
    header = ["class", "metric", "IoU >", *(f"{d} R40" for d in _DIFFICULTIES), *(f"{d} R11" for d in _DIFFICULTIES)]
    rows = []
    for cls, per_difficulty in result["results"].items():
        for metric in settings["metrics"]:
            threshold = settings["min_overlap"][cls]["bbox" if metric == "aos" else metric]
            aps = [percent(per_difficulty[d][metric][key], decimals=2) for key in ("ap_r40", "ap_r11")
                   for d in _DIFFICULTIES]
            rows.append([cls, _METRIC_NAMES[metric], f"{threshold:g}", *aps])
    lines = [
        f"KITTI AP ({result['mode']} mode), {counts['frames']} frames; percent; "
        "a detection matches when its overlap is strictly above the class threshold.",
        "",
        *md_table(header, rows, align="lll" + "r" * 6),
    ]
    gt_counts = ", ".join(f"{cls} {result['results'][cls]['moderate']['num_gt']}" for cls in result["results"])
    lines += ["", f"Ground truth counted at moderate difficulty: {gt_counts}."]
    lines += [f"Note: {note}" for note in result.get("notes", [])]
    return "\n".join(lines) + "\n"
