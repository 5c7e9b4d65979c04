"""Config files: every shipped file validates; bad files fail naming file, key path, value and what is allowed."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pipeline.core.config import ConfigError, ExperimentConfig, ScenarioConfig, load_config
from pipeline.core.config.loading import available_names
from tests.conftest import REPO


@pytest.mark.parametrize("name", available_names("scenarios"))
def test_shipped_scenarios_validate(name):
    config, path = load_config(ScenarioConfig, name, "scenarios")
    assert config.name == path.stem


@pytest.mark.parametrize("path", sorted((REPO / "configs" / "experiments").glob("*.yaml")))
def test_shipped_experiments_validate(path):
    load_config(ExperimentConfig, path, "experiments")


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _highway() -> dict:
    return yaml.safe_load((REPO / "configs" / "scenarios" / "highway.yaml").read_text())


def test_unknown_enum_value_lists_the_allowed_names(tmp_path):
    data = _highway()
    data["network"]["kind"] = "motorway"
    with pytest.raises(ConfigError) as err:
        load_config(ScenarioConfig, _write(tmp_path, data), "scenarios")
    msg = str(err.value)
    assert "bad.yaml" in msg and "network.kind" in msg and "'motorway'" in msg
    assert "'highway'" in msg and "'urban'" in msg and "'osm'" in msg


def test_bad_nested_distribution_value_names_the_key_path(tmp_path):
    data = _highway()
    data["demand"]["driver"]["tau_s"]["std"] = -1
    with pytest.raises(ConfigError, match=r"demand\.driver\.tau_s\.std: got -1: Input should be greater than 0"):
        load_config(ScenarioConfig, _write(tmp_path, data), "scenarios")


def test_unknown_distribution_and_class_names(tmp_path):
    data = _highway()
    data["demand"]["driver"]["accel_mps2"] = {"dist": "gamma", "shape": 2}
    data["demand"]["classes"]["tram"] = data["demand"]["classes"]["car"]
    with pytest.raises(ConfigError) as err:
        load_config(ScenarioConfig, _write(tmp_path, data), "scenarios")
    msg = str(err.value)
    assert "demand.driver.accel_mps2" in msg and "'constant', 'uniform', 'truncnormal', 'lognormal'" in msg
    assert "demand.classes.tram" in msg and "'car'" in msg and "'motorcycle'" in msg


def test_unknown_key_and_cross_field_checks(tmp_path):
    data = _highway()
    data["simulation"]["typo_key"] = 1
    with pytest.raises(ConfigError, match=r"simulation\.typo_key: got 1: Extra inputs are not permitted"):
        load_config(ScenarioConfig, _write(tmp_path, data), "scenarios")
    data = _highway()
    data["simulation"]["record_hz"] = 3
    with pytest.raises(ConfigError, match=r"simulation: .*record_hz \(3\.0\) must divide the step rate"):
        load_config(ScenarioConfig, _write(tmp_path, data), "scenarios")


def test_osm_kind_requires_a_file(tmp_path):
    data = _highway()
    data["network"] = {"kind": "osm"}
    with pytest.raises(ConfigError, match="kind 'osm' needs osm_file"):
        load_config(ScenarioConfig, _write(tmp_path, data), "scenarios")


def test_unknown_name_lists_available_configs():
    with pytest.raises(ConfigError, match=r"unknown scenario 'nowhere'; available: .*highway.*urban"):
        load_config(ScenarioConfig, "nowhere", "scenarios")


def test_missing_file_and_invalid_yaml(tmp_path):
    with pytest.raises(ConfigError, match="missing.yaml: config file not found"):
        load_config(ScenarioConfig, tmp_path / "missing.yaml", "scenarios")
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: [unclosed\n")
    with pytest.raises(ConfigError, match="broken.yaml: not valid YAML"):
        load_config(ScenarioConfig, broken, "scenarios")


def test_cli_reports_bad_config_without_traceback(tmp_path, capsys):
    from pipeline.stages.cli import main

    data = _highway()
    data["demand"]["vehicles"] = 0
    code = main(["simulate", "--scenario", str(_write(tmp_path, data)), "--seed", "1", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2
    assert "bad.yaml" in err and "demand.vehicles: got 0" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_names_resolve_in_the_project_configs_first_then_the_shipped_ones(tmp_path, monkeypatch):
    (tmp_path / "configs" / "scenarios").mkdir(parents=True)
    mine = _highway()
    mine["name"] = "mine"
    (tmp_path / "configs" / "scenarios" / "mine.yaml").write_text(yaml.safe_dump(mine))
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("ROADSYNTH_CONFIGS", raising=False)
    assert load_config(ScenarioConfig, "mine", "scenarios")[1] == tmp_path / "configs" / "scenarios" / "mine.yaml"
    assert load_config(ScenarioConfig, "urban", "scenarios")[1] == REPO / "configs" / "scenarios" / "urban.yaml"
    assert {"mine", "highway", "urban"} <= set(available_names("scenarios"))


def test_experiment_seeds_must_be_seeds_sumo_takes():
    from pipeline.core.config.experiment import ExperimentConfig

    base = {"name": "x", "scenarios": ["highway"], "conditions": ["noon"]}
    ExperimentConfig.model_validate({**base, "seeds": [0, 2**31 - 2]})
    with pytest.raises(ValueError, match="32-bit seed"):
        ExperimentConfig.model_validate({**base, "seeds": [2**31]})
