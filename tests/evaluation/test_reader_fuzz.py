"""Property: the evaluation readers never raise a traceback-worthy exception (issue 24).

Small valid COCO ground truth / results and KITTI label directories are mutated (keys dropped, values replaced by
wrong types, NaN, infinities, huge or negative numbers, duplicated or unknown ids, other top levels, truncated or
flipped bytes, binary garbage). :func:`evaluation.evaluate` then either scores them without an error or raises the
readers' validation error (:class:`InputError` for COCO, :class:`KittiFormatError` for KITTI, both ValueErrors whose
message names the file), never KeyError, IndexError, TypeError, a bare numpy ValueError and the like.
"""

from __future__ import annotations

import copy
import json
import math
import tempfile
import warnings
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from evaluation import evaluate
from evaluation.kitti.readers import KittiFormatError
from evaluation.validate import InputError
from pipeline.stages.cli import main as cli_main

SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
VALID_ERRORS = (InputError, KittiFormatError)

GT: dict[str, Any] = {
    "images": [{"id": 1, "file_name": "a.png", "width": 100, "height": 80, "condition": "noon"},
               {"id": 2, "file_name": "b.png", "width": 100, "height": 80, "condition": "night"}],
    "categories": [{"id": 3, "name": "car"}, {"id": 1, "name": "person"}],
    "annotations": [
        {"id": 1, "image_id": 1, "category_id": 3, "bbox": [10, 10, 30, 20], "area": 600.0, "iscrowd": 0,
         "distance_m": 12.5, "occlusion": 0.2},
        {"id": 2, "image_id": 1, "category_id": 1, "bbox": [50, 20, 10, 30], "area": 300.0, "iscrowd": 0,
         "distance_m": 40.0, "occlusion": 0.0},
        {"id": 3, "image_id": 2, "category_id": 3, "bbox": [0, 0, 60, 40], "area": 2400.0, "iscrowd": 1},
    ],
}
RESULTS: list[dict[str, Any]] = [
    {"image_id": 1, "category_id": 3, "bbox": [11, 9, 29, 21], "score": 0.9},
    {"image_id": 1, "category_id": 1, "bbox": [48, 22, 12, 28], "score": 0.6},
    {"image_id": 2, "category_id": 3, "bbox": [5, 5, 20, 20], "score": 0.3},
    {"image_id": 2, "category_id": 44, "bbox": [1, 1, 2, 2], "score": 0.2},
]

NASTY = st.sampled_from([
    None, True, False, 0, -1, 1, 2, 3, 44, 1.5, -0.5, 1e-300, 10**30, -(10**30), 2**63, -(2**63) - 1, 1e308, -1e308,
    math.nan, math.inf, -math.inf, "", "x", "1", "nan", [], [1], [1, 2], [0, 0, 10, 10], [0, 0, -1, 5], [0, 0, 0, 0],
    [math.nan, 0, 1, 1], [1e308, 1e308, 1e308, 1e308], [[1]], [0, 0, 10, "10"], {}, {"id": 1},
])


# Values the readers accept, at the edges of what scoring must survive (zero-size and astronomically large boxes,
# extreme scores): drawn as often as the nasty ones, so that many examples reach the metrics.
EDGE = st.sampled_from([
    0, 0.0, 1e-300, 1e300, -1e300, 1e308, 10**30, [0, 0, 0, 0], [-5, -5, 1e-9, 1e-9], [1e300, 1e300, 1e300, 1e300],
    [0, 0, 1e308, 1e308], [-1e308, -1e308, 1e308, 1e308], 1, 2, 3,
])
VALUES = st.one_of(NASTY, EDGE)


def _containers(data: Any) -> list[Any]:
    """Every non-empty dict and list in a parsed JSON document, the document first."""
    found = [data] if isinstance(data, (dict, list)) and data else []
    children = data.values() if isinstance(data, dict) else data if isinstance(data, list) else ()
    return found + [c for child in children for c in _containers(child)]


def _mutate(data: Any, draw) -> Any:
    """One structural mutation of a parsed JSON document: in one of its objects or lists (each as likely), drop,
    replace or duplicate an entry."""
    containers = _containers(data)
    if not containers:
        return copy.deepcopy(draw(VALUES))  # a copy: later mutations must not change the strategy's own values
    target = draw(st.sampled_from(containers))
    key = draw(st.sampled_from(list(target) if isinstance(target, dict) else range(len(target))))
    action = draw(st.sampled_from(["drop", "replace", "replace", "duplicate"]))
    if action == "drop":
        del target[key]
    elif action == "duplicate" and isinstance(target, list):
        target.append(copy.deepcopy(target[key]))
    else:
        target[key] = copy.deepcopy(draw(VALUES))
    return data


