"""KITTI export read with a parser written here from the object devkit's readme.txt, then checked by geometry.

Devkit format (readme.txt of the KITTI object development kit), one object per line, 15 values:
type, truncated (0..1), occluded (0..3), alpha ([-pi, pi]), bbox left top right bottom (pixels),
dimensions height width length (m), location x y z (bottom centre, camera coordinates, m),
rotation_y ([-pi, pi]). calib files: ``P0: ..`` .. ``P3`` (3x4), ``R0_rect`` (3x3), ``Tr_velo_to_cam``
and ``Tr_imu_to_velo`` (3x4); a velodyne point X maps to the image by P2 * R0_rect * Tr_velo_to_cam * X.
velodyne .bin: float32 x, y, z, reflectance.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from exporters.base import BoxMode, ExportOptions, get_exporter
from exporters.splits import SplitSpec
from pipeline.core.record import DatasetRecord

TYPES = {"Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc", "DontCare"}


@dataclass
class KittiObject:
    type: str
    truncated: float
    occluded: int
    alpha: float
    bbox: np.ndarray  # left, top, right, bottom
    dimensions: np.ndarray  # h, w, l
    location: np.ndarray  # x, y, z
    rotation_y: float


def parse_label(path: Path) -> list[KittiObject]:
    objects = []
    for line in path.read_text().splitlines():
        f = line.split(" ")
        if len(f) != 15:
            raise ValueError(f"{path}: {len(f)} fields in {line!r}")
        if f[0] not in TYPES:
            raise ValueError(f"{path}: type {f[0]!r}")
        values = [float(v) for v in f[1:]]
        objects.append(KittiObject(f[0], values[0], int(f[2]), values[2], np.array(values[3:7]), np.array(values[7:10]),
                                   np.array(values[10:13]), values[13]))
    return objects


def parse_calib(path: Path) -> dict[str, np.ndarray]:
    shapes = {"P0": (3, 4), "P1": (3, 4), "P2": (3, 4), "P3": (3, 4), "R0_rect": (3, 3), "Tr_velo_to_cam": (3, 4),
              "Tr_imu_to_velo": (3, 4)}
    calib = {}
    for line in path.read_text().splitlines():
        key, _, rest = line.partition(":")
        calib[key] = np.array([float(v) for v in rest.split()]).reshape(shapes[key])
    assert set(calib) == set(shapes)
    return calib


def box_contains(obj: KittiObject, pts_cam: np.ndarray, margin: float) -> np.ndarray:
    """Points (N, 3) in the rectified camera frame inside the 3D box of a label (devkit's box definition)."""
    h, w, length = obj.dimensions
    rel = pts_cam - obj.location
    c, s = np.cos(obj.rotation_y), np.sin(obj.rotation_y)
    # Object frame: x along the heading (cos ry, 0, -sin ry), y down, z completes; origin at the bottom centre.
    along = rel[:, 0] * c - rel[:, 2] * s
    across = rel[:, 0] * s + rel[:, 2] * c
    return ((np.abs(along) <= length / 2 + margin) & (np.abs(across) <= w / 2 + margin)
            & (rel[:, 1] <= margin) & (rel[:, 1] >= -h - margin))


@pytest.fixture(scope="module")
def kitti_out(tmp_path_factory, morning, night) -> Path:
    out = tmp_path_factory.mktemp("kitti") / "kitti"
    get_exporter("kitti").export([night, morning], out)
    return out


def _index(out: Path, roots: list[Path]) -> list[tuple[Path, int]]:
    by_condition = {DatasetRecord(r).info.condition: r for r in roots}
    rows = [line.split() for line in (out / "mapping.txt").read_text().splitlines()]
    return [(by_condition[row[3]], int(row[4])) for row in rows]


def _check_projection(out: Path, roots: list[Path], check_bbox) -> int:
    """For each labelled object: its LiDAR points lie in its rebuilt 3D box and (check_bbox) in its 2D box."""
    checked = 0
    for i, (root, frame) in enumerate(_index(out, roots)):
        stem = f"{i:06d}"
        calib = parse_calib(out / "training" / "calib" / f"{stem}.txt")
        velo = np.fromfile(out / "training" / "velodyne" / f"{stem}.bin", dtype=np.float32).reshape(-1, 4)
        record_points = DatasetRecord(root).points("top", frame)
        np.testing.assert_array_equal(velo[:, :3], record_points[["x_m", "y_m", "z_m"]].to_numpy())
        ids = record_points["instance_id"].to_numpy()
        homo = np.hstack([velo[:, :3].astype(np.float64), np.ones((len(velo), 1))])
        cam = (calib["R0_rect"] @ calib["Tr_velo_to_cam"] @ homo.T).T
        img = (calib["P2"] @ np.hstack([cam, np.ones((len(cam), 1))]).T).T
        uv = img[:, :2] / img[:, 2:3]
        for obj in parse_label(out / "training" / "label_2" / f"{stem}.txt"):
            if obj.type == "DontCare":
                continue
            inside = box_contains(obj, cam, margin=0.03)  # labels carry 2 decimals
            track_ids = set(ids[inside]) - {0}
            assert len(track_ids) == 1, (stem, obj)
            own = ids == track_ids.pop()
            assert inside[own].all()  # every point of the object is in the box rebuilt from its label
            if check_bbox(obj):
                on_image = own & (uv[:, 0] >= 0) & (uv[:, 0] < 800) & (uv[:, 1] >= 0) & (uv[:, 1] < 600)
                x1, y1, x2, y2 = obj.bbox
                u, v = uv[on_image, 0], uv[on_image, 1]
                assert on_image.any()
                assert np.all((u >= x1 - 1) & (u <= x2 + 1) & (v >= y1 - 1) & (v <= y2 + 1)), (stem, obj)
            checked += 1
    return checked


def test_lidar_points_fall_in_2d_box_and_rebuilt_3d_box(kitti_out, morning, night):
    # Tight boxes hold the points of unoccluded objects (occluded ones may have points behind the occluder).
    assert _check_projection(kitti_out, [morning, night], lambda obj: obj.occluded == 0) == 12


def test_amodal_boxes_hold_all_points(tmp_path, morning):
    out = tmp_path / "kitti"
    get_exporter("kitti").export([morning], out, ExportOptions(box=BoxMode.AMODAL))
    assert _check_projection(out, [morning], lambda obj: True) == 6


def test_labels_follow_the_devkit(kitti_out):
    objects = parse_label(kitti_out / "training" / "label_2" / "000000.txt")
    assert [o.type for o in objects] == ["Car", "Van", "Truck", "DontCare"]  # hidden car 7 absent
    car, van, truck, dont_care = objects
    assert car.rotation_y == pytest.approx(-np.pi / 2, abs=0.006)  # ahead, driving away
    assert car.occluded == 0 and van.occluded == 1  # van 45 % occluded
    assert truck.truncated == pytest.approx(0.49, abs=0.01) and truck.bbox[0] == 0.0
    for o in (car, van, truck):
        expected = o.rotation_y - np.arctan2(o.location[0], o.location[2])
        assert np.angle(np.exp(1j * (o.alpha - expected))) == pytest.approx(0.0, abs=0.011)
        assert -np.pi <= o.alpha < np.pi and -np.pi <= o.rotation_y < np.pi
        assert o.location[1] == pytest.approx(2.35)  # bottom on the ground, 2.35 m below the camera
    np.testing.assert_allclose(car.dimensions, [1.5, 1.8, 4.5])
    assert (dont_care.truncated, dont_care.occluded, dont_care.alpha, dont_care.rotation_y) == (-1, -1, -10, -10)
    np.testing.assert_allclose(dont_care.bbox, [382, 302, 384, 310])


def test_calib(kitti_out):
    calib = parse_calib(kitti_out / "training" / "calib" / "000000.txt")
    k = np.array([[400.0, 0, 400], [0, 400, 300], [0, 0, 1]])
    for name in ("P0", "P1", "P2", "P3"):
        np.testing.assert_allclose(calib[name], np.hstack([k, np.zeros((3, 1))]))
    np.testing.assert_allclose(calib["R0_rect"], np.eye(3))
    # The LiDAR origin (0, 0, 1.8 in ego) seen from the camera (1.5, 0, 1.6 in ego, looking along +x).
    np.testing.assert_allclose(calib["Tr_velo_to_cam"][:, 3], [0.0, -0.2, -1.5], atol=1e-12)
    np.testing.assert_allclose(calib["Tr_imu_to_velo"][:, 3], [0.0, 0.0, -1.8], atol=1e-12)


def test_layout_mapping_and_image_sets(tmp_path, records):
    out = tmp_path / "kitti"
    get_exporter("kitti").export(records, out, ExportOptions(splits=SplitSpec.parse("train=highway:1,val=*")))
    for sub, ext in (("image_2", "png"), ("label_2", "txt"), ("calib", "txt"), ("velodyne", "bin")):
        assert sorted(p.name for p in (out / "training" / sub).iterdir()) == [f"{i:06d}.{ext}" for i in range(6)]
    mapping = [line.split() for line in (out / "mapping.txt").read_text().splitlines()]
    assert [m[1:4] for m in mapping[:2]] == [["highway", "1", "morning"]] * 2
    assert (out / "ImageSets" / "train.txt").read_text().split() == ["000000", "000001", "000002", "000003"]
    assert (out / "ImageSets" / "val.txt").read_text().split() == ["000004", "000005"]
