"""The environment the project promises: quiet libsumo + pyarrow in one process, layers, lint."""

from __future__ import annotations

import shutil
import subprocess
import sys

from tests.conftest import REPO

# The Parquet round trip goes through a file path, as the pipeline's tables do (pipeline.core.tables). Not an
# in-memory Python file: pyarrow's scanner may drop its last reference to one from a worker thread while the
# interpreter exits, which needs the GIL and aborts the process ("terminate called without an active exception":
# 9 of 60 runs of that round trip alone, without libsumo; pyarrow 23.0.1).
_BOTH = """
import libsumo, pyarrow as pa, pyarrow.parquet as pq, sys
from pipeline.traffic.sumo_tools import binary
pq.write_table(pa.table({"x": [1.0, 2.0]}), sys.argv[2])
assert pq.read_table(sys.argv[2]).column("x").to_pylist() == [1.0, 2.0]
libsumo.start([binary("sumo"), "-n", sys.argv[1], "--no-step-log", "true"])
libsumo.simulationStep()
print("time", libsumo.simulation.getTime())
libsumo.close()
"""


def test_libsumo_and_pyarrow_work_quietly_in_one_process(small_highway_run, tmp_path):
    proc = subprocess.run([sys.executable, "-c", _BOTH, str(small_highway_run / "network.net.xml"),
                           str(tmp_path / "x.parquet")], capture_output=True, text=True, cwd=REPO, check=False)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    assert "time 1.0" in proc.stdout  # default step length 1 s
    # libsumo prints a warning when pyarrow differs from the libarrow it was built against.
    assert "might be incompatible" not in proc.stdout + proc.stderr


def _tool(name: str) -> str:
    here = REPO / ".venv" / "bin" / name
    return str(here) if here.exists() else (shutil.which(name) or name)


def test_import_layers_hold():
    proc = subprocess.run([_tool("lint-imports"), "--no-cache"], capture_output=True, text=True, cwd=REPO,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_ruff_is_clean():
    proc = subprocess.run([_tool("ruff"), "check", "."], capture_output=True, text=True, cwd=REPO, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
