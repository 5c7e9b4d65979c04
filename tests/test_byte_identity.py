"""The fixed tiny run (tests/byte_identity_run.py) keeps its promises.

- Same config and seed, same bytes: the run made twice on this machine, the second time with the render's shards
  in two worker processes, writes the same bytes in every output file (``meta.json`` aside: command line, paths,
  versions). Safe on any machine: both runs share the processor and every library.
- What the outputs hold is what it was (the refactors of issue 25 must not change a value): compared with
  tests/data/byte_identity_golden.json.gz by value, with the tolerances of ``byte_identity_run.tolerance``. Bytes are
  never compared with the golden file: Embree, numpy's SIMD maths, BLAS, zlib, pyarrow and matplotlib choose bytes
  that depend on the processor and the library versions of an install, not on our code.
"""

from __future__ import annotations

import copy

import pytest

from tests.byte_identity_run import GOLDEN, compare, file_digests, read_golden, run, summaries

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def outputs(tmp_path_factory) -> dict:
    return run(tmp_path_factory.mktemp("byte_identity"))


@pytest.fixture(scope="module")
def result(outputs) -> dict:
    return summaries(outputs)


@pytest.fixture(scope="module")
def golden() -> dict:
    return read_golden()


def test_the_same_run_twice_writes_the_same_bytes(outputs, tmp_path_factory):
    again = run(tmp_path_factory.mktemp("byte_identity_again"), render_workers=2)
    assert set(again) == set(outputs)
    for name in outputs:
        first, second = file_digests(outputs[name]), file_digests(again[name])
        assert sorted(first) == sorted(second), name
        differ = sorted(rel for rel in first if first[rel] != second[rel])
        assert not differ, f"{name}: these files differ between two runs of the same config and seed: {differ}"


def test_outputs_hold_the_golden_values(result, golden):
    problems = compare(result, golden)
    assert not problems, f"{len(problems)} differences from {GOLDEN.name}:\n" + "\n".join(problems[:40])


def _first(files: dict, suffix: str) -> str:
    return next(rel for rel in sorted(files) if rel.endswith(suffix))


@pytest.mark.parametrize(("output", "suffix", "change", "caught"), [
    ("record-morning", "rgb/000000.png", lambda s: s["block_means"][3][4].__setitem__(1, s["block_means"][3][4][1] + 3),
     True),  # a block 3 levels brighter in one channel
    ("record-morning", "rgb/000000.png", lambda s: s["block_means"][3][4].__setitem__(1, s["block_means"][3][4][1] + 1),
     False),  # one level: rounding on another machine
    ("record-night", "labels.parquet", lambda s: s["columns"]["x1"].__setitem__(0, s["columns"]["x1"][0] + 2), True),
    ("record-night", "labels.parquet", lambda s: s["columns"]["x1"].__setitem__(0, s["columns"]["x1"][0] + 1), False),
    ("record-night", "labels.parquet", lambda s: s["columns"]["yaw_rad"].__setitem__(0, s["columns"]["yaw_rad"][0]
                                                                                      + 1e-3), True),
    ("record-fog", "000000.parquet", lambda s: s.__setitem__("rows", int(s["rows"] * 1.02)), True),
    ("sim", "trajectories.parquet", lambda s: s["columns"]["lane_id"].__setitem__(0, "elsewhere_0"), True),
    ("kitti", "label_2/000000.txt", lambda s: s["tokens"].__setitem__(3, f"{float(s['tokens'][3]) + 0.05:.2f}"),
     True),  # alpha of the first object, printed to 0.01
    ("kitti", "label_2/000000.txt", lambda s: s["tokens"].__setitem__(3, f"{float(s['tokens'][3]) + 0.01:.2f}"),
     False),
    ("eval", "metrics.json", lambda s: s["json"].__setitem__("extra", 1), True),
])
def test_the_comparison_catches_what_it_should(result, output, suffix, change, caught):
    """The tolerances let last-bit rounding through and nothing a change of the picture or the labels makes."""
    changed = copy.deepcopy(result)
    change(changed[output][_first(changed[output], suffix)])
    assert bool(compare(changed, result)) is caught
