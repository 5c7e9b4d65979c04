"""Bad input through the real CLI, one table: each case runs ``roadsynth`` in-process in a workspace of real
stage outputs (a simulated run, a rendered record, a COCO export, detections, an evaluation, a user's own files)
and checks the exit code, that the error's first line names the flag or file at fault, that there is no
traceback, and that no byte outside the stage's own output changed (nothing else appears, nothing is left
behind: no lock, no temporary)."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.core.png import encode_png, with_text
from pipeline.stages.cli import build_parser
from pipeline.stages.cli import main as cli_main
from tests.conftest import REPO

NOTES = {"notes/a.txt": "my notes\n", "notes/b.txt": "more\n", "notes.txt": "a file of mine\n"}


def main(argv: list[str]) -> int:
    """The console script's exit code (argparse's usage errors exit through SystemExit)."""
    try:
        return cli_main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def snapshot(root: Path) -> dict[str, tuple[str, int] | None]:
    """Every file (sha256, mtime) and folder (None) under ``root``, hidden ones included, by relative path."""
    out: dict[str, tuple[str, int] | None] = {}
    for path in sorted(root.rglob("*")):
        rel = str(path.relative_to(root))
        out[rel] = None if path.is_dir() else (hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns)
    return out


@pytest.fixture(scope="session")
def workspace_base(tmp_path_factory, run_21_frames, small_record, small_rig) -> Path:
    """A project folder holding one output of each stage the cases read, and a user's own files."""
    base = tmp_path_factory.mktemp("bad-input") / "ws"
    base.mkdir()
    shutil.copytree(run_21_frames, base / "sim")
    shutil.copytree(small_record, base / "rec")
    (base / "rig.yaml").write_text(yaml.safe_dump(small_rig.model_dump(mode="json")))
    for rel, text in NOTES.items():
        (base / rel).parent.mkdir(parents=True, exist_ok=True)
        (base / rel).write_text(text)
    (base / "dets.json").write_text("[]\n")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(base)
        assert main(["export", "--dataset", "rec", "--format", "coco", "--out", "coco", "--no-progress"]) == 0
        assert main(["evaluate", "--gt", "coco/annotations.json", "--detections", "dets.json", "--out", "eval"]) == 0
    return base


@pytest.fixture
def workspace(workspace_base, tmp_path, monkeypatch) -> Path:
    ws = tmp_path / "ws"
    shutil.copytree(workspace_base, ws)
    monkeypatch.chdir(ws)
    return ws


RENDER = ["render", "--sim", "sim", "--condition", "noon", "--rig", "rig.yaml", "--frames", "1", "--workers", "1",
          "--no-progress"]
EXPORT = ["export", "--dataset", "rec", "--no-progress"]
EVALUATE = ["evaluate", "--gt", "coco/annotations.json", "--detections", "dets.json"]
REPORT = ["report", "--eval", "eval", "--gt", "coco/annotations.json", "--detections", "dets.json"]
SIMULATE = ["simulate", "--scenario", "highway", "--seed", "1", "--vehicles", "30", "--duration", "0.5", "--warmup",
            "10", "--no-progress"]  # a run that succeeds where its output is allowed

