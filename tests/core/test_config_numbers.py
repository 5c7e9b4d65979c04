"""Non-finite and absurd numbers in configs fail loading with the file and key path, never render garbage.

YAML spells inf and NaN as ``.inf`` and ``.nan``; ``1e30`` reaches pydantic as the string "1e30".
Every config model derives from pipeline.core.config.base.ConfigModel, which checks every float once.
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.core.config import (
    ConditionConfig,
    ConfigError,
    DetectorConfig,
    ExperimentConfig,
    RigConfig,
    ScenarioConfig,
    load_config,
)
from pipeline.core.config.base import MAX_ABS, MIN_ABS
from tests.conftest import REPO

BAD_CONDITION_LINES = [
    ("lens:\n  exposure: .inf\n", "lens.exposure", "finite"),
    ("lens:\n  exposure: -.inf\n", "lens.exposure", "finite"),
    ("sun:\n  intensity: 1e30\n", "sun.intensity", "magnitude"),
    ("sun:\n  intensity: 1.0e-30\n", "sun.intensity", "magnitude"),
    ("lens:\n  bloom_strength: 1.0e+30\n", "lens.bloom_strength", "magnitude"),
    ("sky:\n  zenith_rgb: [0.2, .nan, 0.6]\n", "sky.zenith_rgb[1]", "finite"),
    ("sun:\n  intensity: .NaN\n", "sun.intensity", "finite"),
    ("fog:\n  visibility_m: .inf\n", "fog.visibility_m", "finite"),
]


@pytest.mark.parametrize(("text", "key", "reason"), BAD_CONDITION_LINES)
def test_condition_with_bad_number_fails_naming_file_and_key(tmp_path: Path, text: str, key: str, reason: str) -> None:
    path = tmp_path / "bad_condition.yaml"
    path.write_text("name: bad\n" + text)
    with pytest.raises(ConfigError) as err:
        load_config(ConditionConfig, path, "conditions")
    first = str(err.value).splitlines()[0]
    assert first.startswith(f"{path}: invalid config: {key}: got ")
    assert reason in first


def test_limits_are_inclusive_and_zero_is_allowed(tmp_path: Path) -> None:
    path = tmp_path / "edge.yaml"
    path.write_text(f"name: edge\nsun:\n  intensity: {MAX_ABS!r}\nlens:\n  bloom_strength: 0.0\n"
                    f"  lens_flare: {MIN_ABS!r}\n")
    config, _ = load_config(ConditionConfig, path, "conditions")
    assert (config.sun.intensity, config.lens.bloom_strength, config.lens.lens_flare) == (MAX_ABS, 0.0, MIN_ABS)


def test_scenario_distribution_and_experiment_numbers(tmp_path: Path) -> None:
    scenario = yaml.safe_load((REPO / "configs" / "scenarios" / "highway.yaml").read_text())
    scenario["demand"]["driver"]["tau_s"]["high"] = float("inf")
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(scenario))  # writes .inf
    with pytest.raises(ConfigError, match=r"^\S+scenario\.yaml: invalid config: demand\.driver\.tau_s\.high: got inf"):
        load_config(ScenarioConfig, path, "scenarios")
    experiment = tmp_path / "experiment.yaml"
    experiment.write_text("name: e\nscenarios: [highway]\nseeds: [1]\nconditions: [noon]\nduration_s: .nan\n")
    with pytest.raises(ConfigError, match=r"experiment\.yaml: invalid config: duration_s: got nan"):
        load_config(ExperimentConfig, experiment, "experiments")


def test_cli_rejects_infinite_exposure_before_rendering(tmp_path: Path, capsys) -> None:
    from pipeline.stages.cli import main

    path = tmp_path / "dark.yaml"
    path.write_text("name: dark\nlens:\n  exposure: .inf\n")
    code = main(["render", "--sim", str(tmp_path / "no-sim"), "--condition", str(path), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2
    assert err.splitlines()[0] == (
        f"roadsynth render: error: {path}: invalid config: lens.exposure: got inf: Input should be a finite number"
    )
    assert "Traceback" not in err and not (tmp_path / "r").exists()


def test_write_meta_refuses_non_finite_numbers(tmp_path: Path) -> None:
    from pipeline.stages.common import write_meta

    with pytest.raises(ValueError, match=r"config: settings\.gain\[1\] is inf"):
        write_meta(tmp_path, stage="x", config={"settings": {"gain": [1.0, math.inf]}}, seed=None)
    assert not (tmp_path / "meta.json").exists()
    meta = write_meta(tmp_path, stage="x", config={"settings": {"gain": [1.0, 2.0]}}, seed=3)
    assert json.loads((tmp_path / "meta.json").read_text(), parse_constant=_no_constant)["seed"] == meta["seed"]


def _no_constant(name: str) -> float:
    raise AssertionError(f"meta.json holds {name}")


# --- property: any edit of a shipped config either loads (and dumps to strict JSON) or fails with ConfigError

SHIPPED = {
    "scenarios": (ScenarioConfig, "highway"),
    "conditions": (ConditionConfig, "night"),
    "rigs": (RigConfig, "default"),
    "experiments": (ExperimentConfig, "paper_table1"),
    "detector": (DetectorConfig, "default"),
}
numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-12, 1e-9, 1e6, 1e7, 1e30, -1e30, 0.5, 2.0, -1.0]),
    st.integers(-(2**70), 2**70),
)
leaves = st.one_of(numbers, st.booleans(), st.none(), st.text(max_size=5), st.lists(numbers, max_size=4))


def _paths(data, prefix=()):
    """Every key path of nested dicts and lists."""
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, list) else ()
    for key, value in items:
        yield (*prefix, key)
        yield from _paths(value, (*prefix, key))


def _set(data, path, value):
    for key in path[:-1]:
        data = data[key]
    data[path[-1]] = value


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(sorted(SHIPPED)), picks=st.lists(st.tuples(st.integers(0, 10**6), leaves), max_size=3))
def test_loading_never_shows_a_traceback(kind: str, picks) -> None:
    model, name = SHIPPED[kind]
    source = REPO / "configs" / kind / f"{name}.yaml"
    data = yaml.safe_load(source.read_text())
    for index, value in picks:
        paths = list(_paths(data))
        _set(data, paths[index % len(paths)], value)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "edited.yaml"
        path.write_text(yaml.safe_dump(data))
        try:
            config, _ = load_config(model, path, kind)
        except ConfigError as exc:
            assert str(exc).startswith(f"{path}: ")
            return
    json.dumps(config.model_dump(mode="json"), allow_nan=False)


def test_lognormal_without_upper_bound_holds_no_infinity() -> None:
    """The open upper bound is None (it was inf, which a strict JSON meta.json cannot hold)."""
    import numpy as np
    from scipy import stats

    from pipeline.core.config import LogNormal

    dist = LogNormal(median=2.0, sigma=0.5, low=1.0)
    assert dist.high is None
    json.dumps(dist.model_dump(mode="json"), allow_nan=False)
    x = np.array([0.5, 1.0, 2.0, 5.0, 1e3])
    base = stats.lognorm(s=0.5, scale=2.0)
    expected = np.clip((base.cdf(x) - base.cdf(1.0)) / (1 - base.cdf(1.0)), 0, 1)
    np.testing.assert_allclose(dist.cdf(x), expected, rtol=0, atol=1e-12)
    samples = dist.sample(np.random.default_rng(0), 1000)
    assert samples.min() >= 1.0 and np.isfinite(samples).all()
