"""KITTI label and calib readers: fields, shapes, and errors naming file, line and field."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from evaluation.kitti import KittiFormatError, read_calib, read_label_dir, read_label_file

DATA = Path(__file__).resolve().parents[1] / "data" / "kitti"
GOOD = "Car 0.00 0 -1.58 587.01 173.33 614.12 200.12 1.65 1.67 3.64 -0.65 1.71 46.70 -1.59"


def test_reads_fixture_fields_and_shapes(tmp_path: Path) -> None:
    shutil.copy(DATA / "label_000000.txt", tmp_path / "000000.txt")
    frames = read_label_dir(tmp_path, with_score=False)
    assert list(frames) == ["000000"]
    f = frames["000000"]
    assert len(f) == 3
    assert f.type.tolist() == ["Car", "Pedestrian", "DontCare"]
    assert f.bbox.shape == (3, 4) and f.bbox.dtype == np.float64
    assert f.dimensions.shape == (3, 3) and f.location.shape == (3, 3)
    assert f.occluded.dtype == np.int64 and f.occluded.tolist() == [0, 1, -1]
    np.testing.assert_allclose(f.dimensions[0], [1.65, 1.67, 3.64])  # h, w, l
    np.testing.assert_allclose(f.location[1], [-5.83, 1.71, 27.96])
    assert f.rotation_y[0] == pytest.approx(-1.59)
    assert f.score is None
    assert f.has_box3d.tolist() == [True, True, False]
    np.testing.assert_allclose(f.height_px, [200.12 - 173.33, 224.03 - 173.67, 190.13 - 169.71])


def test_detections_read_score_and_empty_files(tmp_path: Path) -> None:
    (tmp_path / "000001.txt").write_text(GOOD + " 0.75\n\n")
    (tmp_path / "000002.txt").write_text("")
    frames = read_label_dir(tmp_path, with_score=True)
    assert frames["000001"].score.tolist() == [0.75]
    assert len(frames["000002"]) == 0 and frames["000002"].score.shape == (0,)
    assert frames["000002"].bbox.shape == (0, 4)


@pytest.mark.parametrize(
    ("text", "with_score", "line", "field"),
    [
        (GOOD + "\n" + GOOD + " 0.5", False, 2, "<columns>"),
        (GOOD, True, 1, "score"),
        (GOOD.replace("46.70", "far"), False, 1, "location_z"),
        (GOOD.replace("173.33", "nan"), False, 1, "bbox_y1"),
        (GOOD + " nan", True, 1, "score"),
        (GOOD.replace("1.67", "-1.67"), False, 1, "width"),
        (GOOD.replace("614.12", "500.00"), False, 1, "bbox"),
        (GOOD.replace("Car 0.00 0", "Car 0.00 0.5"), False, 1, "occluded"),
        (GOOD + "\nCar 0 0", False, 2, "<columns>"),
        # found by the fuzz (tests/evaluation/test_reader_fuzz.py): Python's float() reads these, numpy's fast
        # parser does not, and the reader ended in "invalid content" naming no line
        (GOOD.replace("-0.65", "-0_65"), False, 1, "location_x"),
        (GOOD.replace("-0.65", "\u0661"), False, 1, "location_x"),  # an Arabic-Indic digit one
        # an occlusion level beyond -1..3 dropped the object from every difficulty; 1e300 cast to int64 is undefined
        (GOOD.replace("Car 0.00 0", "Car 0.00 7"), False, 1, "occluded"),
        (GOOD.replace("Car 0.00 0", "Car 0.00 1e300"), False, 1, "occluded"),
        (GOOD.replace("Car 0.00 0", "Car 0.00 -2"), False, 1, "occluded"),
    ],
)
def test_errors_name_file_line_and_field(tmp_path: Path, text: str, with_score: bool, line: int, field: str) -> None:
    path = tmp_path / "000007.txt"
    path.write_text(text + "\n")
    with pytest.raises(KittiFormatError) as err:
        read_label_file(path, with_score=with_score)
    message = str(err.value)
    assert f"{path}:{line}:" in message
    assert f"'{field}'" in message


@pytest.mark.parametrize("raw", [b"\x80", b"Car \xff\xfe 0 0", b"\x89PNG\r\n\x1a\n\x00\x00"])
def test_a_binary_file_names_the_file(tmp_path: Path, raw: bytes) -> None:
    """Found by the fuzz: a UnicodeDecodeError that named no file."""
    path = tmp_path / "000007.txt"
    path.write_bytes(raw)
    with pytest.raises(KittiFormatError, match=f"{path}: not a text file"):
        read_label_file(path, with_score=True)
    with pytest.raises(KittiFormatError, match=f"{path}: not a text file"):
        read_calib(path)


def test_missing_directory_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(KittiFormatError, match="not a directory"):
        read_label_dir(tmp_path / "nope", with_score=False)


def test_calib_round_trip_and_velo_to_rect() -> None:
    calib = read_calib(DATA / "calib_000000.txt")
    assert calib.P2.shape == (3, 4) and calib.R0_rect.shape == (3, 3)
    assert calib.Tr_velo_to_cam.shape == (3, 4) and calib.Tr_imu_to_velo.shape == (3, 4)
    assert calib.P2[0, 0] == pytest.approx(721.5377)
    # a point 10 m ahead of the LiDAR lands roughly 10 m ahead of the camera (z forward, y down)
    rect = calib.velo_to_rect(np.array([[10.0, 0.0, 0.0]]))
    assert rect[0, 2] == pytest.approx(10.0, abs=0.5) and abs(rect[0, 0]) < 0.5


def test_calib_errors(tmp_path: Path) -> None:
    text = (DATA / "calib_000000.txt").read_text().splitlines()
    missing = tmp_path / "missing.txt"
    missing.write_text("\n".join(line for line in text if not line.startswith("R0_rect")))
    with pytest.raises(KittiFormatError, match="R0_rect"):
        read_calib(missing)
    short = tmp_path / "short.txt"
    short.write_text("\n".join([*text[:2], "P2: 1 2 3", *text[3:]]))
    with pytest.raises(KittiFormatError, match=r"short.txt:3: field 'P2': expected 12 numbers"):
        read_calib(short)
