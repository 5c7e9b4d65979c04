"""The Markdown table helpers every report is built from (evaluation.markdown): exact lines on hand-made rows."""

from __future__ import annotations

import pytest

from evaluation.markdown import md_table, percent, pr_table


def test_md_table_lines_and_alignment():
    assert md_table(["a", "b"], [["1", "2"], ["3", "4"]]) == ["| a | b |", "|---|---|", "| 1 | 2 |", "| 3 | 4 |"]
    assert md_table(["a", "b"], [], align="lr") == ["| a | b |", "|---|---:|"]
    with pytest.raises(ValueError, match="one of l, r per column"):
        md_table(["a", "b"], [], align="l")


def test_percent_marks_undefined_values():
    assert [percent(0.5), percent(1 / 3), percent(0.0), percent(None), percent(-1.0)] == ["50.0", "33.3", "0.0", "–",
                                                                                          "–"]
    assert percent(None, "-") == "-" and percent(-1.0, "n/a") == "n/a" and percent(0.12345, decimals=2) == "12.35"


def test_pr_table_rows_columns_and_missing_cells():
    rows = [{"group": "all", "iou": 0.5, "precision": 0.5, "recall": 0.25},
            {"group": "all", "iou": 0.7, "precision": None, "recall": 0.0},
            {"group": "night", "iou": 0.5, "precision": 1.0, "recall": 1.0}]  # night at 0.7 missing
    assert pr_table(rows, "group", [0.5, 0.7], label="condition", undefined="-") == [
        "| condition | P@0.5 | R@0.5 | P@0.7 | R@0.7 |", "|---|---|---|---|---|",
        "| all | 50.0 | 25.0 | - | 0.0 |", "| night | 100.0 | 100.0 | - | - |"]
    assert pr_table(rows, "group", [0.7], recall_only=True) == ["| group | R@0.7 |", "|---|---|", "| all | 0.0 |",
                                                                "| night | – |"]
