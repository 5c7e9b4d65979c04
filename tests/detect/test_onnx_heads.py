"""Raw heads of YOLOX, YOLOv5 and YOLOv8 in closed form: a constant ONNX model whose output holds one
known anchor gives one known box, through the family's letterbox and back to original pixels."""

from __future__ import annotations

import math

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper

from pipeline.detect.classmap import COCO80, COCO80_IDS, names_map, read_names
from pipeline.detect.heads import anchor_grid, grid_cells, guess_family
from pipeline.detect.onnx import OnnxDetector

SIZE = 96  # network input 96x96: 12x12 + 6x6 + 3x3 = 189 cells at strides 8, 16, 32
CELLS = 189
# A 192x144 image letterboxes at scale 0.5 into 96x72: YOLOX at the top-left, YOLOv5/v8 centred (12 px on top).
IMAGE = np.zeros((144, 192, 3), np.uint8)
# The YOLOv5/v8 anchors decode to the input box (24, 24, 56, 40), i.e. (24, 12, 56, 28) without the padding on
# top, i.e. the original box (48, 24, 112, 56).
EXPECTED = [48.0, 24.0, 112.0, 56.0]


def constant_model(path, out: np.ndarray, batch: int | str = 1) -> None:
    """Input ``images`` (batch, 3, 64, 64) float; output ``out`` whatever the image."""
    value = helper.make_tensor("v", TensorProto.FLOAT, list(out.shape), out.astype(np.float32).ravel())
    graph = helper.make_graph(
        [helper.make_node("ReduceSum", ["images"], ["s"], keepdims=0),
         helper.make_node("Constant", [], ["c"], value=value),
         helper.make_node("Mul", ["s", "zero"], ["z"]),
         helper.make_node("Add", ["c", "z"], ["output"])],
        "head", [helper.make_tensor_value_info("images", TensorProto.FLOAT, [batch, 3, SIZE, SIZE])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, list(out.shape))],
        initializer=[helper.make_tensor("zero", TensorProto.FLOAT, [], [0.0])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.save(model, str(path))


def yolox_output(n_classes: int = 80) -> np.ndarray:
    out = np.zeros((1, CELLS, 5 + n_classes), np.float32)
    # stride 16 grid (6x6) starts after the 144 stride-8 cells; cell (col 2, row 1) is row-major index 1*6 + 2.
    k = 144 + 1 * 6 + 2
    out[0, k, :5] = [0.5, -0.25, math.log(2.0), 0.0, 0.9]
    out[0, k, 5 + 2] = 0.8  # car
    out[0, k + 1, 4], out[0, k + 1, 5 + 2] = 0.2, 0.2  # score 0.04: below the 0.05 threshold
    return out


def test_anchor_grid_order():
    grid, stride = anchor_grid(SIZE, SIZE)
    assert len(grid) == grid_cells(SIZE, SIZE) == CELLS
    assert grid[:3].tolist() == [[0, 0], [1, 0], [2, 0]] and grid[12].tolist() == [0, 1]
    assert grid[144 + 8].tolist() == [2, 1] and stride[144 + 8, 0] == 16 and stride[-1, 0] == 32
    assert grid[-1].tolist() == [2, 2]


def test_yolox_one_anchor_one_box(tmp_path):
    out = yolox_output()
    # centre = ((0.5 + 2) * 16, (-0.25 + 1) * 16) = (40, 12); size = (exp(log 2) * 16, exp(0) * 16) = (32, 16)
    # -> input box (24, 4, 56, 20): with the top-left letterbox (scale 0.5) the original is (48, 8, 112, 40).
    constant_model(tmp_path / "m.onnx", out)
    det = OnnxDetector(tmp_path / "m.onnx")
    assert det.family == "yolox" and det.options.channels == "bgr" and det.options.nms_iou == 0.65
    (d,) = det.predict([IMAGE])
    assert len(d.boxes) == 1 and d.boxes[0].tolist() == pytest.approx([48.0, 8.0, 112.0, 40.0], abs=1e-4)
    assert d.scores.tolist() == pytest.approx([0.72]) and d.category_ids.tolist() == [3]


def test_yolov5_one_anchor_one_box(tmp_path):
    out = np.zeros((1, 3 * CELLS, 85), np.float32)
    out[0, 200, :5] = [40, 32, 32, 16, 0.9]  # cx cy w h input px, objectness
    out[0, 200, 5 + 7] = 0.5  # truck
    constant_model(tmp_path / "m.onnx", out)
    det = OnnxDetector(tmp_path / "m.onnx")
    assert det.family == "yolov5" and det.options.placement == "centre" and det.options.nms_iou == 0.45
    (d,) = det.predict([IMAGE])
    # input (24, 24, 56, 40); centred letterbox: 12 px of padding on top -> (24, 12, 56, 28) / 0.5
    assert len(d.boxes) == 1 and d.boxes[0].tolist() == pytest.approx(EXPECTED, abs=1e-4)
    assert d.scores.tolist() == pytest.approx([0.45]) and d.category_ids.tolist() == [8]


def test_yolov8_one_anchor_one_box_and_the_last_coco_class(tmp_path):
    out = np.zeros((1, 84, CELLS), np.float32)  # channels first, no objectness
    out[0, :4, 10] = [40, 32, 32, 16]
    out[0, 4 + 79, 10] = 0.6  # index 79, toothbrush: COCO id 90
    out[0, :4, 11] = [10, 20, 4, 4]
    out[0, 4 + 9, 11] = 0.3  # index 9, traffic light: id 10
    constant_model(tmp_path / "m.onnx", out)
    det = OnnxDetector(tmp_path / "m.onnx")
    assert det.family == "yolov8" and det.options.channels == "rgb" and det.options.scale == pytest.approx(1 / 255)
    (d,) = det.predict([IMAGE])
    assert d.category_ids.tolist() == [90, 10] and d.scores.tolist() == pytest.approx([0.6, 0.3])
    assert d.boxes[0].tolist() == pytest.approx(EXPECTED, abs=1e-4)
    assert d.boxes[1].tolist() == pytest.approx([16.0, 12.0, 24.0, 20.0], abs=1e-4)  # (8, 18, 12, 22) - 12, / 0.5


def test_dynamic_batch_runs_several_images_per_call(tmp_path):
    out = np.repeat(yolox_output(), 3, axis=0)
    out[1, :, 4] = 0.0  # image 2: nothing
    constant_model(tmp_path / "m.onnx", out, batch="batch")
    det = OnnxDetector(tmp_path / "m.onnx", family="yolox", batch_size=3)
    assert det.batch == 3
    d = det.predict([IMAGE, IMAGE, IMAGE])
    assert [len(x.boxes) for x in d] == [1, 0, 1]
    assert d[2].boxes[0].tolist() == pytest.approx([48.0, 8.0, 112.0, 40.0], abs=1e-4)


def test_classwise_nms_keeps_overlapping_boxes_of_other_classes(tmp_path):
    out = np.zeros((1, 84, CELLS), np.float32)
    for k, (cls, score, dx) in enumerate([(2, 0.9, 0), (2, 0.8, 1), (7, 0.7, 1), (2, 0.6, 40)]):
        out[0, :4, k] = [20 + dx, 30, 16, 16]
        out[0, 4 + cls, k] = score
    constant_model(tmp_path / "m.onnx", out)
    (d,) = OnnxDetector(tmp_path / "m.onnx").predict([IMAGE])
    # the 0.8 car overlaps the 0.9 car at IoU 15*16 / (17*16) = 0.88 > 0.7: gone; the truck stays
    assert d.scores.tolist() == pytest.approx([0.9, 0.7, 0.6]) and d.category_ids.tolist() == [3, 8, 3]


def test_unmapped_classes_are_counted(tmp_path):
    out = yolox_output(n_classes=3)
    out[0, 144 + 8, 5:] = [0.0, 0.0, 0.8]  # class 2 of a 3-class model
    constant_model(tmp_path / "m.onnx", out)
    with pytest.raises(ValueError, match="3 classes, not COCO's 80"):
        OnnxDetector(tmp_path / "m.onnx")
    names = tmp_path / "names.txt"
    names.write_text("car\ntruck\nforklift\n")
    mapping, missing = names_map(read_names(names))
    assert mapping == {0: 3, 1: 8} and missing == ["forklift"]
    det = OnnxDetector(tmp_path / "m.onnx", class_map=mapping)
    (d,) = det.predict([IMAGE])
    assert len(d.boxes) == 0 and det.unmapped == {2: 1}


def test_guess_family_refuses_unknown_shapes():
    assert guess_family([(1, CELLS, 85)], SIZE, SIZE)[0] == "yolox"
    assert guess_family([(1, 1, 4), (1, 1), (1, 1)], SIZE, SIZE)[0] == "decoded"
    with pytest.raises(ValueError, match="fit no known head"):
        guess_family([(1, 100, 85)], SIZE, SIZE)


def test_preprocessing_per_family(tmp_path):
    red = np.zeros((144, 192, 3), np.uint8)
    red[..., 0] = 200  # RGB red
    constant_model(tmp_path / "x.onnx", yolox_output())
    x, place = OnnxDetector(tmp_path / "x.onnx")._prepare(red)  # BGR, 0-255, top-left, grey 114
    assert x.shape == (3, 96, 96) and place.dy == 0
    assert (x[2, :72] == 200).all() and (x[0, :72] == 0).all() and (x[:, 72:] == 114).all()
    out = np.zeros((1, 84, CELLS), np.float32)
    constant_model(tmp_path / "v8.onnx", out)
    x, place = OnnxDetector(tmp_path / "v8.onnx")._prepare(red)  # RGB / 255, centred
    assert place.dy == 12
    assert np.allclose(x[0, 12:84], 200 / 255) and np.allclose(x[2, 12:84], 0)
    assert np.allclose(x[:, :12], 114 / 255) and np.allclose(x[:, 84:], 114 / 255)


def test_coco80_table():
    ids = list(COCO80_IDS)
    assert len(ids) == 80 == len(set(ids)) and ids == sorted(ids)
    assert ids[0] == 1 and ids[2] == 3 and ids[5] == 6 and ids[7] == 8 and ids[-1] == 90
    assert set(range(1, 91)) - set(ids) == {12, 26, 29, 30, 45, 66, 68, 69, 71, 83}
    assert dict(COCO80)[32] == "tie"


def test_names_files_and_model_metadata(tmp_path):
    from pipeline.detect.classmap import metadata_names

    (tmp_path / "data.yaml").write_text("names:\n  0: person\n  1: Car\n  2: forklift\n")
    (tmp_path / "names.json").write_text('{"names": ["bus", "truck"]}')
    assert read_names(tmp_path / "data.yaml") == ["person", "Car", "forklift"]
    assert names_map(read_names(tmp_path / "data.yaml")) == ({0: 1, 1: 3}, ["forklift"])
    assert names_map(read_names(tmp_path / "names.json"))[0] == {0: 6, 1: 8}
    assert metadata_names("{0: 'person', 1: 'bicycle'}") == ["person", "bicycle"]  # Ultralytics' metadata
    assert metadata_names("not python") is None
    (tmp_path / "bad.yaml").write_text("names:\n  0: person\n  2: car\n")
    with pytest.raises(ValueError, match=r"bad.yaml: field 'names' keys are \[0, 2\]"):
        read_names(tmp_path / "bad.yaml")
    with pytest.raises(FileNotFoundError, match="names file not found"):
        read_names(tmp_path / "missing.txt")


def test_names_from_the_models_metadata(tmp_path):
    out = yolox_output(n_classes=3)
    constant_model(tmp_path / "m.onnx", out)
    model = onnx.load(str(tmp_path / "m.onnx"))
    onnx.helper.set_model_props(model, {"names": "{0: 'truck', 1: 'bus', 2: 'car'}"})
    onnx.save(model, str(tmp_path / "m.onnx"))
    det = OnnxDetector(tmp_path / "m.onnx")
    assert det.options.class_map == {0: 8, 1: 6, 2: 3}
    (d,) = det.predict([IMAGE])
    assert d.category_ids.tolist() == [3]  # the anchor's class 2 is 'car' by the model's own names
