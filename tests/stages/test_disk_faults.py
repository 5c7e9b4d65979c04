"""Outputs on a disk that refuses them: the message names the user's --out (never our lock or temporary files) and
nothing is left behind. The full disk is a small tmpfs (needs root; skipped otherwise)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from pipeline.stages.cli import main


def test_an_output_where_nothing_can_be_written_names_the_flag_and_path(small_record, tmp_path, capsys):
    out = "/proc/self/coco"  # no one, root included, creates files under /proc
    assert main(["export", "--dataset", str(small_record), "--format", "coco", "--no-progress", "--out", out]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: cannot write there" in err and ".lock" not in err


@pytest.fixture
def full_disk(tmp_path):
    mount = tmp_path / "full"
    mount.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=24k", "tmpfs", str(mount)],
                                           capture_output=True, check=False).returncode != 0:
        pytest.skip("needs root to mount a small tmpfs")
    yield mount
    subprocess.run(["umount", str(mount)], check=False)


def test_a_full_disk_leaves_nothing_and_names_the_output(small_record, full_disk: Path, capsys):
    out = full_disk / "coco"
    argv = ["export", "--dataset", str(small_record), "--format", "coco", "--copy-images", "--no-progress", "--out",
            str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and str(out) in err and ".tmp-" not in err
    assert "nothing half-written is left" in err
    assert list(full_disk.iterdir()) == []
