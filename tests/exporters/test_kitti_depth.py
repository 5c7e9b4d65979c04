"""The KITTI depth export read back as the benchmark's tools read it: uint16 PNGs through Pillow and OpenCV, depth =
value / 256, valid = value > 0 (the devkit's readme); calibration files through a pykitti-style parser.

Closed-form cases on the synthetic records (a flat ground whose z-depth per row is known on paper; LiDAR points placed
at chosen camera coordinates), and the real rendered record (``rendered`` in conftest.py) for the round trip and for
the sparse map's agreement with the dense ground truth.
"""

from __future__ import annotations

import contextlib
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
from PIL import Image

from exporters.base import ExportError, ExportOptions, get_exporter
from exporters.splits import SplitSpec
from pipeline.core.classes import SemanticClass
from pipeline.core.record import POINT_COLUMNS, RECORD_FILE, DatasetRecord, lidar_path
from pipeline.core.tables import write_parquet
from tests.conftest import tree_hashes
from tests.exporters.synthetic_record import CAMERA_MOUNT, FIRST_FRAME, GROUND_Z_EGO, HEIGHT, WIDTH
from tests.exporters.test_export_requirements import strip

DRIVE = "2026_01_01_drive_{:04d}_sync"
GT = "proj_depth/groundtruth/image_02"
RAW = "proj_depth/velodyne_raw/image_02"


def read_png_m(path: Path) -> np.ndarray:
    """(H, W) float64 metres of a KITTI depth PNG, read by Pillow as the devkit defines it (0 = no measurement)."""
    with Image.open(path) as image:
        assert image.mode.startswith("I") and image.size == (WIDTH, HEIGHT)  # one 16-bit channel
        values = np.array(image).astype(np.int64)
    assert values.ndim == 2 and values.min() >= 0 and values.max() <= 65535
    return values / 256.0


def read_calib(path: Path) -> dict[str, np.ndarray]:
    """A raw-KITTI calib file as pykitti's ``read_calib_file`` reads it: 'key: floats', other lines skipped."""
    data = {}
    for line in path.read_text().splitlines():
        key, value = line.split(":", 1)
        with contextlib.suppress(ValueError):  # calib_time
            data[key] = np.array([float(x) for x in value.split()])
    return data


def velo_to_image(drive: Path) -> np.ndarray:
    """(3, 4) LiDAR point -> image_02 pixel projection, composed as the raw-data readers do:
    P_rect_02 @ R_rect_00 @ [R | T] (velo_to_cam)."""
    cam = read_calib(drive / "calib_cam_to_cam.txt")
    velo = read_calib(drive / "calib_velo_to_cam.txt")
    r_rect = np.eye(4)
    r_rect[:3, :3] = cam["R_rect_00"].reshape(3, 3)
    velo_to_cam = np.eye(4)
    velo_to_cam[:3, :3], velo_to_cam[:3, 3] = velo["R"].reshape(3, 3), velo["T"]
    return cam["P_rect_02"].reshape(3, 4) @ r_rect @ velo_to_cam


@pytest.fixture(scope="module")
def merged(tmp_path_factory, records) -> Path:
    out = tmp_path_factory.mktemp("kd") / "kitti_depth"
    get_exporter("kitti-depth").export(records, out, ExportOptions(splits=SplitSpec.parse("val=urban:2,train=*")))
    return out


def test_layout_mapping_and_description(merged):
    drives = {1: ("train", "highway", 1, "morning"), 2: ("train", "highway", 1, "night"),
              3: ("val", "urban", 2, "morning")}
    assert sorted(p.name for p in merged.iterdir()) == ["export.json", "mapping.txt", "train", "val"]
    assert sorted(p.name for p in (merged / "val").iterdir()) == [DRIVE.format(3)]
    for n, (split, *_) in drives.items():
        drive = merged / split / DRIVE.format(n)
        assert sorted(p.name for p in drive.iterdir()) == [
            "calib_cam_to_cam.txt", "calib_imu_to_velo.txt", "calib_velo_to_cam.txt", "image_02", "proj_depth"]
        for sub in ("image_02/data", GT, RAW):
            assert sorted(p.name for p in (drive / sub).iterdir()) == ["0000000000.png", "0000000001.png"]
    mapping = [line.split() for line in (merged / "mapping.txt").read_text().splitlines()]
    assert mapping[0] == ["train", DRIVE.format(1), "0000000000", "highway", "1", "morning", str(FIRST_FRAME),
                          "1.000000"]
    assert [(m[0], m[1], m[3], m[5], m[6]) for m in mapping][-1] == ("val", DRIVE.format(3), "urban", "morning", "11")
    counts = json.loads((merged / "export.json").read_text())["counts"]
    assert counts["frames"] == 6 and counts["drives_per_split"] == {"train": 2, "val": 1}
    assert {name: (d["split"], d["scenario"], d["seed"], d["condition"]) for name, d in counts["drives"].items()} == {
        DRIVE.format(n): v for n, v in drives.items()}
    # the synthetic ground reaches past 255.99 m near the horizon: those pixels were rewritten as 0
    assert counts["groundtruth_rewritten"] == 6 and counts["groundtruth_saturated_px"] > 0