@st.composite
def _document(draw, base: Any) -> bytes:
    """A mutated ``base``, serialised; sometimes damaged at the byte level afterwards."""
    data = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        data = _mutate(data, draw)
    if draw(st.integers(0, 7)) == 0:
        data = draw(st.sampled_from([data, {"images": data}, [data], "text", 3, None]))
    raw = json.dumps(data).encode()  # NaN and Infinity as Python's json writes them (and json.load reads)
    damage = draw(st.sampled_from(["none"] * 5 + ["truncate", "flip", "garbage"]))
    if damage == "truncate":
        raw = raw[: draw(st.integers(0, max(len(raw) - 1, 0)))]
    elif damage == "flip" and raw:
        i = draw(st.integers(0, len(raw) - 1))
        raw = raw[:i] + bytes([raw[i] ^ draw(st.integers(1, 255))]) + raw[i + 1:]
    elif damage == "garbage":
        raw = draw(st.binary(max_size=64))
    return raw


def _evaluate_or_clear_error(gt: Path, det: Path) -> None:
    """Score; a validation error is fine, anything else fails the property (pytest shows its traceback)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # NaN IoUs of zero-size boxes are scored, not errors
        try:
            evaluate(gt, det, group_by="condition" if gt.suffix == ".json" else None)
        except VALID_ERRORS as exc:
            assert str(exc).strip(), "an empty error message"
            event("refused")  # --hypothesis-show-statistics: how many examples reach the metrics
        else:
            event("scored")


def _one_or_both(document: st.SearchStrategy[bytes], valid: bytes) -> st.SearchStrategy[bytes]:
    """Each input is the valid one half the time, so that the other input's mutations are what is tested."""
    return st.one_of(st.just(valid), document)


@SETTINGS
@given(gt=_one_or_both(_document(GT), json.dumps(GT).encode()),
       results=_one_or_both(_document(RESULTS), json.dumps(RESULTS).encode()))
def test_coco_readers_accept_or_fail_clearly(gt: bytes, results: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "gt.json").write_bytes(gt)
        (Path(tmp) / "res.json").write_bytes(results)
        _evaluate_or_clear_error(Path(tmp) / "gt.json", Path(tmp) / "res.json")


FINITE = st.floats(allow_nan=False, allow_infinity=False)
SIZE = st.floats(min_value=0.0, allow_infinity=False)
BOX = st.tuples(FINITE, FINITE, SIZE, SIZE).map(list)


@st.composite
def _valid_pair(draw) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """GT and results the readers accept, with any finite coordinates, sizes (zero, subnormal, near 1.8e308),
    areas and scores, and up to 30 more results: what scoring must survive without an error."""
    gt, results = copy.deepcopy(GT), copy.deepcopy(RESULTS)
    for ann in gt["annotations"]:
        if draw(st.booleans()):
            ann["bbox"], ann["area"] = draw(BOX), draw(SIZE)
    results += draw(st.lists(st.fixed_dictionaries({"image_id": st.sampled_from([1, 2]),
                                                    "category_id": st.sampled_from([1, 3, 44]),
                                                    "bbox": BOX, "score": FINITE}), max_size=30))
    for res in results:
        if draw(st.booleans()):
            res["bbox"], res["score"] = draw(BOX), draw(FINITE)
    return gt, results


@SETTINGS
@given(pair=_valid_pair())
def test_accepted_coco_inputs_at_the_edges_are_scored_without_an_error(pair) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "gt.json").write_text(json.dumps(pair[0]))
        (Path(tmp) / "res.json").write_text(json.dumps(pair[1]))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # overflowing areas give inf/NaN IoUs: scored as such
            evaluate(Path(tmp) / "gt.json", Path(tmp) / "res.json", group_by="condition")


KITTI_GT = ["Car 0.00 0 -1.58 587.01 173.33 614.12 200.12 1.65 1.67 3.64 -0.65 1.71 46.70 -1.59",
            "Pedestrian 0.00 1 0.21 423.17 173.67 433.17 224.03 1.87 0.50 0.90 -5.83 1.71 27.96 0.00",
            "DontCare -1 -1 -10 503.89 169.71 590.61 190.13 -1 -1 -1 -1000 -1000 -1000 -10"]
KITTI_DET = ["Car -1 -1 -1.50 585.0 170.0 616.0 201.0 1.60 1.70 3.60 -0.60 1.70 46.0 -1.55 0.93",
             "Pedestrian -1 -1 0.20 420.0 175.0 434.0 225.0 1.80 0.55 0.85 -5.80 1.70 28.0 0.05 0.71",
             "Cyclist -1 -1 0.00 100.0 150.0 140.0 200.0 1.70 0.60 1.70 -10.0 1.70 20.0 0.00 0.40"]
