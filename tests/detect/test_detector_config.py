"""DetectorConfig: the default file loads; bad values fail naming the file and the field."""

from __future__ import annotations

import pytest
import yaml

from pipeline.core.config import ConfigError, DetectorConfig, load_config
from pipeline.stages.train import resolve_config


def test_default_config_loads():
    config, path = load_config(DetectorConfig, "default", "detector")
    assert path.name == "default.yaml"
    assert config.input_size == (384, 288) and config.train.conditions == ("morning", "noon")
    # the file spells out the model's defaults
    assert config.model_dump(exclude={"description"}) == DetectorConfig().model_dump(exclude={"description"})


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"input_size": [300, 288]}, "input_size"),
        ({"classes": ["car", "tram"]}, "unknown classes ['tram']"),
        ({"classes": ["car", "car"]}, "unique"),
        ({"train": {"steps": 10, "warmup_steps": 10}}, "warmup_steps"),
        ({"train": {"batch": 8}}, "train.batch"),
        ({"augment": {"scale": [1.5, 1.0]}}, "augment.scale"),
        ({"infer": {"nms_iou": 0.0}}, "infer.nms_iou"),
        ({"backbone": {"widths": [8, 8, 8]}}, "backbone.widths"),
    ],
)
def test_bad_config_names_file_and_field(tmp_path, data, message):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as err:
        load_config(DetectorConfig, path, "detector")
    assert str(path) in str(err.value) and message in str(err.value)


def test_unknown_name_lists_available():
    with pytest.raises(ConfigError, match="available: .*default"):
        load_config(DetectorConfig, "nope", "detector")


def test_command_line_overrides_are_validated():
    config, _ = resolve_config("default", steps=5, conditions="all")
    assert config.train.steps == 5 and config.train.warmup_steps == 4 and config.train.conditions is None
    with pytest.raises(ConfigError, match="train.steps"):
        resolve_config("default", steps=0)


def test_target_defaults_match_the_config():
    from pipeline.detect.losses import GAUSSIAN_ALPHA, MIN_SIGMA_CELLS

    train = DetectorConfig().train
    assert (train.gaussian_alpha, train.min_sigma_cells) == (GAUSSIAN_ALPHA, MIN_SIGMA_CELLS)
