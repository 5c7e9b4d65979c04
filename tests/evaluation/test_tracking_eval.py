"""The tracking metrics (evaluation.tracking) against TrackEval run directly on the same MOTChallenge files.

TrackEval reads each case through its own ``MotChallenge2DBox`` dataset (MOT17 rules, pedestrian class) and its
``Evaluator``; ours reads the same files with evaluation.io_mot. Cases where the metrics could differ: identity
switches, fragmentations, empty frames (also after the last ground truth), a tracker with no output, a false track,
boxes matched to distractors and to ground truth marked not considered, partial overlaps (HOTA's alphas), and
several sequences combined. Every field of HOTA, CLEAR and Identity must agree within 1e-6.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from evaluation.io_mot import read_gt
from evaluation.tracking import evaluate_tracking
from evaluation.validate import InputError

trackeval = pytest.importorskip("trackeval")

TOL = 1e-6


def _box(x: float, y: float = 100.0, w: float = 40.0, h: float = 80.0) -> list[float]:
    return [x, y, w, h]


def _gt_line(frame, tid, box, considered=1, cls=1, vis=1.0) -> str:
    return f"{frame},{tid},{box[0]:.2f},{box[1]:.2f},{box[2]:.2f},{box[3]:.2f},{considered},{cls},{vis}\n"


def _res_line(frame, tid, box, conf=1.0) -> str:
    return f"{frame},{tid},{box[0]:.2f},{box[1]:.2f},{box[2]:.2f},{box[3]:.2f},{conf},-1,-1,-1\n"


def _crossing(length: int = 20):
    """Two pedestrians crossing: A moves right, B left; they meet at frame 10."""
    gt, a, b = [], [], []
    for f in range(1, length + 1):
        xa, xb = 100 + 20 * f, 500 - 20 * f
        gt += [_gt_line(f, 1, _box(xa)), _gt_line(f, 2, _box(xb))]
        a.append((f, _box(xa + 3)))
        b.append((f, _box(xb - 2)))
    return gt, a, b


def cases() -> dict[str, tuple[str, str, int]]:
    """name -> (gt.txt, results .txt, seqLength)."""
    out = {}
    gt, a, b = _crossing()
    # identity switch: after the crossing the tracker swaps the ids
    res = [_res_line(f, 1 if f <= 10 else 2, box) for f, box in a] + [
        _res_line(f, 2 if f <= 10 else 1, box) for f, box in b]
    out["idswitch"] = ("".join(gt), "".join(res), 20)
    # fragmentation: A lost for frames 6-8, then found again with the same id; B found again under a new id
    res = [_res_line(f, 1, box) for f, box in a if not 6 <= f <= 8]
    res += [_res_line(f, 2 if f < 12 else 7, box) for f, box in b if not 9 <= f <= 11]
    out["fragments"] = ("".join(gt), "".join(res), 20)
    # empty frames: no object in frames 1-3 and after frame 12 of a 25-frame sequence; one tracker box in an
    # empty frame
    gt2 = [_gt_line(f, 5, _box(50 + 10 * f)) for f in range(4, 13)]
    res2 = [_res_line(f, 3, _box(52 + 10 * f)) for f in range(4, 13)] + [_res_line(20, 3, _box(300))]
    out["empty_frames"] = ("".join(gt2), "".join(res2), 25)
    # a tracker that outputs nothing
    out["no_output"] = ("".join(gt), "", 20)
    # a false track: right on A and B, plus a track where nothing is
    res = [_res_line(f, 1, box) for f, box in a] + [_res_line(f, 2, box) for f, box in b]
    res += [_res_line(f, 9, _box(700, 300)) for f in range(3, 15)]
    out["false_track"] = ("".join(gt), "".join(res), 20)
    # distractors and boxes not considered: a static person (class 7) and a zero-marked pedestrian, both covered
    gt3 = list(gt) + [_gt_line(f, 3, _box(800, 50), cls=7) for f in range(1, 21)]
    gt3 += [_gt_line(f, 4, _box(900, 50), considered=0) for f in range(1, 21)]
    res = [_res_line(f, 1, box) for f, box in a] + [_res_line(f, 2, box) for f, box in b]
    res += [_res_line(f, 11, _box(802, 52)) for f in range(1, 21)] + [_res_line(f, 12, _box(903, 50))
                                                                      for f in range(1, 21)]
    out["distractors"] = ("".join(gt3), "".join(res), 20)
    # partial overlaps, noisy boxes, a spurious re-identification: a seeded random case
    rng = np.random.default_rng(43)
    gt4, res4 = [], []
    for tid in range(1, 6):
        start, stop = sorted(rng.integers(1, 31, 2))
        x0, y0 = rng.uniform(0, 1000), rng.uniform(0, 500)
        for f in range(start, stop + 1):
            box = _box(x0 + 7 * f, y0, 30 + tid * 5, 60 + tid * 7)
            gt4.append(_gt_line(f, tid, box, vis=0.5))
            if rng.random() < 0.85:
                noisy = np.array(box) + rng.normal(0, 6, 4) * [1, 1, 0.5, 0.5]
                rid = tid + (10 if f > (start + stop) / 2 and tid % 2 else 0)
                res4.append(_res_line(f, rid, noisy))
    out["random"] = ("".join(gt4), "".join(res4), 30)
    return out


def _write_layout(root: Path, selected: dict[str, tuple[str, str, int]], gt_class: int | None = None) -> Path:
    """TrackEval's MOTChallenge layout: root/gt/<seq>/{gt/gt.txt, seqinfo.ini}, root/gt/seqmap.txt,
    root/trackers/t/data/<seq>.txt. Returns root. ``gt_class`` rewrites every ground-truth class."""
    for seq, (gt, res, length) in selected.items():
        seq_dir = root / "gt" / seq
        (seq_dir / "gt").mkdir(parents=True)
        if gt_class is not None:
            gt = "".join(",".join([*line.split(",")[:7], str(gt_class), line.split(",")[8]]) for line in
                         gt.splitlines(keepends=True))
        (seq_dir / "gt" / "gt.txt").write_text(gt)
        (seq_dir / "seqinfo.ini").write_text(f"[Sequence]\nname={seq}\nimDir=img1\nframeRate=10\n"
                                             f"seqLength={length}\nimWidth=1920\nimHeight=1080\nimExt=.png\n")
        (root / "trackers" / "t" / "data").mkdir(parents=True, exist_ok=True)
        (root / "trackers" / "t" / "data" / f"{seq}.txt").write_text(res)
    (root / "gt" / "seqmap.txt").write_text("name\n" + "".join(f"{s}\n" for s in selected))
    return root


def trackeval_results(root: Path) -> dict:
    """TrackEval's results per sequence and ``COMBINED_SEQ`` (pedestrian class): {seq: {metric: {field: value}}}."""
    config = {"USE_PARALLEL": False, "PRINT_RESULTS": False, "PRINT_CONFIG": False, "TIME_PROGRESS": False,
              "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False, "DISPLAY_LESS_PROGRESS": True}
    dataset = trackeval.datasets.MotChallenge2DBox({
        "GT_FOLDER": str(root / "gt"), "TRACKERS_FOLDER": str(root / "trackers"), "SKIP_SPLIT_FOL": True,
        "SEQMAP_FILE": str(root / "gt" / "seqmap.txt"), "BENCHMARK": "MOT17", "TRACKERS_TO_EVAL": ["t"],
        "PRINT_CONFIG": False, "OUTPUT_FOLDER": str(root / "out")})
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               trackeval.metrics.Identity({"PRINT_CONFIG": False})]
    res, msg = trackeval.Evaluator(config).evaluate([dataset], metrics)
    assert msg["MotChallenge2DBox"]["t"] == "Success", msg
    return {seq: r["pedestrian"] for seq, r in res["MotChallenge2DBox"]["t"].items()}