TOKENS = st.sampled_from(["nan", "NaN", "inf", "-inf", "1e400", "-1e400", "x", "", "-1", "0", "1e300", "-1e300",
                          "4", "2.5", "Truck", "DontCare", "Ünïcode", "١", "1_000", "0x10", "1e5", "-0"])


@st.composite
def _kitti_file(draw, base: list[str]) -> bytes:
    rows = [line.split() for line in base]
    for _ in range(draw(st.integers(0, 3))):
        action = draw(st.sampled_from(["token", "token", "drop_token", "add_token", "drop_line", "copy_line"]))
        if not rows:
            break
        r = draw(st.integers(0, len(rows) - 1))
        if action == "token" and rows[r]:
            rows[r][draw(st.integers(0, len(rows[r]) - 1))] = draw(TOKENS)
        elif action == "drop_token" and rows[r]:
            del rows[r][draw(st.integers(0, len(rows[r]) - 1))]
        elif action == "add_token":
            rows[r].append(draw(TOKENS))
        elif action == "drop_line":
            del rows[r]
        else:
            rows.append(list(rows[r]))
    raw = "\n".join(" ".join(row) for row in rows).encode()
    damage = draw(st.sampled_from(["none"] * 5 + ["truncate", "flip", "garbage", "empty"]))
    if damage == "truncate":
        raw = raw[: draw(st.integers(0, max(len(raw) - 1, 0)))]
    elif damage == "flip" and raw:
        i = draw(st.integers(0, len(raw) - 1))
        raw = raw[:i] + bytes([raw[i] ^ draw(st.integers(1, 255))]) + raw[i + 1:]
    elif damage == "garbage":
        raw = draw(st.binary(max_size=64))
    elif damage == "empty":
        raw = b""
    return raw


@SETTINGS
@given(gt=_one_or_both(_kitti_file(KITTI_GT), "\n".join(KITTI_GT).encode()),
       det=_one_or_both(_kitti_file(KITTI_DET), "\n".join(KITTI_DET).encode()))
def test_kitti_readers_accept_or_fail_clearly(gt: bytes, det: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for name, raw in (("gt", gt), ("det", det)):
            (Path(tmp) / name).mkdir()
            (Path(tmp) / name / "000000.txt").write_bytes(raw)
        _evaluate_or_clear_error(Path(tmp) / "gt", Path(tmp) / "det")


def _cli(argv: list[str]) -> int:
    try:
        return cli_main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


# Inputs the readers refuse, through the real CLI: exit 2, one message naming the file, no traceback.
CLI_CASES = [
    ("gt.json", b'{"images": [{"id": 1}], "categories": [], "annotations": [', "gt.json: not valid JSON"),
    ("gt.json", b"\xff\xfe\x00garbage\x89PNG", "gt.json"),
    ("res.json", json.dumps([{"image_id": 1, "category_id": 3, "bbox": [0, 0, 1, 1], "score": [0.5, 1]}]).encode(),
     "res.json: results[0]: field 'score'"),
    ("res.json", json.dumps([{"image_id": 7, "category_id": 3, "bbox": [0, 0, 1, 1], "score": 0.5}]).encode(),
     "res.json: results[0]: field 'image_id' is 7"),
    ("res.json", b'[{"image_id": 1, "category_id": 3, "bbox": [0, 0, NaN, 1], "score": 0.5}]',
     "res.json: results[0]: field 'bbox'"),
    ("gt/000000.txt", b"Car 0 0 0 1 2 3\n", "gt/000000.txt:1: field '<columns>'"),
    ("det/000000.txt", b"\x00\x9f\x92\x96 binary\n", "det/000000.txt"),
    ("det/000000.txt", (KITTI_DET[0].rsplit(" ", 1)[0] + " nan\n").encode(), "det/000000.txt:1: field 'score'"),
]


@pytest.mark.parametrize(("name", "raw", "names"), CLI_CASES, ids=[f"{c[0]}: {c[2]}" for c in CLI_CASES])
def test_cli_refuses_a_mutated_input_with_exit_2_and_no_traceback(tmp_path, monkeypatch, capsys, name, raw, names):
    monkeypatch.chdir(tmp_path)
    Path("gt.json").write_text(json.dumps(GT))
    Path("res.json").write_text(json.dumps(RESULTS))
    for folder, lines in (("gt", KITTI_GT), ("det", KITTI_DET)):
        Path(folder).mkdir()
        Path(folder, "000000.txt").write_text("\n".join(lines) + "\n")
    Path(name).write_bytes(raw)
    gt, det = ("gt", "det") if "/" in name else ("gt.json", "res.json")
    rc = _cli(["evaluate", "--gt", gt, "--detections", det, "--out", "eval"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    first = next(line for line in err.splitlines() if line.startswith("roadsynth evaluate: error: "))
    assert names in first, err
    assert not Path("eval").exists()
