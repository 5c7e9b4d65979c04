"""``roadsynth render --executor ray --ray-address`` against a 2-node Ray cluster on this machine
(``ray.cluster_utils.Cluster``): a worker process killed mid-shard is replaced, and the record is still the local
executor's, byte for byte.

Skipped without Ray (``pip install 'roadsynth[ray]'``; ``make setup-dev`` installs it)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest

from tests.conftest import REPO, tree_hashes
from tests.stages.conftest import RAY_FRAMES

ray = pytest.importorskip("ray")

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def two_nodes():
    """A head and a second node of 1 CPU each; this process is connected as a driver too (to see the nodes)."""
    from ray.cluster_utils import Cluster

    if ray.is_initialized():
        ray.shutdown()
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    cluster.add_node(num_cpus=1)
    ray.init(address=cluster.address, log_to_driver=False)
    cluster.wait_for_nodes()
    yield cluster
    ray.shutdown()
    cluster.shutdown()


def _task_process(title: str) -> psutil.Process | None:
    """The Ray worker process whose title (``ray::`` and the running task's name) contains ``title``."""
    for process in psutil.process_iter(["cmdline"]):
        with_title = " ".join(process.info["cmdline"] or [])
        if with_title.startswith("ray::") and title in with_title:
            return process
    return None


def _kill_mid_shard(title: str, done_file: Path, killed: list[int], stop: threading.Event) -> None:
    """Kill (SIGKILL) the worker as soon as it runs the task named ``title`` (Ray titles a worker process with its
    task while the task runs), while ``done_file`` (the shard's completion marker) is not there yet."""
    while not stop.is_set() and not killed:
        process = _task_process(title)
        if process is not None and not done_file.exists():
            process.kill()
            killed.append(process.pid)
        time.sleep(0.01)


def test_a_worker_killed_mid_shard_is_retried_and_the_bytes_are_the_local_ones(
        two_nodes, small_highway_run, small_rig, four_frame_record, tmp_path):
    rig = tmp_path / "small.yaml"
    import yaml

    rig.write_text(yaml.safe_dump(small_rig.model_dump(mode="json")))
    out = tmp_path / "highway-7-noon"
    killed: list[int] = []
    stop = threading.Event()
    killer = threading.Thread(target=_kill_mid_shard, args=(
        "condition noon shard 1 ", tmp_path / ".highway-7-noon.partial" / "shards" / "done-00001", killed, stop))
    killer.start()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "pipeline.stages.cli", "render", "--sim", str(small_highway_run),
                           "--condition", "noon", "--rig", str(rig), "--frames", str(RAY_FRAMES), "--shard-size", "1",
                           "--no-progress", "--executor", "ray", "--ray-address", two_nodes.address,
                           "--out", str(out)], capture_output=True, text=True, env=env, check=False, timeout=600)
    stop.set()
    killer.join()
    assert killed, "no worker was seen rendering shard 1"
    assert not psutil.pid_exists(killed[0]) or psutil.Process(killed[0]).status() == psutil.STATUS_ZOMBIE
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert tree_hashes(out, skip=("meta.json",)) == tree_hashes(four_frame_record, skip=("meta.json",))
