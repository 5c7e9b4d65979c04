"""``roadsynth render`` with a rig that names a user's mesh (an OBJ the test writes): every car is drawn with it, so
each car's LiDAR points lie on the model's surface in its 3D box, and the record's meta holds the file's digest."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import yaml

from pipeline.core.classes import SemanticClass
from pipeline.core.record import DatasetRecord
from pipeline.stages.cli import main as cli
from tests.conftest import tree_hashes
from tests.world.user_assets import UNIT_CABIN_HI, UNIT_CABIN_LO, write_obj

BODY_TOP_UNIT = UNIT_CABIN_LO[2]  # the body's top face, where the cabin stands


def test_render_draws_cars_with_the_rigs_mesh(dense_highway_run, tmp_path, capsys):
    (tmp_path / "assets").mkdir()
    obj = write_obj(tmp_path / "assets")
    rig = {"name": "mine",
           "cameras": [{"name": "front", "width_px": 160, "height_px": 120, "hfov_deg": 90.0, "quality": "fast",
                        "mount": {"xyz_m": [0.6, 0.0, 0.65]}}],
           "lidars": [{"name": "top", "channels": 32, "horizontal_resolution_deg": 0.4, "range_noise_std_m": 0.0,
                       "dropout": 0.0, "mount": {"xyz_m": [0.0, 0.0, 1.05]}}],
           "actor_meshes": [{"cls": "car", "path": "assets/wedge.obj", "material": {"glass": "glass"}}]}
    rig_path = tmp_path / "rig.yaml"
    rig_path.write_text(yaml.safe_dump(rig))
    out = tmp_path / "record"
    assert cli(["render", "--sim", str(dense_highway_run), "--condition", "noon", "--rig", str(rig_path),
                "--out", str(out), "--frames", "1", "--workers", "1", "--no-progress"]) == 0

    meta = json.loads((out / "meta.json").read_text())
    (entry,) = meta["config"]["rig"]["actor_meshes"]
    assert entry["path"] == "assets/wedge.obj" and entry["sha256"] == hashlib.sha256(obj.read_bytes()).hexdigest()

    record = DatasetRecord(out)
    labels = record.labels
    (frame,) = record.frames["frame"].tolist()
    points = record.points("top", frame)
    lidar = labels[(labels["sensor_type"] == "lidar") & (labels["lidar_points"] > 0)]
    cars = lidar[lidar["cls"] == "car"]
    assert len(cars) >= 2, "the run should have cars near the ego"
    checked = 0
    for row in cars.itertuples():
        mine = points[points["instance_id"] == row.track_id]
        assert (mine["semantic"] == SemanticClass.CAR).all()
        c, s = np.cos(row.sensor_yaw_rad), np.sin(row.sensor_yaw_rad)
        d = mine[["x_m", "y_m", "z_m"]].to_numpy() - [row.sensor_x_m, row.sensor_y_m, row.sensor_z_m]
        unit = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]]) \
            / [row.length_m, row.width_m, row.height_m]
        assert np.all(np.abs(unit) <= 0.5 + 1e-3)  # float32 points
        # Above the body's top only the cabin: the built-in families (bonnets, roofs, boots) have points there.
        above = unit[:, 2] > BODY_TOP_UNIT + 1e-3
        inside = (unit[above, 0] >= UNIT_CABIN_LO[0] - 1e-3) & (unit[above, 0] <= UNIT_CABIN_HI[0] + 1e-3) \
            & (np.abs(unit[above, 1]) <= UNIT_CABIN_HI[1] + 1e-3)
        assert inside.all(), f"car {row.track_id}: points above the body outside the cabin"
        checked += above.sum() > 0
    assert checked >= 1  # some car showed its cabin to the LiDAR

    cams = labels[labels["sensor_type"] == "camera"]
    instance = record.instance("front", frame)
    visible = cams[cams["visible"]]
    assert set(visible["track_id"]) == set(np.unique(instance[instance > 0]).tolist())


def test_a_bad_mesh_fails_before_any_output_naming_rig_mesh_and_key(dense_highway_run, tmp_path, capsys):
    obj = write_obj(tmp_path)
    rig_path = tmp_path / "rig.yaml"
    rig_path.write_text(yaml.safe_dump({
        "name": "mine",
        "cameras": [{"name": "front", "width_px": 160, "height_px": 120, "mount": {"xyz_m": [0, 0, 1]}}],
        "actor_meshes": [{"cls": "bus", "path": "wedge.obj", "material": {"glass": "glas"}}]}))
    out = tmp_path / "record"
    assert cli(["render", "--sim", str(dense_highway_run), "--condition", "noon", "--rig", str(rig_path),
                "--out", str(out), "--frames", "1", "--workers", "1", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"{rig_path}: {obj}: actor_meshes[0].material: unknown material 'glas'; known: asphalt" in err
    assert not out.exists() and not list(tmp_path.glob(".*partial"))


def test_workers_read_the_rigs_meshes_too(dense_highway_run, tmp_path):
    """Rendered by a pool (after a render in this process started Embree, so its workers come from a forkserver
    and read the meshes from the pickled rig), the record is the one rendered here, byte for byte."""
    from pipeline.core.config import ConditionConfig, RigConfig, load_config
    from pipeline.stages.render import render
    from pipeline.world.scene import embree_started

    write_obj(tmp_path)
    rig_path = tmp_path / "rig.yaml"
    rig_path.write_text(yaml.safe_dump({
        "name": "mine", "lidars": [{"name": "top", "channels": 16, "horizontal_resolution_deg": 0.8,
                                    "mount": {"xyz_m": [0.0, 0.0, 1.05]}}],
        "actor_meshes": [{"cls": c, "path": "wedge.obj", "material": {"glass": "glass"}} for c in ("car", "van")]}))
    rig = load_config(RigConfig, rig_path, "rigs")[0]
    noon = load_config(ConditionConfig, "noon", "conditions")[0]
    render(dense_highway_run, noon, rig, tmp_path / "here", frames=2, workers=1, shard_size=1, progress=False)
    assert embree_started()
    render(dense_highway_run, noon, rig, tmp_path / "pool", frames=2, workers=2, shard_size=1, progress=False)
    assert tree_hashes(tmp_path / "here", skip=("meta.json",)) == tree_hashes(tmp_path / "pool", skip=("meta.json",))
    labels = DatasetRecord(tmp_path / "pool").labels
    assert (labels["lidar_points"] > 0).any()
