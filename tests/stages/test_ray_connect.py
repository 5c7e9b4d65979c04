"""Connecting to a Ray cluster fails fast and says what to do (``--executor ray --ray-address``): a malformed
address is refused before anything runs; an address where nothing listens fails within seconds; a port that
accepts connections but never answers as Ray fails after ``--ray-timeout``. Each render runs in a process of its
own (a half-connected Ray must not stay in the test process). Only 127.0.0.1."""

from __future__ import annotations

import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from pipeline.stages.executor import ExecutorSpec, head_host_port

pytest.importorskip("ray")

CLI = [sys.executable, "-m", "pipeline.stages.cli"]


@pytest.mark.parametrize(("address", "expected"), [
    ("10.1.2.3:6379", ("10.1.2.3", 6379)), ("ray://head.example:10001", ("head.example", 10001)),
    ("[::1]:6379", ("::1", 6379)), ("auto", None)])
def test_cluster_addresses_are_read(address, expected):
    assert head_host_port(address) == expected


@pytest.mark.parametrize("address", ["nonsense", "head:", ":6379", "head:99999", "http://head:80", "head:port"])
def test_a_malformed_address_is_refused_naming_the_flag(address):
    with pytest.raises(ValueError, match="--ray-address"):
        ExecutorSpec("ray", address)


def test_a_bad_timeout_is_refused():
    with pytest.raises(ValueError, match="--ray-timeout"):
        ExecutorSpec("ray", "127.0.0.1:6379", timeout_s=0.0)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def render_args(run_21_frames, small_rig, tmp_path_factory) -> list[str]:
    rig = tmp_path_factory.mktemp("ray-connect") / "small.yaml"
    rig.write_text(yaml.safe_dump(small_rig.model_dump(mode="json")))
    return ["render", "--sim", str(run_21_frames), "--condition", "noon", "--rig", str(rig), "--frames", "1",
            "--executor", "ray", "--no-progress", "--out", "rec"]


def _render(args: list[str], cwd: Path) -> tuple[subprocess.CompletedProcess, float]:
    start = time.monotonic()
    proc = subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False)
    return proc, time.monotonic() - start


@pytest.mark.slow
def test_an_address_where_nothing_listens_fails_within_seconds(render_args, tmp_path):
    address = f"127.0.0.1:{_free_port()}"
    proc, took = _render([*render_args, "--ray-address", address], tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert took < 60  # the process's start and imports; it hung for more than 10 minutes before
    assert "nothing listens there" in proc.stderr and f"ray status --address {address}" in proc.stderr
    assert "RAY_AUTH_MODE=token" in proc.stderr and "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_port_that_never_answers_as_ray_fails_after_the_timeout(render_args, tmp_path):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    held: list[socket.socket] = []
    stop = threading.Event()

    def accept() -> None:  # accept connections and say nothing
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                held.append(server.accept()[0])
            except OSError:
                continue

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        address = f"127.0.0.1:{server.getsockname()[1]}"
        proc, took = _render([*render_args, "--ray-address", address, "--ray-timeout", "4"], tmp_path)
    finally:
        stop.set()
        thread.join()
        for conn in held:
            conn.close()
        server.close()
    assert proc.returncode == 2, proc.stderr
    assert took < 90
    assert "no answer within 4 s (--ray-timeout)" in proc.stderr and "Traceback" not in proc.stderr
    # The process ends with the error: Ray's connecting thread, given up on, neither prints its retries after it
    # nor crashes the interpreter's shutdown (SIGABRT, status -6, seen once in CI).
    assert proc.stderr.rstrip().splitlines()[-1].startswith("roadsynth render: error: --ray-address"), proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_ray_flags_with_the_local_executor_are_refused(render_args, tmp_path):
    args = [a for a in render_args if a not in ("--executor", "ray")] + ["--ray-timeout", "5"]
    proc, _ = _render(args, tmp_path)
    assert proc.returncode == 2 and "--ray-timeout" in proc.stderr


@pytest.mark.slow
def test_a_new_local_instance_outlives_its_start(render_args, tmp_path):
    # No address: the CLI starts a local Ray. Its head's processes die with the thread that starts them (a
    # parent-death signal); started from the helper thread that bounds a cluster's connection, they died a second
    # later and the render hung, then failed, waiting for them.
    proc, _ = _render(render_args, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "rec" / "meta.json").is_file()