def test_groundtruth_is_the_flat_grounds_z_depth(merged, morning):
    """The synthetic ground seen at row r (pixel centre r + 0.5) lies at z-depth h fy / (r + 0.5 - cy), h the camera's
    height; farther than 255.99 m (near the horizon) and above it: 0."""
    record = DatasetRecord(morning)
    for index, frame in enumerate((FIRST_FRAME, FIRST_FRAME + 1)):
        gt = read_png_m(merged / "train" / DRIVE.format(1) / GT / f"{index:010d}.png")
        rows = np.arange(HEIGHT) + 0.5
        with np.errstate(divide="ignore"):
            ground = np.where(rows > 300.0, (CAMERA_MOUNT[2] - GROUND_Z_EGO) * 400.0 / (rows - 300.0), np.inf)
        expected = np.where(ground < 65534.5 / 256, ground, 0.0)[:, None] * np.ones((1, WIDTH))
        free = record.instance("front", frame) == 0
        assert np.abs(gt - expected)[free].max() <= 1 / 512
        assert (gt[free] == 0).sum() == ((expected == 0) & free).sum() > 0
        assert (gt[~free] > 0).all()  # every object pixel has a depth


def test_groundtruth_round_trip_of_a_rendered_record(rendered, tmp_path):
    """Pillow's uint16 / 256 gives back the record's depth where valid (one rounding: within 1/512 m) and 0 elsewhere;
    OpenCV reads the same values."""
    get_exporter("kitti-depth").export([rendered], tmp_path / "kd")
    record = DatasetRecord(rendered)
    drive = tmp_path / "kd" / "train" / DRIVE.format(1)
    for index, frame in enumerate(record.frames["frame"]):
        depth, valid = record.depth_m("front", int(frame))
        path = drive / GT / f"{index:010d}.png"
        gt = read_png_m(path)
        assert valid.sum() > 0.3 * valid.size
        assert np.abs(gt - depth)[valid].max() <= 1 / 512 and (gt[~valid] == 0).all() and (gt[valid] > 0).all()
        np.testing.assert_array_equal(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), np.rint(gt * 256).astype(np.uint16))
        assert cv2.imread(str(drive / "image_02" / "data" / f"{index:010d}.png")).shape == (HEIGHT, WIDTH, 3)


def test_sparse_map_of_points_at_known_camera_coordinates(tmp_path, morning):
    """LiDAR points placed at chosen camera coordinates (x, y, z) land on pixel (floor(fx x/z + cx), floor(fy y/z +
    cy)) with value round(256 z): fx = fy = 400, cx = 400, cy = 300 (synthetic_record.py). The nearer of two points on
    one pixel wins; points behind the camera, outside the image or 255.998 m or farther are left out."""
    root = tmp_path / "record"
    shutil.copytree(morning, root)
    cam_xyz = np.array([
        [1.13, -0.52, 10.0],  # u 445.2, v 279.2 -> (445, 279), 2560
        [1.695, -0.78, 15.0],  # same pixel, farther: hidden
        [-2.02, 1.02, 20.0 + 0.4 / 256],  # u 359.60, v 320.40 -> (359, 320), 5120.4 -> 5120
        [2.02, 1.02, 20.0 + 0.6 / 256],  # u 440.40 -> (440, 320), 5120.6 -> 5121
        [0.0, 0.0, -5.0],  # behind the camera
        [12.0, 0.0, 10.0],  # u 880: right of the image
        [0.5, -0.3, 300.0],  # in the image, too far for uint16 / 256
        [0.31, -0.23, 255.99],  # u 400.48, v 299.64 -> (400, 299), 65533.44 -> 65533
        [-9.99, 0.0513, 10.0],  # u 0.4, v 302.05 -> (0, 302), 2560
    ])
    expected = {(279, 445): 2560, (320, 359): 5120, (320, 440): 5121, (299, 400): 65533, (302, 0): 2560}
    info = DatasetRecord(root).info
    lidar_from_cam = np.linalg.inv(info.lidars[0].T_array) @ info.cameras[0].T_array
    xyz = cam_xyz @ lidar_from_cam[:3, :3].T + lidar_from_cam[:3, 3]
    n = len(xyz)
    sweep = pd.DataFrame({"x_m": xyz[:, 0], "y_m": xyz[:, 1], "z_m": xyz[:, 2], "intensity": 0.5, "ring": np.arange(n),
                          "instance_id": 0, "semantic": 1}).astype(POINT_COLUMNS)
    write_parquet(sweep, lidar_path(root, "top", FIRST_FRAME))
    out = tmp_path / "kd"
    description = get_exporter("kitti-depth").export([root], out)
    drive = out / "train" / DRIVE.format(1)
    sparse = cv2.imread(str(drive / RAW / "0000000000.png"), cv2.IMREAD_UNCHANGED)
    assert sparse.dtype == np.uint16 and sparse.shape == (HEIGHT, WIDTH)
    assert {(int(r), int(c)): int(sparse[r, c]) for r, c in zip(*np.nonzero(sparse), strict=True)} == expected
    assert description["counts"]["lidar_points_too_far"] == 1
    # the calibration files, composed as the raw-data readers do, take the points to the same pixels and z-depths
    uvw = (velo_to_image(drive) @ np.hstack([xyz, np.ones((n, 1))]).T).T
    np.testing.assert_allclose(uvw[:, 2], cam_xyz[:, 2], atol=1e-5)
    pixels = [(int(np.floor(v / w)), int(np.floor(u / w))) for u, v, w in uvw[[0, 2, 3, 7, 8]]]
    assert pixels == list(expected)


