"""One source of LiDAR defaults: the renderer's LiDAR takes the rig config (pipeline.core.config) itself, and a
rig that leaves a field out behaves as the shipped rig."""

from __future__ import annotations

import numpy as np
import yaml

from pipeline.core.config import RigConfig, load_config
from pipeline.sensors.lidar import Lidar
from tests.conftest import REPO


def test_a_rig_without_optional_lidar_fields_renders_like_the_shipped_one(tmp_path):
    shipped = yaml.safe_load((REPO / "configs" / "rigs" / "default.yaml").read_text())
    bare = dict(shipped, name="bare", lidars=[{"name": "top", "mount": shipped["lidars"][0]["mount"]}])
    path = tmp_path / "bare.yaml"
    path.write_text(yaml.safe_dump(bare))
    rig = load_config(RigConfig, path, "rigs")[0]
    default = load_config(RigConfig, "default", "rigs")[0]
    bare_lidar, shipped_lidar = Lidar(rig.lidars[0]), Lidar(default.lidars[0])
    assert bare_lidar.config.model_dump() == shipped_lidar.config.model_dump()
    assert bare_lidar.config.dropout == 0.02
    np.testing.assert_array_equal(bare_lidar.directions, shipped_lidar.directions)
    np.testing.assert_array_equal(bare_lidar.mount.matrix, shipped_lidar.mount.matrix)
