"""What an output folder of ``roadsynth evaluate`` scored, checked against what a later stage is given.

The evaluate stage records in its ``meta.json`` config the paths and sha256 digests of ``--gt`` and
``--detections`` and its ``--group-by``; the report stage reads the evaluation's table and must not
mix in other ground truth or detections, nor title the table by a key it was not grouped by.
"""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.core.digests import path_sha256

__all__ = ["check_evaluated_inputs"]


def _evaluated_config(eval_dir: Path) -> tuple[Path, dict]:
    """The evaluation's meta.json path and its recorded config."""
    path = eval_dir / "meta.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not found (--eval must be an output folder of `roadsynth evaluate`)")
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("stage") != "evaluate" or not isinstance(meta.get("config"), dict):
        stage = meta.get("stage") if isinstance(meta, dict) else None
        raise ValueError(f"{path}: stage is {stage!r}, expected 'evaluate' with a config mapping "
                         "(--eval must be an output folder of `roadsynth evaluate`)")
    return path, meta["config"]


def check_evaluated_inputs(eval_dir: Path, gt: Path, detections: Path, group_by: str | None) -> str:
    """Fail unless ``gt`` and ``detections`` are the files the evaluation in ``eval_dir`` scored and
    ``group_by`` (None: the evaluation's) is the key it grouped by; return the group-by key."""
    meta_path, config = _evaluated_config(eval_dir)
    for key, given in (("gt", gt), ("detections", detections)):
        recorded = config.get(f"{key}_sha256")
        if not isinstance(recorded, str):
            raise ValueError(f"{meta_path}: config.{key}_sha256 is missing: this evaluation does not record what it "
                             f"scored; re-run `roadsynth evaluate` so that the report can check its --{key}")
        if path_sha256(given) != recorded:
            raise ValueError(f"{given}: not the --{key} that {eval_dir} evaluated ({meta_path}: config.{key} = "
                             f"{config.get(key)!r}, config.{key}_sha256 = {recorded[:16]}..., this file differs)")
    evaluated = config.get("group_by")
    if evaluated is None:
        raise ValueError(f"{meta_path}: config.group_by is null: the evaluation has no per-group table; "
                         "run `roadsynth evaluate --group-by KEY` (e.g. condition) first")
    if group_by is not None and group_by != evaluated:
        raise ValueError(f"{meta_path}: config.group_by is {evaluated!r}, not {group_by!r} (report --group-by): "
                         f"the evaluation's table has rows per {evaluated!r} only")
    return evaluated