def reference_projection(record: DatasetRecord, frame: int) -> tuple[np.ndarray, np.ndarray]:
    """The sparse map by its definition, one point at a time in order of distance (no code of the exporter's): the
    (H, W) uint16 value round(256 z) of the nearest point per pixel (pixel = floor of the pinhole projection, values
    1..65534 kept) and the (H, W) semantic class of that point (255 where none)."""
    cam, lidar = record.info.cameras[0], record.info.lidars[0]
    cloud = record.points(lidar.name, frame)
    xyz1 = np.hstack([cloud[["x_m", "y_m", "z_m"]].to_numpy(np.float64), np.ones((len(cloud), 1))])
    cam_xyz = (np.linalg.inv(cam.T_array) @ lidar.T_array @ xyz1.T).T[:, :3]
    value = np.zeros((HEIGHT, WIDTH), np.uint16)
    semantic = np.full((HEIGHT, WIDTH), 255, np.uint8)
    (fx, _, cx), (_, fy, cy) = cam.K_array[:2]
    for i in np.argsort(-cam_xyz[:, 2], kind="stable"):  # far to near: the nearest is written last
        x, y, z = cam_xyz[i]
        col, row, v = np.floor(fx * x / z + cx), np.floor(fy * y / z + cy), np.rint(z * 256) if z > 0 else 0
        if z > 0 and 0 <= col < WIDTH and 0 <= row < HEIGHT and 1 <= v <= 65534:
            value[int(row), int(col)], semantic[int(row), int(col)] = v, cloud["semantic"].iat[i]
    return value, semantic


@pytest.mark.slow
def test_sparse_map_agrees_with_the_groundtruth_on_the_road(rendered, tmp_path):
    """The sparse map is the reference projection of the record's sweep, pixel for pixel. Where that pixel's point and
    the camera (in the pixel and its 8 neighbours) both see road, the two maps agree: the road is flat there, and a
    point the LiDAR sees from its higher mount past a step the camera cannot see over (terrain beyond a raised road
    edge) is another class, so it is left out. The point may hit anywhere in the pixel, the ground truth is the depth
    at its centre: on a plane 1/z is linear in (u, v), so the depth anywhere in the pixel lies between the extremes of
    the 3x3 centres around it. Tolerance beyond those: 6 sigma of the default rig's LiDAR range noise (0.02 m; z =
    range cos(angle to the axis) moves by at most the range error) plus one rounding of each map (1/512 m each). A
    ray length instead of a z-depth would be up to sqrt(2) times longer at the image's sides: the check includes
    pixels far off the axis."""
    tolerance = 6 * 0.02 + 2 / 512
    road_classes = [SemanticClass.ROAD, SemanticClass.LANE_MARKING]
    get_exporter("kitti-depth").export([rendered], tmp_path / "kd")
    record = DatasetRecord(rendered)
    drive = tmp_path / "kd" / "train" / DRIVE.format(1)
    checked = off_axis = 0
    for index, frame in enumerate(record.frames["frame"]):
        gt = read_png_m(drive / GT / f"{index:010d}.png")
        path = drive / RAW / f"{index:010d}.png"
        value, point_class = reference_projection(record, int(frame))
        np.testing.assert_array_equal(cv2.imread(str(path), cv2.IMREAD_UNCHANGED), value)
        sparse = read_png_m(path)
        road = np.isin(record.semantic("front", int(frame)), road_classes) & (gt > 0)
        windows = np.lib.stride_tricks.sliding_window_view(np.pad(gt, 1), (3, 3))
        lo, hi = windows.min(axis=(2, 3)), windows.max(axis=(2, 3))
        all_road = np.lib.stride_tricks.sliding_window_view(np.pad(road, 1), (3, 3)).all(axis=(2, 3))
        check = all_road & (sparse > 0) & np.isin(point_class, road_classes)
        assert check.sum() > 500
        s = sparse[check]
        bad = (s < lo[check] - tolerance) | (s > hi[check] + tolerance)
        assert not bad.any(), (frame, np.argwhere(check)[bad][:5], s[bad][:5], gt[check][bad][:5])
        checked += int(check.sum())
        cols = np.nonzero(check)[1]
        off_axis += int((np.abs(cols + 0.5 - 400) > 250).sum())  # rays more than 32 deg off the axis: ratio > 1.18
    assert checked > 2000 and off_axis > 50


