"""Faults around a stage's output, with real processes and signals: a render and an export stopped by Ctrl-C
(SIGINT) or ``kill -9`` at a point of their work, and two renders into one ``--out``.

Afterwards no process of the run is alive and nothing hidden is left beside the output once a later run has
finished there; a resumed render and a rerun export give the same bytes as runs that were never stopped.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

import pipeline.stages.render  # noqa: F401 - imported now, so that the in-process second writer starts at once
from pipeline.stages.cli import main
from tests.conftest import REPO, tree_hashes

CLI = [sys.executable, "-m", "pipeline.stages.cli"]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}


def _render_args(sim: Path, rig: Path, condition: str = "noon") -> list[str]:
    return ["render", "--sim", str(sim), "--condition", condition, "--rig", str(rig), "--shard-size", "1",
            "--workers", "2", "--no-progress", "--out", "rec"]


def _export_args(record: Path) -> list[str]:
    return ["export", "--dataset", str(record), "--format", "mcap", "--no-progress", "--out", "runs.mcap"]


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], cwd=cwd, env=_env(), capture_output=True, text=True, check=False,
                          timeout=300)


def _default_interrupt() -> None:
    """In the child: Ctrl-C as a user's terminal delivers it. A suite started as a background job of a shell without
    job control (`.ci/run &`, nohup) inherits SIGINT ignored, and Python then installs no handler for it."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen([*CLI, *args], cwd=cwd, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_default_interrupt)