def assert_same(ours: dict, theirs: dict) -> None:
    """Every TrackEval field (arrays averaged over alphas, as our summary does) equals ours within TOL."""
    checked = 0
    for metric in ("HOTA", "CLEAR", "Identity"):
        for field, value in theirs[metric].items():
            expected = float(np.mean(value))
            assert ours[field] == pytest.approx(expected, abs=TOL), (metric, field)
            checked += 1
    np.testing.assert_allclose(list(ours["HOTA_per_alpha"].values()), theirs["HOTA"]["HOTA"], atol=TOL)
    assert checked > 40


@pytest.fixture(scope="module")
def all_cases(tmp_path_factory) -> tuple[Path, dict]:
    root = _write_layout(tmp_path_factory.mktemp("mot"), cases())
    return root, trackeval_results(root)


@pytest.mark.parametrize("seq", list(cases()))
def test_each_case_equals_trackeval(all_cases, seq):
    root, theirs = all_cases
    ours = evaluate_tracking(root / "gt" / seq, root / "trackers" / "t" / "data" / f"{seq}.txt", classes=(1,))
    assert_same(ours["sequences"][seq], theirs[seq])
    assert_same(ours["combined"], theirs[seq])


def test_sequences_combined_equal_trackeval(all_cases):
    root, theirs = all_cases
    ours = evaluate_tracking(root / "gt", root / "trackers" / "t" / "data", classes=(1,))
    assert list(ours["sequences"]) == sorted(cases())
    for seq in cases():
        assert_same(ours["sequences"][seq], theirs[seq])
    assert_same(ours["combined"], theirs["COMBINED_SEQ"])


