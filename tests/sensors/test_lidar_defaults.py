"""One source of LiDAR defaults: the rig config (pipeline.core.config) and the renderer's LidarConfig agree, and a
rig that leaves a field out behaves as the shipped rig."""

from __future__ import annotations

import dataclasses

import numpy as np
import yaml

from pipeline.core.config import RigConfig, load_config
from pipeline.core.config.sensors import LidarConfig as LidarSpec
from pipeline.sensors.lidar import LidarConfig
from pipeline.stages.rig import lidar_from_spec
from tests.conftest import REPO


def _fields(cfg: LidarConfig) -> dict:
    """Everything but the mount (a Transform of arrays; compared on its own)."""
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg) if f.name != "mount"}


def test_a_spec_with_defaults_builds_the_renderers_default_lidar():
    built = lidar_from_spec(LidarSpec(name="top", mount={"xyz_m": (0.0, 0.0, 0.0)})).config
    assert _fields(built) == _fields(LidarConfig())
    assert built.dropout_prob == 0.02


def test_a_rig_without_optional_lidar_fields_renders_like_the_shipped_one(tmp_path):
    shipped = yaml.safe_load((REPO / "configs" / "rigs" / "default.yaml").read_text())
    bare = dict(shipped, name="bare", lidars=[{"name": "top", "mount": shipped["lidars"][0]["mount"]}])
    path = tmp_path / "bare.yaml"
    path.write_text(yaml.safe_dump(bare))
    rig = load_config(RigConfig, path, "rigs")[0]
    default = load_config(RigConfig, "default", "rigs")[0]
    bare_lidar, shipped_lidar = lidar_from_spec(rig.lidars[0]).config, lidar_from_spec(default.lidars[0]).config
    assert _fields(bare_lidar) == _fields(shipped_lidar)
    np.testing.assert_array_equal(bare_lidar.mount.matrix, shipped_lidar.mount.matrix)