def _wait_for(condition: Callable[[], bool], proc: subprocess.Popen, timeout_s: float = 120.0) -> None:
    end = time.monotonic() + timeout_s
    while not condition():
        if proc.poll() is not None:
            pytest.fail(f"the process ended (rc {proc.returncode}) before the point to stop it: {proc.stderr.read()}")
        if time.monotonic() > end:
            proc.kill()
            pytest.fail("the process did not reach the point to stop it")
        time.sleep(0.005)


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    """Running (a zombie, dead but not reaped by an init that does not reap, is not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def _none_alive(pids: list[int], within_s: float = 10.0) -> bool:
    end = time.monotonic() + within_s
    while any(_alive(p) for p in pids):
        if time.monotonic() > end:
            return False
        time.sleep(0.05)
    return True


@pytest.fixture(scope="module")
def rig_file(small_rig, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("faults-rig") / "small.yaml"
    path.write_text(yaml.safe_dump(small_rig.model_dump(mode="json")))
    return path


@pytest.fixture(scope="module")
def reference_record(run_21_frames, rig_file, tmp_path_factory) -> Path:
    """All 21 frames rendered in one go, with the command line the faulted renders use."""
    cwd = tmp_path_factory.mktemp("faults-ref")
    proc = _run(_render_args(run_21_frames, rig_file), cwd)
    assert proc.returncode == 0, proc.stderr
    return cwd / "rec"


@pytest.fixture(scope="module")
def reference_export(reference_record, tmp_path_factory) -> Path:
    cwd = tmp_path_factory.mktemp("faults-export-ref")
    proc = _run(_export_args(reference_record), cwd)
    assert proc.returncode == 0, proc.stderr
    return cwd


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["ctrl-c", "sigterm", "kill-9"])
def test_a_stopped_render_leaves_no_process_and_resumes_to_the_same_bytes(run_21_frames, rig_file, reference_record,
                                                                          tmp_path, sig):
    args = _render_args(run_21_frames, rig_file)
    proc = _start(args, tmp_path)
    shards = tmp_path / ".rec.partial" / "shards"
    _wait_for(lambda: any(shards.glob("done-*")), proc)  # a shard is done, 20 are not
    workers = _children(proc.pid)
    assert workers, "the render has a worker process"
    proc.send_signal(sig)
    err = proc.communicate(timeout=120)[1]
    assert _none_alive(workers), "a worker outlived the render"
    if sig in (signal.SIGINT, signal.SIGTERM):  # SIGTERM (timeout, docker stop) is handled like Ctrl-C
        word, status = ("interrupted", 130) if sig == signal.SIGINT else ("terminated", 143)
        assert proc.returncode == status
        assert word in err and "rerun the same command to resume" in err
        assert "Traceback" not in err
        assert not (tmp_path / ".rec.lock").exists()
    else:
        assert proc.returncode == -signal.SIGKILL
    assert not (tmp_path / "rec").exists()
    resumed = _run(args, tmp_path)
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming:" in resumed.stderr
    assert tree_hashes(tmp_path / "rec") == tree_hashes(reference_record)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]  # no lock, work folder or temporary left


def _stopped(proc: subprocess.Popen, timeout_s: float = 10.0) -> bool:
    """Wait until ``proc`` is stopped (state T in /proc/PID/stat); False if it exited first."""
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except (FileNotFoundError, ProcessLookupError):
            return False
        if state in ("T", "t"):
            return True
        time.sleep(0.001)
    return False


def _stopped_mid_export(args: list[str], cwd: Path) -> subprocess.Popen:
    """An export frozen (SIGSTOP) while its temporary output exists; tries again when the export was too quick."""
    for _ in range(5):
        proc = _start(args, cwd)
        while proc.poll() is None and not any(p.name.startswith(".runs.mcap.tmp-") for p in cwd.iterdir()):
            time.sleep(0.001)  # the export writes for about 0.1 s
        if proc.poll() is None:
            proc.send_signal(signal.SIGSTOP)
            # A signal is delivered asynchronously: on a busy machine the export may still finish and rename its
            # output between the kill and the look at the folder, so look only once the kernel shows it stopped.
            if _stopped(proc) and any(p.name.startswith(".runs.mcap.tmp-") for p in cwd.iterdir()):
                return proc
            if proc.poll() is None:  # stopped with its output already in place: let it finish
                proc.send_signal(signal.SIGCONT)
        proc.wait()
        for path in cwd.iterdir():  # it finished: start over
            path.unlink()
    pytest.fail("could not stop the export while it wrote")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["ctrl-c", "sigterm", "kill-9"])
def test_a_stopped_export_leaves_nothing_and_reruns_to_the_same_bytes(reference_record, reference_export, tmp_path,
                                                                      sig):
    args = _export_args(reference_record)
    proc = _stopped_mid_export(args, tmp_path)
    proc.send_signal(sig)
    proc.send_signal(signal.SIGCONT)
    err = proc.communicate(timeout=120)[1]
    assert not (tmp_path / "runs.mcap").exists()
    if sig in (signal.SIGINT, signal.SIGTERM):
        word, status = ("interrupted", 130) if sig == signal.SIGINT else ("terminated", 143)
        assert proc.returncode == status and word in err and "Traceback" not in err
        assert list(tmp_path.iterdir()) == []  # its temporaries and locks removed
    else:
        assert proc.returncode == -signal.SIGKILL
        assert any(p.name.startswith(".runs.mcap.tmp-") for p in tmp_path.iterdir())
    rerun = _run(args, tmp_path)
    assert rerun.returncode == 0, rerun.stderr
    assert tree_hashes(tmp_path) == tree_hashes(reference_export)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs.layout.json", "runs.mcap"]


def test_a_second_render_into_the_same_out_fails_at_once(run_21_frames, rig_file, reference_record, tmp_path,
                                                         monkeypatch, capsys):
    first = _start(_render_args(run_21_frames, rig_file), tmp_path)
    shards = tmp_path / ".rec.partial" / "shards"
    _wait_for(lambda: any(shards.glob("done-*")), first)
    monkeypatch.chdir(tmp_path)
    start = time.monotonic()
    rc = main(_render_args(run_21_frames, rig_file, condition="night"))
    seconds = time.monotonic() - start
    err = capsys.readouterr().err
    assert first.poll() is None, "the first render was still running"
    assert rc == 2 and seconds < 5
    assert "--out rec" in err.splitlines()[0] and "another process is writing it" in err
    assert "roadsynth render, pid" in err
    assert first.wait(timeout=300) == 0, first.stderr.read()
    assert tree_hashes(tmp_path / "rec") == tree_hashes(reference_record)  # the first's output, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


def test_the_render_function_takes_the_lock_too(run_21_frames, small_rig, noon_condition, tmp_path):
    """Called from Python, not the CLI, a render still refuses an output another process is writing."""
    from pipeline.core.outputs import OutputBusy
    from pipeline.stages.render import render

    holder = subprocess.Popen([sys.executable, "-c", "import sys, time\nfrom pipeline.core.outputs import output_lock\n"
                               "with output_lock(sys.argv[1], 'render'):\n    print('held', flush=True)\n"
                               "    time.sleep(60)", str(tmp_path / "rec")],
                              env=_env(), stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(OutputBusy, match="another process is writing it"):
            render(run_21_frames, noon_condition, small_rig, tmp_path / "rec", frames=1, progress=False)
    finally:
        holder.kill()
        holder.wait()
    assert not (tmp_path / ".rec.partial").exists()