def test_expected_values_of_the_closed_form_cases(all_cases):
    root, _ = all_cases
    run = {seq: evaluate_tracking(root / "gt" / seq, root / "trackers" / "t" / "data" / f"{seq}.txt")["combined"]
           for seq in ("idswitch", "no_output", "false_track", "distractors")}
    assert run["idswitch"]["IDSW"] == 2 and run["idswitch"]["CLR_FN"] == 0 and run["idswitch"]["CLR_FP"] == 0
    assert run["idswitch"]["MOTA"] == pytest.approx(1 - 2 / 40)
    assert run["no_output"]["MOTA"] == 0 and run["no_output"]["HOTA"] == 0 and run["no_output"]["IDF1"] == 0
    assert run["false_track"]["CLR_FP"] == 12 and run["false_track"]["MOTA"] == pytest.approx(1 - 12 / 40)
    # the box on the static person is removed, the one on the pedestrian not considered is a false positive
    assert run["distractors"]["CLR_FP"] == 20 and run["distractors"]["CLR_TP"] == 40


def test_other_classes_evaluate_like_pedestrians(tmp_path):
    """Cars (class 3, evaluated by default) score as TrackEval scores the same boxes labelled pedestrian."""
    selected = {k: v for k, v in cases().items() if k in ("fragments", "random")}
    cars = _write_layout(tmp_path / "cars", selected, gt_class=3)
    theirs = trackeval_results(_write_layout(tmp_path / "peds", selected, gt_class=1))
    ours = evaluate_tracking(cars / "gt", cars / "trackers" / "t" / "data")
    assert_same(ours["combined"], theirs["COMBINED_SEQ"])
    assert evaluate_tracking(cars / "gt", cars / "trackers" / "t" / "data", classes=(1,))["combined"]["CLR_TP"] == 0


@pytest.mark.parametrize(("line", "message"), [
    ("1,1,10,10,5,5,1", "at least 8"),
    ("1,1,10,10,5,x,1,1,1", "bb_height 'x' is not a number"),
    ("0,1,10,10,5,5,1,1,1", "frame 0 is not an integer from 1"),
    ("1,1.5,10,10,5,5,1,1,1", "id 1.5"),
    ("1,1,10,10,-5,5,1,1,1", "bb_width and bb_height must be >= 0"),
    ("1,1,10,10,5,5,2,1,1", "considered 2 is not 0 or 1"),
    ("1,1,10,10,5,5,1,14,1", "class 14 is not a MOT class id"),
    ("1,1,10,10,5,5,1,1,1\n1,1,20,10,5,5,1,1,1", "frame 1 has id 1 more than once"),
    ("1,1,10,10,5,5,1,1,nan", None),  # visibility is not read
])
def test_bad_ground_truth_names_file_and_field(tmp_path, line, message):
    gt = tmp_path / "seq" / "gt" / "gt.txt"
    gt.parent.mkdir(parents=True)
    gt.write_text(line + "\n")
    if message is None:
        assert read_gt(gt)["seq"].length == 1
        return
    with pytest.raises(InputError, match=message) as info:
        read_gt(gt)
    assert str(gt) in str(info.value)


