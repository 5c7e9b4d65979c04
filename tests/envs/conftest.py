"""Fixtures shared by the environment tests."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml


@pytest.fixture(scope="session")
def small_default_rig(tmp_path_factory) -> Path:
    """The default rig (configs/rigs/default.yaml: its camera's field of view and mounts), smaller to keep tests
    short: a 400x300 camera of one sample per pixel, a 32-channel LiDAR without drop-out, no radar."""
    rig = yaml.safe_load((Path(__file__).parents[2] / "configs" / "rigs" / "default.yaml").read_text())
    rig["name"] = "small"
    rig["cameras"][0].update(width_px=400, height_px=300, samples_per_pixel=1, quality="fast")
    rig["lidars"][0].update(channels=32, horizontal_resolution_deg=0.4, dropout=0.0)
    rig.pop("radars")
    path = tmp_path_factory.mktemp("rig") / "small.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path