# (id, argv, what the error's first line must hold); every case exits 2 and changes nothing.
REFUSED = [
    # --out destroys data (issue 24, item 2): inputs, files, folders that are not the stage's own output
    ("render onto its --sim", [*RENDER, "--out", "sim"], "--out sim: is an input"),
    ("render into its --sim", [*RENDER, "--out", "sim/record"], "--out sim/record: is inside an input"),
    ("render onto its --rig file", [*RENDER, "--out", "rig.yaml"], "--out rig.yaml: is an input"),
    ("render onto a folder of other files", [*RENDER, "--out", "notes"], "--out notes: is a non-empty folder"),
    ("render onto a file", [*RENDER, "--out", "notes.txt"], "--out notes.txt: is a file"),
    ("render onto another stage's output", [*RENDER, "--out", "coco"], "`roadsynth export` output"),
    ("render --overwrite still spares its input", [*RENDER, "--out", "sim", "--overwrite"], "--out sim: is an input"),
    ("export onto its record", [*EXPORT, "--format", "coco", "--out", "rec"], "--out rec: is an input"),
    ("export to ..", [*EXPORT, "--format", "coco", "--out", ".."], "--out ..:"),
    ("export to the working folder", [*EXPORT, "--format", "coco", "--out", "."], "--out .:"),
    ("export mcap onto a text file", [*EXPORT, "--format", "mcap", "--out", "notes.txt"], "not an MCAP file"),
    ("export onto an evaluation", [*EXPORT, "--format", "kitti", "--out", "eval"], "`roadsynth evaluate` output"),
    ("evaluate into the COCO folder", [*EVALUATE, "--out", "coco"], "--out coco: is an input"),
    ("evaluate beside its GT, in the export", [*EVALUATE, "--out", "coco/eval"], "--out coco/eval: is inside an input"),
    ("evaluate onto its detections", [*EVALUATE, "--out", "dets.json"], "--out dets.json: is an input"),
    ("report onto its --eval", [*REPORT, "--out", "eval"], "--out eval: is an input"),
    ("preview onto a folder", ["preview", "--dataset", "rec", "--out", "notes"], "--out notes: is a folder"),
    ("preview onto its record", ["preview", "--dataset", "rec", "--out", "rec"], "--out rec: is an input"),
    ("preview onto a text file", ["preview", "--dataset", "rec", "--out", "notes.txt"], "--out notes.txt"),
    ("simulate onto a folder of other files", [*SIMULATE, "--out", "notes"], "--out notes: is a non-empty folder"),
    ("simulate --metrics-out onto a file", [*SIMULATE, "--out", "sim2", "--metrics-out", "notes.txt"],
     "--metrics-out notes.txt"),
    ("train onto its COCO export", ["train", "--coco", "coco", "--split", "x", "--out", "coco"],
     "--out coco: is an input"),
    ("detect onto a text file", ["detect", "--onnx", "rig.yaml", "--annotations", "coco/annotations.json",
                                 "--out", "notes.txt"], "--out notes.txt"),
    ("export of a missing record into new folders", ["export", "--dataset", "nope", "--format", "coco", "--out",
                                                     "new/deeper/c"], "nope"),
    # unclear errors and tracebacks (item 8)
    ("preview to a .jpg", ["preview", "--dataset", "rec", "--out", "sheet.jpg"], "--out sheet.jpg"),
    ("preview --frames 0", ["preview", "--dataset", "rec", "--out", "p.png", "--frames", "0"], "--frames"),
    ("report --examples 0", [*REPORT, "--out", "rep", "--examples", "0"], "--examples"),
    ("simulate --seed -1", [*SIMULATE[:3], "--seed", "-1", "--out", "s"], "--seed"),
    # SUMO reads --seed as a C int: past 2^31 - 1 it printed "not a valid integer" and ran with its own default seed
    # while meta.json kept ours
    ("simulate --seed 2^31", [*SIMULATE[:3], "--seed", str(2**31), "--out", "s"], "SUMO takes a 32-bit seed"),
    ("a folder as --scenario", ["simulate", "--scenario", "notes", "--seed", "1", "--out", "s"], "notes: a folder"),
    ("render --workers 0", [*RENDER[:-3], "--workers", "0", "--out", "r"], "--workers"),
    ("render --frames 0", [*RENDER, "--frames", "0", "--out", "r"], "--frames"),
    ("export --camera for coco", [*EXPORT, "--format", "coco", "--camera", "rear", "--out", "c"], "--camera"),
    ("export --compression for yolo", [*EXPORT, "--format", "yolo", "--compression", "lz4", "--out", "y"],
     "--compression"),
    ("export --copy-images for mcap", [*EXPORT, "--format", "mcap", "--copy-images", "--out", "m.mcap"],
     "--copy-images"),
    ("evaluate --iou not a number", [*EVALUATE, "--iou", "0.5,x", "--out", "e"], "--iou"),
]


def _first_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith("roadsynth")]
    assert lines, f"no error message in {err!r}"
    return lines[0]


@pytest.mark.parametrize(("argv", "names"), [case[1:] for case in REFUSED], ids=[case[0] for case in REFUSED])
def test_bad_input_is_refused_naming_it_and_changes_nothing(workspace, capsys, argv, names):
    before = snapshot(workspace)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert names in _first_error_line(err)
    assert "Traceback" not in err
    assert snapshot(workspace) == before


