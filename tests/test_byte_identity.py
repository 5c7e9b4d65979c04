"""Records, exports and metrics of a fixed tiny run stay what they were (the refactors of issue 25 must not
change a byte).

The run and the digests are in tests/byte_identity_run.py, which also regenerates the golden file
tests/data/byte_identity_golden.json. Two checks:

- the machine-independent fingerprints (rounded values: trajectories to 1e-4, labels to 0.01, metrics to
  1e-3; LiDAR point and annotation counts) are compared on every machine;
- the SHA-256 of every output file (``meta.json`` left out) is compared only on a processor with the same
  instruction-set features as the one that wrote the golden file: docs/dataset.md says records and exports
  are meant to be the same bytes on any x86-64, but libraries' own SIMD code (Embree, OpenCV) is outside our
  control, and the tests never assert bytes that depend on the processor.
"""

from __future__ import annotations

import json

import pytest

from tests.byte_identity_run import GOLDEN, cpu_features, digests, run


@pytest.fixture(scope="module")
def result(tmp_path_factory) -> dict:
    return digests(run(tmp_path_factory.mktemp("byte_identity")))


@pytest.fixture(scope="module")
def golden() -> dict:
    return json.loads(GOLDEN.read_text())


def test_fingerprints_are_unchanged(result, golden):
    assert result["fingerprint"] == golden["fingerprint"]


def test_every_file_is_byte_identical_on_the_golden_files_processor(result, golden):
    if cpu_features() != golden["cpu_features"]:
        pytest.skip(f"this processor's features {cpu_features()} differ from the golden file's "
                    f"{golden['cpu_features']}: only the fingerprints are compared")
    for name, files in golden["files"].items():
        assert result["files"][name] == files, name
