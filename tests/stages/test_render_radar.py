"""The render stage's radar: scans a plain Parquet reader finds consistent, their counts in labels.parquet, and a
radar that changes nothing else in the record (and a rig without one that writes no trace of it)."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.core.record import RADAR_COLUMNS, DatasetRecord
from pipeline.stages.render import render
from tests.conftest import tree_hashes


@pytest.fixture(scope="module")
def radar_name(small_rig) -> str:
    assert len(small_rig.radars) == 1  # the default rig's front radar
    return small_rig.radars[0].name


def test_scans_are_consistent_to_an_independent_reader(small_record, radar_name):
    info = json.loads((small_record / "record.json").read_text())
    (radar,) = info["radars"]
    assert radar["name"] == radar_name and radar["range_max_m"] == 200.0
    labels = pq.read_table(small_record / "labels.parquet").to_pandas()
    frames = pq.read_table(small_record / "frames.parquet").column("frame").to_pylist()
    moving = 0
    for frame in frames:
        path = small_record / "radars" / radar_name / f"{frame:06d}.parquet"
        table = pq.read_table(path)
        assert table.schema.names == list(RADAR_COLUMNS)
        d = {c: table.column(c).to_numpy() for c in table.schema.names}
        assert 0 < len(d["x_m"]) <= radar["max_detections"]
        xyz = np.column_stack([d["x_m"], d["y_m"], d["z_m"]]).astype(np.float64)
        np.testing.assert_allclose(d["range_m"], np.linalg.norm(xyz, axis=1), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(d["azimuth_rad"], np.arctan2(xyz[:, 1], xyz[:, 0]), atol=1e-5)
        assert (d["range_m"] <= radar["range_max_m"] + 1.0).all()
        here = labels[labels["frame"] == frame]
        ids = d["instance_id"][d["instance_id"] > 0]
        assert set(ids) <= set(here["track_id"])  # every object detected is labelled
        rows = here[here["sensor"] == radar_name].set_index("track_id")["radar_detections"]
        counted = dict(zip(*np.unique(ids, return_counts=True), strict=True))
        assert {int(k): int(v) for k, v in rows.items() if v} == {int(k): int(v) for k, v in counted.items()}
        for _, row in here[here["sensor"] != radar_name].iterrows():  # the other rows carry the same counts
            assert row["radar_detections"] == counted.get(row["track_id"], 0)
        moving += int((np.abs(d["radial_velocity_comp_mps"][d["instance_id"] > 0]) > 1.0).sum())
        static = d["instance_id"] == 0
        assert np.abs(d["radial_velocity_comp_mps"][static]).max(initial=0) < 0.5  # the world stands still
    assert moving > 0  # Doppler from the traffic
    record = DatasetRecord(small_record)
    assert len(record.radar_detections(radar_name, frames[0])) > 0
    assert "radar_detections" in record.labels.columns


@pytest.mark.slow
def test_the_radar_changes_nothing_else_and_a_rig_without_it_leaves_no_trace(run_21_frames, small_rig,
                                                                             noon_condition, small_record,
                                                                             tmp_path):
    bare = small_rig.model_copy(update={"radars": []})
    out = tmp_path / "bare"
    render(run_21_frames, noon_condition, bare, out, frames=3, workers=1, shard_size=2, progress=False)
    with_radar, without = tree_hashes(small_record), tree_hashes(out)
    assert not (out / "radars").exists()
    assert "radars" not in json.loads((out / "record.json").read_text())
    assert "radars" not in json.loads((out / "meta.json").read_text())["config"]["rig"]
    for name, digest in without.items():
        if name.startswith(("cameras/", "lidars/")) or name == "frames.parquet":
            assert with_radar[name] == digest, name
    a = pq.read_table(out / "labels.parquet").to_pandas()
    b = pq.read_table(small_record / "labels.parquet").to_pandas()
    assert "radar_detections" not in a.columns
    b = b[b["sensor_type"] != "radar"][list(a.columns)].reset_index(drop=True)
    assert a.equals(b)
