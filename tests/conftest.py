"""Shared fixtures: small real SUMO runs (no mocks), built once per test session."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"


def tree_hashes(root: Path, *, skip: tuple[str, ...] = ()) -> dict[str, str]:
    """sha256 of every file under ``root`` by relative path."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name not in skip
    }


def simulated_highway(tmp_path_factory, seed: int, **overrides) -> Path:
    """Run the simulate stage on the highway scenario with command-line-style overrides."""
    from pipeline.stages.simulate import resolve_scenario, simulate

    config, _ = resolve_scenario("highway", **overrides)
    out = tmp_path_factory.mktemp("sim") / f"highway-{seed}"
    simulate(config, seed, out, progress=False)
    return out


@pytest.fixture(scope="session")
def small_highway_run(tmp_path_factory) -> Path:
    """A small highway simulation: 40 vehicles, 20 s warm-up, 3 s recorded at 10 Hz."""
    return simulated_highway(tmp_path_factory, 7, vehicles=40, duration_s=3.0, warmup_s=20.0)


@pytest.fixture(scope="session")
def dense_highway_run(tmp_path_factory) -> Path:
    """A highway run with traffic around the ego: 200 vehicles, 90 s warm-up, 1 s recorded."""
    return simulated_highway(tmp_path_factory, 3, vehicles=200, duration_s=1.0, warmup_s=90.0)
