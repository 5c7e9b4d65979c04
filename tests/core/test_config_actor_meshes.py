"""A rig's ``actor_meshes``: paths relative to the YAML file, the file's sha256 in the config (filled or checked),
and errors that name the file, the key and what was expected."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
import yaml

from pipeline.core.config import ConfigError, RigConfig, load_config
from pipeline.core.config.loading import parse_config

CAMERA = {"name": "front", "mount": {"xyz_m": [0.6, 0.0, 0.65]}}


def rig_file(folder: Path, entries: list[dict], name: str = "rig.yaml") -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump({"name": "mine", "cameras": [CAMERA], "actor_meshes": entries}))
    return path


@pytest.fixture
def asset(tmp_path) -> Path:
    """A mesh file under assets/ beside the rig (its content does not matter to the config)."""
    (tmp_path / "assets").mkdir()
    path = tmp_path / "assets" / "car.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 1\nf 1 2 3\n")
    return path


def test_paths_resolve_against_the_yaml_file_and_the_digest_is_recorded(tmp_path, asset, monkeypatch):
    path = rig_file(tmp_path, [{"cls": "car", "path": "assets/car.obj"}])
    monkeypatch.chdir(asset.parent)  # not the rig's folder: the path must not resolve against the current one
    rig, _ = load_config(RigConfig, path, "rigs")
    (entry,) = rig.actor_meshes
    assert entry.file == asset.resolve()
    digest = hashlib.sha256(asset.read_bytes()).hexdigest()
    dumped = rig.model_dump(mode="json")["actor_meshes"][0]
    assert dumped == {"cls": "car", "path": "assets/car.obj", "sha256": digest, "forward_axis": "+x",
                      "up_axis": "+z", "material": "paint", "replace": True}
    # The dump validates again (from the same folder) into the same config: a record's meta describes its rig.
    assert parse_config(RigConfig, rig.model_dump(mode="json"), "meta", path) == rig
    # A changed asset changes the config (so its hash) ...
    asset.write_text(asset.read_text() + "v 0 0 2\n")
    changed, _ = load_config(RigConfig, path, "rigs")
    assert changed.actor_meshes[0].sha256 != digest and changed != rig
    # ... and a config that pins the old digest fails.
    pinned = rig_file(tmp_path, [{"cls": "car", "path": "assets/car.obj", "sha256": digest}], "pinned.yaml")
    with pytest.raises(ConfigError, match=r"pinned\.yaml: invalid config: actor_meshes\[0\]: .*the asset changed"):
        load_config(RigConfig, pinned, "rigs")


@pytest.mark.parametrize(("entry", "expected"), [
    ({"cls": "car", "path": "assets/none.glb"}, r"actor_meshes\[0\]: .*path 'assets/none.glb': no such file"),
    ({"cls": "car", "path": "assets/car.fbx"}, r"expected a mesh file \(\.glb, \.gltf, \.obj, \.ply, \.stl\)"),
    ({"cls": "tank", "path": "assets/car.obj"}, r"actor_meshes\[0\]\.cls: got 'tank'"),
    ({"cls": "car", "path": "assets/car.obj", "forward_axis": "+y", "up_axis": "-y"}, "must be different axes"),
    ({"cls": "car", "path": "assets/car.obj", "up_axis": "up"}, r"actor_meshes\[0\]\.up_axis: got 'up'"),
    ({"cls": "car", "path": "assets/car.obj", "material": {}}, "material: an empty mapping"),
    ({"cls": "car", "path": "assets/car.obj", "material": "shiny paint"}, "not a material name"),
    ({"cls": "car", "path": "assets/car.obj", "scale": 2}, r"actor_meshes\[0\]\.scale: .*Extra inputs"),
    ({"cls": "car"}, r"actor_meshes\[0\]\.path: Field required"),
])
def test_bad_entries_name_the_file_and_key(tmp_path, asset, entry, expected):
    path = rig_file(tmp_path, [entry])
    with pytest.raises(ConfigError, match=r"rig\.yaml: invalid config: .*" + expected):
        load_config(RigConfig, path, "rigs")


def test_entries_of_a_class_must_agree_on_replace(tmp_path, asset):
    (asset.parent / "van.obj").write_text(asset.read_text())
    path = rig_file(tmp_path, [{"cls": "car", "path": "assets/car.obj"}, {"cls": "van", "path": "assets/van.obj",
                                                                          "replace": False},
                               {"cls": "car", "path": "assets/van.obj", "replace": False}])
    with pytest.raises(ConfigError, match="the entries of class car disagree on replace"):
        load_config(RigConfig, path, "rigs")