def _truncate(rel: str) -> None:
    data = Path(rel).read_bytes()
    Path(rel).write_bytes(data[: len(data) // 2])


def _flip_byte(rel: str) -> None:
    data = bytearray(Path(rel).read_bytes())
    data[len(data) // 2] ^= 0xFF
    Path(rel).write_bytes(bytes(data))


def _column_ends(path: Path) -> dict[str, int]:
    """Per column of the first row group, the offset just past its last page (whose last bytes are values); an empty
    table has no pages."""
    import pyarrow.parquet as pq

    group = pq.ParquetFile(path).metadata.row_group(0)
    chunks = [group.column(i) for i in range(group.num_columns)]
    return {c.path_in_schema: (c.dictionary_page_offset if c.has_dictionary_page else c.data_page_offset)
            + c.total_compressed_size for c in chunks if c.total_compressed_size}


def _flip_value_byte(rel: str, column: str) -> None:
    """Flip the last byte of ``column``'s data page: a value's byte, which without a page checksum reads silently."""
    data = bytearray(Path(rel).read_bytes())
    data[_column_ends(Path(rel))[column] - 1] ^= 0x01
    Path(rel).write_bytes(bytes(data))


def _set_nan(rel: str, column: str) -> None:
    import pandas as pd

    from pipeline.core.tables import write_parquet

    table = pd.read_parquet(rel)
    table.loc[len(table) // 2, column] = float("nan")
    write_parquet(table, Path(rel))


def _drop_column(rel: str, column: str) -> None:
    import pandas as pd

    from pipeline.core.tables import write_parquet

    write_parquet(pd.read_parquet(rel).drop(columns=[column]), Path(rel))


RGB, INSTANCE, SWEEP = "rec/cameras/front/rgb/000010.png", "rec/cameras/front/instance/000010.png", \
    "rec/lidars/top/000010.parquet"
# Corrupt inputs (issue 24, item 5): (id, how the input is damaged, argv, what the first error line must name).
CORRUPT = [
    ("truncated RGB PNG into COCO", lambda: _truncate(RGB), [*EXPORT, "--format", "coco", "--out", "c"],
     f"{RGB}: truncated PNG"),
    ("truncated RGB PNG into YOLO", lambda: _truncate(RGB), [*EXPORT, "--format", "yolo", "--out", "y"],
     f"{RGB}: truncated PNG"),
    ("truncated RGB PNG into MCAP", lambda: _truncate(RGB), [*EXPORT, "--format", "mcap", "--out", "m.mcap"],
     f"{RGB}: truncated PNG"),
    ("flipped byte in an RGB PNG into rosbag2", lambda: _flip_byte(RGB),
     [*EXPORT, "--format", "rosbag2", "--out", "bag"], f"{RGB}: damaged PNG"),
    ("truncated RGB PNG into preview", lambda: _truncate(RGB), ["preview", "--dataset", "rec", "--out", "p.png"],
     f"{RGB}: truncated PNG"),
    ("truncated instance PNG into COCO", lambda: _truncate(INSTANCE), [*EXPORT, "--format", "coco", "--out", "c"],
     f"{INSTANCE}: truncated PNG"),
    ("damaged LiDAR sweep into MCAP", lambda: _truncate(SWEEP), [*EXPORT, "--format", "mcap", "--out", "m.mcap"],
     f"{SWEEP}: not a readable LiDAR sweep"),
    ("NaN time in the record into MCAP", lambda: _set_nan("rec/frames.parquet", "time_s"),
     [*EXPORT, "--format", "mcap", "--out", "m.mcap"], "rec/frames.parquet: field time_s is nan at frame"),
    ("NaN position in the trajectories into render", lambda: _set_nan("sim/trajectories.parquet", "x_m"),
     [*RENDER, "--out", "r"], "sim/trajectories.parquet: field x_m is nan at frame"),
    ("trajectories without the parked column into render", lambda: _drop_column("sim/trajectories.parquet", "parked"),
     [*RENDER, "--out", "r"], "sim/trajectories.parquet: no column parked"),
    ("flipped byte in a position of the trajectories into render",
     lambda: _flip_value_byte("sim/trajectories.parquet", "x_m"), [*RENDER, "--out", "r"],
     "sim/trajectories.parquet: corrupt (page checksum mismatch"),
    ("flipped byte in a label of the record into COCO", lambda: _flip_value_byte("rec/labels.parquet", "x1"),
     [*EXPORT, "--format", "coco", "--out", "c"], "rec/labels.parquet: corrupt (page checksum mismatch"),
    ("flipped byte in a LiDAR point into MCAP", lambda: _flip_value_byte(SWEEP, "x_m"),
     [*EXPORT, "--format", "mcap", "--out", "m.mcap"], f"{SWEEP}: corrupt (page checksum mismatch"),
]


@pytest.mark.parametrize(("damage", "argv", "names"), [case[1:] for case in CORRUPT], ids=[case[0] for case in CORRUPT])
def test_a_corrupt_input_fails_naming_file_frame_and_field(workspace, capsys, damage, argv, names):
    damage()
    before = snapshot(workspace)
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert names in _first_error_line(err)
    assert "Traceback" not in err
    assert snapshot(workspace) == before


def test_every_table_simulate_and_render_write_carries_page_checksums(run_21_frames, small_record, tmp_path):
    """Trajectories, signals, vehicles, road geometry, frames, labels and LiDAR sweeps: a byte flipped in any
    column's values fails naming the file (without a checksum most such flips read as another value)."""
    from pipeline.core.tables import read_parquet

    paths = [p for source in (run_21_frames, small_record) for p in sorted(source.rglob("*.parquet"))]
    assert {"trajectories", "tls_states", "vehicles", "lanes", "frames", "labels"} <= {p.stem for p in paths}
    assert any(p.parent.parent.name == "lidars" for p in paths)
    flipped = 0
    for path in paths:
        copy = tmp_path / "copy.parquet"
        for end in _column_ends(path).values():
            data = bytearray(path.read_bytes())
            data[end - 1] ^= 0x01
            copy.write_bytes(bytes(data))
            with pytest.raises(ValueError, match=r"copy.parquet: corrupt \(page checksum mismatch"):
                read_parquet(copy)
            flipped += 1
    assert flipped > 100


def test_a_config_error_is_not_buried_under_a_dump_of_the_config(workspace, capsys):
    scenario = yaml.safe_load((REPO / "configs" / "scenarios" / "highway.yaml").read_text())
    for spec in scenario["demand"]["classes"].values():
        spec["share"] = 0
    (workspace / "zero.yaml").write_text(yaml.safe_dump(scenario))
    before = snapshot(workspace)
    assert main([*SIMULATE[:2], "zero.yaml", *SIMULATE[3:], "--out", "s"]) == 2
    err = capsys.readouterr().err
    assert "zero.yaml" in _first_error_line(err) and "class shares must not all be zero" in err
    assert len(err) < 400, err
    assert snapshot(workspace) == before


def test_a_broken_meta_json_is_named(workspace, capsys):
    (workspace / "sim" / "meta.json").write_text('{"seed": 1,')
    before = snapshot(workspace)
    assert main([*RENDER, "--out", "r"]) == 2
    assert "sim/meta.json: not valid JSON" in _first_error_line(capsys.readouterr().err)
    assert snapshot(workspace) == before


# Reruns into an earlier output of the same stage (what `dvc repro` does), and --overwrite where nothing is an input.
ACCEPTED = [
    ("export onto its earlier export", [*EXPORT, "--format", "coco", "--out", "coco"], "coco"),
    ("render onto its earlier record", [*RENDER, "--out", "rec2"], "rec2"),
    ("preview onto its earlier sheet", ["preview", "--dataset", "rec", "--out", "sheet.png"], "sheet.png"),
    ("evaluate onto its earlier evaluation, --iou with commas and spaces",
     [*EVALUATE, "--out", "eval", "--iou", "0.5,0.7", "0.9"], "eval"),
    ("export --overwrite onto a folder of other files", [*EXPORT, "--format", "yolo", "--out", "notes", "--overwrite"],
     "notes"),
    ("preview --overwrite onto an empty folder", ["preview", "--dataset", "rec", "--out", "empty.png", "--overwrite"],
     "empty.png"),
]


@pytest.mark.parametrize(("argv", "output"), [case[1:] for case in ACCEPTED], ids=[case[0] for case in ACCEPTED])
def test_an_earlier_output_of_the_stage_is_replaced(workspace, capsys, argv, output):
    (workspace / "empty.png").mkdir()
    shutil.copytree(workspace / "rec", workspace / "rec2")  # an earlier render output
    # an earlier contact sheet: a PNG carrying preview's mark
    (workspace / "sheet.png").write_bytes(with_text(encode_png(np.zeros((2, 2, 3), np.uint8)), "Software",
                                                    "roadsynth preview"))
    before = {k: v for k, v in snapshot(workspace).items() if k != output and not k.startswith(f"{output}/")}
    assert main(argv) == 0, capsys.readouterr().err
    after = {k: v for k, v in snapshot(workspace).items() if k != output and not k.startswith(f"{output}/")}
    assert after == before  # no lock or temporary left beside it, nothing else touched
    assert (workspace / output).exists()


def test_a_users_file_in_a_stage_output_or_another_programs_file_is_kept(workspace, capsys, tmp_path):
    """Issue 38's data losses: an evaluation folder into which the user put NOTES.md, an MCAP another program
    wrote, a contact sheet another program drew: each refused and kept as it was; --overwrite replaces it."""
    from mcap.writer import Writer

    assert main([*EVALUATE, "--out", "eval2"]) == 0
    (workspace / "eval2" / "NOTES.md").write_text("my notes")
    with (workspace / "theirs.mcap").open("wb") as fh:  # a valid MCAP of someone else's
        writer = Writer(fh)
        writer.start(profile="", library="another program")
        writer.finish()
    foreign_png = encode_png(np.zeros((2, 2, 3), np.uint8))
    (workspace / "theirs.png").write_bytes(foreign_png)
    cases = [([*EVALUATE, "--out", "eval2"], "eval2/NOTES.md", "also holds NOTES.md"),
             ([*EXPORT, "--format", "mcap", "--out", "theirs.mcap"], "theirs.mcap", "an MCAP file roadsynth did not"),
             (["preview", "--dataset", "rec", "--out", "theirs.png"], "theirs.png", "a PNG image roadsynth did not")]
    for argv, kept, why in cases:
        before = (workspace / kept).read_bytes()
        capsys.readouterr()
        assert main(argv) == 2, argv
        assert why in capsys.readouterr().err
        assert (workspace / kept).read_bytes() == before
        assert main([*argv, "--overwrite"]) == 0, capsys.readouterr().err
    assert not (workspace / "eval2" / "NOTES.md").exists()  # replaced, as asked
    assert main([*EVALUATE, "--out", "eval2"]) == 0  # and a plain rerun replaces its own output again


def test_the_iou_list_takes_commas_and_spaces(workspace, capsys):
    assert main([*EVALUATE, "--out", "eval", "--iou", "0.5,0.7", "0.9"]) == 0
    assert json.loads((workspace / "eval" / "metrics.json").read_text())["table"]["iou_thresholds"] == [0.5, 0.7, 0.9]


def test_version_and_verbose_after_the_sub_command(capsys):
    assert main(["--version"]) == 0 and capsys.readouterr().out.startswith("roadsynth ")
    parser = build_parser("render")
    assert parser.parse_args(["-v", *RENDER, "--out", "r"]).verbose
    assert parser.parse_args([*RENDER, "--out", "r", "-v"]).verbose
    assert not parser.parse_args([*RENDER, "--out", "r"]).verbose


def test_a_run_killed_earlier_leaves_nothing_behind_the_next_run(workspace, capsys, caplog):
    """What a killed export leaves (its temporary, an unlocked lock file) is removed by the next export there;
    an earlier output a killed run had set aside for replacement is put back."""
    (workspace / ".c.tmp-99999").mkdir()
    (workspace / ".c.tmp-99999" / "big.bin").write_bytes(b"x" * 1000)
    (workspace / ".c.lock").write_text("99999 roadsynth export\n")
    shutil.copytree(workspace / "coco", workspace / ".coco.old-99998")
    shutil.rmtree(workspace / "coco")
    assert main([*EXPORT, "--format", "coco", "--out", "c"]) == 0, capsys.readouterr().err
    assert not (workspace / ".c.tmp-99999").exists() and not (workspace / ".c.lock").exists()
    assert main([*EXPORT, "--format", "coco", "--out", "coco"]) == 0, capsys.readouterr().err
    assert "put back the earlier output" in caplog.text
    assert not list(workspace.glob(".coco*"))
