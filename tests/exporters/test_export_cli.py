"""``roadsynth export`` through the real CLI entry point."""

from __future__ import annotations

import json

import pytest

from pipeline.stages.cli import main


def test_cli_exports_and_writes_meta(tmp_path, morning, night):
    out = tmp_path / "kitti"
    rc = main(["export", "--dataset", str(morning), "--dataset", str(night), "--format", "kitti", "--out", str(out),
               "--splits", "train=1.0", "--min-visible-px", "10", "--no-progress"])
    assert rc == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["stage"] == "export" and meta["config"]["filter"] == {"min_visible_px": 10, "max_occlusion": 0.9}
    assert len(meta["config_hash"]) == 64
    assert json.loads((out / "export.json").read_text())["counts"]["objects"]["total"]["tiny"] == 0


def test_cli_reports_a_missing_record(tmp_path, capsys):
    rc = main(["export", "--dataset", str(tmp_path / "nope"), "--format", "mcap", "--out", str(tmp_path / "x.mcap")])
    assert rc == 2
    assert "dataset record not found" in capsys.readouterr().err
    assert not (tmp_path / "x.mcap").exists()


def test_cli_rejects_unknown_format(tmp_path, morning):
    with pytest.raises(SystemExit):
        main(["export", "--dataset", str(morning), "--format", "voc", "--out", str(tmp_path / "x")])


@pytest.mark.parametrize("flag", [["--min-visible-px", "50"], ["--max-occlusion", "0.5"]])
def test_the_camera_filter_is_refused_for_nuscenes_which_ignores_it(tmp_path, morning, capsys, flag):
    """nuScenes annotates objects in 3D whatever the cameras see: the filter would be ignored without a word."""
    rc = main(["export", "--dataset", str(morning), "--format", "nuscenes", "--out", str(tmp_path / "n"), *flag,
               "--no-progress"])
    assert rc == 2
    assert f"{flag[0]} applies to --format coco" in capsys.readouterr().err
    assert not (tmp_path / "n").exists()