def test_bad_results(tmp_path):
    root = _write_layout(tmp_path, {"s": cases()["idswitch"]})
    data = root / "trackers" / "t" / "data"
    (data / "s.txt").write_text("21,1,10,10,5,5,1\n")
    with pytest.raises(InputError, match=r"s\.txt, box 1: frame 21 is beyond the sequence's 20 frames"):
        evaluate_tracking(root / "gt", data)
    (data / "s.txt").unlink()
    with pytest.raises(InputError, match=r"no results file for sequence\(s\) s\.txt"):
        evaluate_tracking(root / "gt", data)


def test_cli_task_tracking(tmp_path, capsys):
    import json

    from pipeline.stages.cli import main

    root = _write_layout(tmp_path / "mot", {k: v for k, v in cases().items() if k in ("idswitch", "random")})
    out = tmp_path / "eval"
    assert main(["evaluate", "--task", "tracking", "--gt", str(root / "gt"), "--detections",
                 str(root / "trackers" / "t" / "data"), "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["combined"]["HOTA"] == pytest.approx(evaluate_tracking(root / "gt", root / "trackers" / "t" / "data")
                                                        ["combined"]["HOTA"], abs=1e-12)
    assert json.loads((out / "meta.json").read_text())["config"]["task"] == "tracking"
    assert "| combined |" in (out / "report.md").read_text()
    (root / "trackers" / "t" / "data" / "random.txt").write_text("1,1,2,3\n")
    assert main(["evaluate", "--task", "tracking", "--gt", str(root / "gt"), "--detections",
                 str(root / "trackers" / "t" / "data"), "--out", str(tmp_path / "eval2")]) == 2
    assert "random.txt, line 1: 4 values, expected at least 7" in capsys.readouterr().err
    assert not (tmp_path / "eval2").exists()


FIELD_TEXT = ["0", "1", "-1", "2.5", "1e300", "-1e300", "nan", "inf", "x", "", "14", "8", "3"]


@pytest.mark.parametrize("kind", ["gt", "results"])
def test_mutated_files_are_scored_or_refused(tmp_path_factory, kind):
    """Any field of a valid file replaced by other text: the file is scored or refused with InputError."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    gt_text, res_text, length = cases()["fragments"]

    @settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))
    @given(line=st.integers(0, 50), field=st.integers(0, 9), text=st.sampled_from(FIELD_TEXT))
    def check(line, field, text):
        root = _write_layout(tmp_path_factory.mktemp("fuzz"), {"s": (gt_text, res_text, length)})
        path = root / "gt" / "s" / "gt" / "gt.txt" if kind == "gt" else root / "trackers" / "t" / "data" / "s.txt"
        lines = path.read_text().splitlines()
        values = lines[line % len(lines)].split(",")
        values[field % len(values)] = text
        lines[line % len(lines)] = ",".join(values)
        path.write_text("\n".join(lines) + "\n")
        try:
            metrics = evaluate_tracking(root / "gt", root / "trackers" / "t" / "data")
        except InputError as exc:
            assert str(path) in str(exc)
            return
        assert 0.0 <= metrics["combined"]["HOTA"] <= 1.0

    check()


def test_empty_field_is_refused_not_shifted(tmp_path):
    gt = tmp_path / "s" / "gt" / "gt.txt"
    gt.parent.mkdir(parents=True)
    gt.write_text("1,2,,10,5,5,1,1,1\n")
    with pytest.raises(InputError, match="line 1: bb_left '' is not a number"):
        read_gt(gt)
    gt.write_text("1 2 10 10 5 5 1 1 1\n")  # space-separated, as TrackEval's reader also accepts
    assert read_gt(gt)["s"].boxes.tolist() == [[10, 10, 5, 5]]


def test_cli_refuses_detection_options_with_task_tracking(tmp_path, capsys):
    from pipeline.stages.cli import main

    root = _write_layout(tmp_path / "mot", {"s": cases()["idswitch"]})
    assert main(["evaluate", "--task", "tracking", "--gt", str(root / "gt"), "--detections",
                 str(root / "trackers" / "t" / "data"), "--out", str(tmp_path / "eval"), "--iou", "0.7",
                 "--group-by", "condition"]) == 2
    assert "--iou, --group-by apply to --task detection only, not tracking" in capsys.readouterr().err
    assert not (tmp_path / "eval").exists()
