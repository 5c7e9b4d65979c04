"""Hand-built canonical records (tests/exporters/synthetic_record.py), built once per test session."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.exporters.synthetic_record import build_record


@pytest.fixture(scope="session")
def record_root(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("records")


@pytest.fixture(scope="session")
def morning(record_root) -> Path:
    """highway, seed 1, morning: 2 frames."""
    return build_record(record_root / "highway-1-morning", scenario="highway", seed=1, condition="morning")


@pytest.fixture(scope="session")
def night(record_root) -> Path:
    """The same run as ``morning`` (highway, seed 1) under the night condition."""
    return build_record(record_root / "highway-1-night", scenario="highway", seed=1, condition="night")


@pytest.fixture(scope="session")
def urban(record_root) -> Path:
    """Another run: urban, seed 2, morning."""
    return build_record(record_root / "urban-2-morning", scenario="urban", seed=2, condition="morning")


@pytest.fixture(scope="session")
def records(morning, night, urban) -> list[Path]:
    return [morning, night, urban]
