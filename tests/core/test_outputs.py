"""The output rule (pipeline.core.outputs) and the whole-PNG check (pipeline.core.png.check_png), case by case."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.core.files import seal
from pipeline.core.outputs import (
    OutputError,
    OutputSpec,
    check_inputs,
    check_replaceable,
    json_file,
    lock_path,
    marked_sidecar,
    output_lock,
    png_file,
    write_sidecar,
)
from pipeline.core.png import check_png, encode_png, png_text, with_text


def _folder(path, stage=None, *, sealed=True):
    path.mkdir(parents=True)
    (path / "data.bin").write_bytes(b"x")
    (path / "sub").mkdir()
    (path / "sub" / "more.txt").write_text("abc")
    if stage:
        (path / "meta.json").write_text(json.dumps({"stage": stage}))
        if sealed:
            seal(path)
    return path


def test_a_folder_output_replaces_only_nothing_an_empty_folder_or_its_own_stage(tmp_path):
    check_replaceable([OutputSpec(tmp_path / "missing")], "render")
    (tmp_path / "empty").mkdir()
    check_replaceable([OutputSpec(tmp_path / "empty")], "render")
    mine = _folder(tmp_path / "mine", "render")
    assert json.loads((mine / "meta.json").read_text())["files"] == {"data.bin": 1, "sub/more.txt": 3}
    check_replaceable([OutputSpec(mine)], "render")
    for name, stage, why in [("theirs", "export", "`roadsynth export` output"), ("plain", None, "no meta.json")]:
        with pytest.raises(OutputError, match=why):
            check_replaceable([OutputSpec(_folder(tmp_path / name, stage))], "render")
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="is a file"):
        check_replaceable([OutputSpec(tmp_path / "file")], "render")


def test_a_stage_output_holding_anything_else_is_not_replaced(tmp_path):
    """Exactly what the stage wrote (its manifest): a user's file in it, a file changed since, or no manifest at
    all (an older roadsynth) each need --overwrite."""
    notes = _folder(tmp_path / "notes", "evaluate")
    (notes / "sub" / "NOTES.md").write_text("mine")
    with pytest.raises(OutputError, match="also holds sub/NOTES.md, which the stage did not write"):
        check_replaceable([OutputSpec(notes)], "evaluate")
    edited = _folder(tmp_path / "edited", "evaluate")
    (edited / "data.bin").write_bytes(b"xy")
    with pytest.raises(OutputError, match="data.bin changed since the stage wrote it"):
        check_replaceable([OutputSpec(edited)], "evaluate")
    old = _folder(tmp_path / "old", "evaluate", sealed=False)
    with pytest.raises(OutputError, match="lists no files"):
        check_replaceable([OutputSpec(old)], "evaluate")
    removed = _folder(tmp_path / "removed", "evaluate")
    (removed / "data.bin").unlink()  # less than the stage wrote: nothing of the user's to lose
    check_replaceable([OutputSpec(removed)], "evaluate")


def test_a_json_object_output_is_replaced_only_with_our_mark(tmp_path):
    stats = json_file(dict, ("frames",))
    spec = OutputSpec(tmp_path / "s.json", folder=False, recognise=stats, expected="stats")
    spec.path.write_text('{"frames": 3, "written_by": "roadsynth simulate"}')
    check_replaceable([spec], "simulate")
    spec.path.write_text('{"frames": 3}')  # the same keys, another program's
    with pytest.raises(OutputError, match="did not write"):
        check_replaceable([spec], "simulate")


def test_a_png_is_replaced_only_with_our_text_chunk(tmp_path):
    png = encode_png(np.zeros((4, 5, 3), np.uint8))
    spec = OutputSpec(tmp_path / "p.png", folder=False, recognise=png_file, expected="a PNG image")
    spec.path.write_bytes(png)
    with pytest.raises(OutputError, match="a PNG image roadsynth did not write"):
        check_replaceable([spec], "preview")
    marked = with_text(png, "Software", "roadsynth preview")
    check_png(marked, "marked")
    spec.path.write_bytes(marked)
    assert png_text(spec.path) == {"Software": "roadsynth preview"}
    check_replaceable([spec], "preview")


def test_a_results_list_is_replaced_only_with_our_sidecar(tmp_path):
    spec = OutputSpec(tmp_path / "r.json", folder=False, recognise=marked_sidecar("detect"), expected="results")
    spec.path.write_text("[]")
    with pytest.raises(OutputError, match="says roadsynth wrote it"):
        check_replaceable([spec], "detect")
    write_sidecar(spec.path, "detect")
    check_replaceable([spec], "detect")
    spec.path.write_text('[{"image_id": 1}]')
    with pytest.raises(OutputError, match="changed since"):
        check_replaceable([spec], "detect")


def test_a_file_output_replaces_only_a_file_of_its_kind(tmp_path):
    results = json_file(list, ("image_id", "score"))
    spec = OutputSpec(tmp_path / "r.json", folder=False, recognise=results, expected="results")
    spec.path.write_text('[{"image_id": 1, "score": 0.5}]')
    check_replaceable([spec], "detect")
    for text in ('{"image_id": 1}', '[{"image_id": 1}]', "not json"):
        spec.path.write_text(text)
        with pytest.raises(OutputError, match="did not write"):
            check_replaceable([spec], "detect")


def test_an_output_never_is_holds_or_lies_in_an_input(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    export = _folder(tmp_path / "coco", "export")
    gt = export / "annotations.json"
    gt.write_text("{}")
    for out, what in [(gt, "is inside an input"), (export, "is an input"), (export / "eval", "is inside an input"),
                      (tmp_path / "x" / ".." / "coco", "is an input")]:
        with pytest.raises(OutputError, match=what):
            check_inputs([OutputSpec(out)], [gt])
    with pytest.raises(OutputError, match="holds an input"):
        check_inputs([OutputSpec(tmp_path / "a")], [_folder(tmp_path / "a" / "b")])
    with pytest.raises(OutputError, match="working directory"):
        check_inputs([OutputSpec(tmp_path.parent / tmp_path.name)], [])
    check_inputs([OutputSpec(tmp_path / "eval")], [gt])


def test_the_lock_is_reentrant_in_its_process_and_gone_after(tmp_path):
    out = tmp_path / "out"
    with output_lock(out, "render"):
        assert lock_path(out).read_text().split()[0].isdigit()
        with output_lock(out, "render"):  # the CLI around a stage function that locks too
            pass
        assert lock_path(out).exists()
    assert not lock_path(out).exists()


def test_check_png_accepts_a_whole_png_and_names_what_is_wrong():
    data = encode_png(np.arange(12 * 10, dtype=np.uint8).reshape(10, 12))
    check_png(data, "f.png", width=12, height=10)
    with pytest.raises(ValueError, match="f.png: truncated PNG"):
        check_png(data[:-5], "f.png")
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 1
    with pytest.raises(ValueError, match="f.png: damaged PNG .CRC mismatch"):
        check_png(bytes(flipped), "f.png")
    with pytest.raises(ValueError, match="f.png: PNG of 12x10 pixels, expected 10x10"):
        check_png(data, "f.png", width=10, height=10)
    with pytest.raises(ValueError, match="not a PNG image"):
        check_png(b"GIF89a", "f.png")