def test_same_records_same_bytes_linked_or_copied(tmp_path, rendered, morning):
    a, b = tmp_path / "a", tmp_path / "b"
    get_exporter("kitti-depth").export([rendered, morning], a)
    get_exporter("kitti-depth").export([morning, rendered], b, ExportOptions(link_images=False))
    # export.json counts the linked and the copied images; every other byte is the same
    assert tree_hashes(a, skip=("export.json",)) == tree_hashes(b, skip=("export.json",))
    assert len(tree_hashes(a)) == 2 * (3 * 2 + 3) + 2


def _leftovers(parent: Path) -> list[str]:
    return sorted(p.name for p in parent.iterdir() if ".tmp-" in p.name)


def test_a_record_without_a_lidar_is_refused_naming_it(tmp_path_factory, tmp_path, morning):
    camera_only = shutil.copytree(morning, tmp_path_factory.mktemp("kd") / "camera-1-noon")
    info = json.loads((camera_only / RECORD_FILE).read_text())
    (camera_only / RECORD_FILE).write_text(json.dumps({**info, "condition": "noon"}))
    strip(camera_only, cameras=True)
    out = tmp_path / "out"
    with pytest.raises(ExportError, match=r"camera-1-noon: the record has no LiDAR \(cameras \[front\], LiDARs \[\], "
                                          r"radars \[\]\); a kitti-depth export writes .* \(proj_depth/velodyne_raw\)"):
        get_exporter("kitti-depth").export([morning, camera_only], out)
    assert not out.exists() and _leftovers(tmp_path) == []


@pytest.mark.parametrize(("remove", "match"), [
    ("cameras/front/depth", r"the record has no depth image of camera front for frame 10 \(.*000010.png is missing\)"),
    ("cameras/front/depth/000011.png", r"the record has no depth image of camera front for frame 11"),
    ("lidars/top/000011.parquet", r"the record has no sweep of LiDAR top for frame 11 \(.*000011.parquet is missing\)"),
])
def test_a_record_without_depth_or_sweeps_is_refused_before_writing(tmp_path, morning, night, remove, match):
    root = tmp_path / "highway-1-broken"
    shutil.copytree(morning, root)
    info = json.loads((root / RECORD_FILE).read_text())
    (root / RECORD_FILE).write_text(json.dumps({**info, "condition": "broken"}))
    target = root / remove
    shutil.rmtree(target) if target.is_dir() else target.unlink()
    out = tmp_path / "out"
    with pytest.raises(ExportError, match=rf"highway-1-broken: {match}"):
        get_exporter("kitti-depth").export([night, root], out)
    assert not out.exists() and _leftovers(tmp_path) == []


def test_a_distorted_camera_is_refused(tmp_path, morning):
    root = tmp_path / "record"
    shutil.copytree(morning, root)
    info = json.loads((root / RECORD_FILE).read_text())
    info["cameras"][0]["distortion"] = [-0.1, 0.0, 0.0, 0.0, 0.0]
    (root / RECORD_FILE).write_text(json.dumps(info))
    with pytest.raises(ExportError, match="camera front has lens distortion"):
        get_exporter("kitti-depth").export([root], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_cli_exports_kitti_depth_and_refuses_the_object_filter(tmp_path, morning, capsys):
    from pipeline.stages.cli import main

    out = tmp_path / "kd"
    assert main(["export", "--dataset", str(morning), "--format", "kitti-depth", "--out", str(out), "--camera", "front",
                 "--lidar", "top", "--copy-images", "--no-progress"]) == 0
    assert json.loads((out / "meta.json").read_text())["config"]["format"] == "kitti-depth"
    assert json.loads((out / "export.json").read_text())["counts"]["images_copied"] == 2
    assert main(["export", "--dataset", str(morning), "--format", "kitti-depth", "--out", str(tmp_path / "x"),
                 "--min-visible-px", "5", "--no-progress"]) == 2
    assert "--min-visible-px applies to --format coco" in capsys.readouterr().err and not (tmp_path / "x").exists()
