"""Properties every format shares: determinism, atomicity, clear errors on bad records; registry; splits."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from exporters.base import ExportError, ExportOptions, formats, get_exporter
from exporters.splits import SplitError, SplitSpec
from pipeline.core.record import RecordError
from tests.conftest import tree_hashes

FORMATS = ["coco", "kitti", "yolo", "mcap", "rosbag2", "mot", "kitti-tracking", "nuscenes", "kitti-depth",
           "cityscapes"]


def _out(base: Path, fmt: str) -> Path:
    return base / ("export.mcap" if fmt == "mcap" else "export")


def _hashes(path: Path) -> dict[str, str]:
    if path.is_file():
        return {path.name: hashlib.sha256(path.read_bytes()).hexdigest()}
    return tree_hashes(path)


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if ".tmp-" in p.name or ".old-" in p.name)


@pytest.mark.parametrize("fmt", FORMATS)
def test_same_input_same_bytes(tmp_path, morning, night, fmt):
    a, b = _out(tmp_path / "a", fmt), _out(tmp_path / "b", fmt)
    get_exporter(fmt).export([morning, night], a)
    get_exporter(fmt).export([night, morning], b)  # argument order does not matter either
    assert _hashes(a) == _hashes(b) and len(_hashes(a)) > 0


@pytest.fixture(scope="module")
def broken(tmp_path_factory, morning) -> Path:
    """A copy of ``morning`` whose second frame lost its RGB image: exports fail half-way."""
    root = tmp_path_factory.mktemp("broken") / "record"
    shutil.copytree(morning, root)
    (root / "cameras" / "front" / "rgb" / "000011.png").unlink()
    return root


@pytest.mark.parametrize("fmt", FORMATS)
def test_failure_half_way_leaves_no_output(tmp_path, broken, fmt):
    out = _out(tmp_path, fmt)
    with pytest.raises(RecordError, match="000011.png"):
        get_exporter(fmt).export([broken], out)
    assert not out.exists() and _leftovers(tmp_path) == []


@pytest.mark.parametrize("fmt", ["coco", "mcap"])
def test_failure_keeps_previous_output(tmp_path, morning, broken, fmt):
    out = _out(tmp_path, fmt)
    get_exporter(fmt).export([morning], out)
    before = _hashes(out)
    with pytest.raises(RecordError):
        get_exporter(fmt).export([broken], out)
    assert _hashes(out) == before and _leftovers(tmp_path) == []


@pytest.mark.parametrize("fmt", FORMATS)
def test_missing_record_fails_clearly(tmp_path, fmt):
    with pytest.raises(RecordError, match="not found"):
        get_exporter(fmt).export([tmp_path / "nope"], _out(tmp_path, fmt))
    (tmp_path / "empty").mkdir()
    with pytest.raises(RecordError, match="not a roadsynth dataset record"):
        get_exporter(fmt).export([tmp_path / "empty"], _out(tmp_path, fmt))
    assert not _out(tmp_path, fmt).exists()


def test_other_schema_version_fails_clearly(tmp_path, morning):
    root = tmp_path / "old"
    shutil.copytree(morning, root)
    info = json.loads((root / "record.json").read_text())
    (root / "record.json").write_text(json.dumps({**info, "schema_version": 0}))
    with pytest.raises(RecordError, match="schema_version 0 is not supported"):
        get_exporter("coco").export([root], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_same_record_twice_is_an_error(tmp_path, morning):
    with pytest.raises(RecordError, match="same run and condition"):
        get_exporter("coco").export([morning, morning], tmp_path / "out")


def test_registry_lists_known_formats():
    registered = ["coco", "kitti", "yolo", "mcap", "rosbag2", "nuscenes", "mot", "kitti-tracking", "cityscapes",
                  "kitti-depth"]
    assert formats() == registered and set(FORMATS) <= set(registered)
    with pytest.raises(KeyError, match=f"known formats: {', '.join(registered)}"):
        get_exporter("voc")
    from exporters.base import register_format

    with pytest.raises(KeyError, match="already registered"):
        register_format("coco", "exporters.coco")


def test_splits_keep_runs_whole_and_are_recorded(tmp_path, records):
    spec = SplitSpec.parse("train=0.5,val=0.5")
    out = tmp_path / "yolo"
    desc = get_exporter("yolo").export(records, out, ExportOptions(splits=spec))
    runs = desc["splits"]["runs"]
    assert set(runs) == {"highway:1", "urban:2"} and set(runs.values()) == {"train", "val"}
    by_split = {s: sorted(p.name for p in (out / "images" / s).iterdir()) for s in ("train", "val")}
    for split, names in by_split.items():  # each split holds exactly the frames of the runs assigned to it
        assert {n.split("_s")[0] for n in names} == {r.split(":")[0] for r, s in runs.items() if s == split}
    highway = next(s for s, names in by_split.items() if names[0].startswith("highway"))
    assert {n.split("_")[2] for n in by_split[highway]} == {"morning", "night"}  # both conditions of the run
    assert json.loads((out / "export.json").read_text())["splits"]["spec"] == {"fractions": {"train": 0.5, "val": 0.5}}


def test_split_spec_parsing_and_assignment():
    runs = [("highway", s) for s in range(10)]
    assignment = SplitSpec.parse("train=0.7,val=0.2,test=0.1").assign(runs)
    assert sorted(assignment.values()).count("train") == 7 and list(assignment.values()).count("test") == 1
    assert SplitSpec.parse("train=0.7,val=0.2,test=0.1").assign(runs[::-1]) == assignment
    explicit = SplitSpec.parse("val=highway:3+highway:4,train=*").assign(runs)
    assert [r for r, s in explicit.items() if s == "val"] == [("highway", 3), ("highway", 4)]
    for bad, match in (("train=0.7,val=0.2", "sum to 1"), ("train", "NAME=VALUE"), ("train=highway", "SCENARIO:SEED"),
                       ("train=*,val=*", "only one split")):
        with pytest.raises(SplitError, match=match):
            SplitSpec.parse(bad)
    with pytest.raises(SplitError, match="in no split"):
        SplitSpec.parse("val=highway:3").assign(runs)
    with pytest.raises(SplitError, match="not among"):
        SplitSpec.parse("val=urban:3,train=*").assign(runs)


def test_points_are_typed_writeable_and_checked(tmp_path, morning):
    """``DatasetRecord.points`` (read straight from Arrow): schema dtypes, a frame callers may modify,
    and a missing column named with its file."""
    import numpy as np
    import pyarrow.parquet as pq

    from pipeline.core.record import POINT_COLUMNS, DatasetRecord, lidar_path

    record = DatasetRecord(morning)
    frame = int(record.frames["frame"].iloc[0])
    points = record.points("top", frame)
    assert dict(points.dtypes.astype(str)) == POINT_COLUMNS
    table = pq.read_table(lidar_path(morning, "top", frame))
    assert np.array_equal(points["x_m"].to_numpy(), table.column("x_m").to_numpy())
    columns = record.point_columns("top", frame)
    assert {c: str(a.dtype) for c, a in columns.items()} == POINT_COLUMNS
    assert all(np.array_equal(columns[c], points[c].to_numpy()) for c in POINT_COLUMNS)
    points.loc[0, "x_m"] = 1.5  # not a read-only view of the Arrow buffers
    assert columns["x_m"][0] != 1.5
    copy = tmp_path / "rec"
    shutil.copytree(morning, copy)
    path = lidar_path(copy, "top", frame)
    pq.write_table(pq.read_table(path).drop_columns(["ring"]), path)
    with pytest.raises(RecordError, match=r"000\d+\.parquet: missing columns ring"):
        DatasetRecord(copy).points("top", frame)
    with pytest.raises(RecordError, match=r"000\d+\.parquet: missing columns ring"):
        DatasetRecord(copy).point_columns("top", frame)


@pytest.mark.parametrize("fmt", ["coco", "kitti", "yolo"])
def test_a_visible_object_without_a_box_fails_naming_it(tmp_path, morning, fmt):
    """A record whose labels say an object is visible but give it no 2D box is refused, not silently dropped."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    copy = tmp_path / "rec"
    shutil.copytree(morning, copy)
    table = pq.read_table(copy / "labels.parquet")
    labels = table.to_pandas()
    row = labels.index[(labels.sensor == "front") & (labels.frame == 10) & (labels.visible_px >= 20)][0]
    labels.loc[row, ["x1", "x2"]] = np.nan
    pq.write_table(pa.Table.from_pandas(labels, schema=table.schema, preserve_index=False), copy / "labels.parquet")
    with pytest.raises(ExportError, match=rf"track {labels.track_id[row]}.* without a tight 2D box|"
                                          rf"track {labels.track_id[row]} is visible but has no tight 2D box"):
        get_exporter(fmt).export([copy], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_depth_reads_metres_and_marks_no_hit_and_saturation_invalid(tmp_path, morning):
    import cv2

    from pipeline.core.record import DatasetRecord

    copy = tmp_path / "rec"
    shutil.copytree(morning, copy)
    record = DatasetRecord(copy)
    path = record.image_path("front", "depth", 10)
    raw = np.zeros((600, 800), np.uint16)
    raw[0, :3] = [0, 2560, 65535]  # no hit, 10 m, 255.996 m or farther
    cv2.imwrite(str(path), raw)
    depth, valid = record.depth_m("front", 10)
    assert depth[0, 1] == 10.0 and valid[0, :3].tolist() == [False, True, False]
