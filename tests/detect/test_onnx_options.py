"""An external ONNX detector with a constant output: pre/post-processing options in closed form."""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper

from pipeline.detect.onnx import OnnxDetector, parse_class_map


def constant_detector(path, rows: list[list[float]], size=(100, 75)) -> None:
    """Input x (1, 3, H, W) float; output det (1, N, 6) = ``rows`` whatever the image."""
    value = helper.make_tensor("v", TensorProto.FLOAT, [1, len(rows), 6], np.array(rows, np.float32).ravel())
    graph = helper.make_graph(
        [helper.make_node("ReduceSum", ["x"], ["s"], keepdims=0),
         helper.make_node("Constant", [], ["c"], value=value),
         helper.make_node("Mul", ["s", "zero"], ["z"]),
         helper.make_node("Add", ["c", "z"], ["det"])],
        "constant", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, size[1], size[0]])],
        [helper.make_tensor_value_info("det", TensorProto.FLOAT, [1, len(rows), 6])],
        initializer=[helper.make_tensor("zero", TensorProto.FLOAT, [], [0.0])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8  # onnxruntime reads up to its own IR version
    onnx.save(model, str(path))


def test_xywh_stretch_coco80(tmp_path):
    path = tmp_path / "m.onnx"
    # xywh in a 100x75 input; the image is 200x150 (x2 both ways under stretch).
    constant_detector(path, [[10, 20, 30, 40, 0.9, 2], [0, 0, 5, 5, 0.8, 9], [10, 20, 30, 40, 0.01, 2]])
    det = OnnxDetector(path, output_format="detections", box_format="xywh", resize="stretch",
                       class_map=parse_class_map("coco80"), score_threshold=0.05)
    assert det.options.input_size == (100, 75) and det.options.layout == "nchw"
    (out,) = det.predict([np.zeros((150, 200, 3), np.uint8)])
    assert len(out.boxes) == 2  # class 9 (traffic light) kept as COCO id 10: evaluate counts it
    assert out.boxes[0].tolist() == pytest.approx([20, 40, 80, 120])
    assert out.boxes[1].tolist() == pytest.approx([0, 0, 10, 10])
    assert out.category_ids.tolist() == [3, 10] and out.scores.tolist() == pytest.approx([0.9, 0.8])


def test_normalized_cxcywh_letterbox_and_nms(tmp_path):
    path = tmp_path / "m.onnx"
    constant_detector(path, [[0.5, 0.5, 0.2, 0.2, 0.9, 3], [0.51, 0.5, 0.2, 0.2, 0.8, 3]])
    det = OnnxDetector(path, output_format="detections", box_format="cxcywh", normalized=True, nms_iou=0.5)
    (out,) = det.predict([np.zeros((300, 400, 3), np.uint8)])  # letterbox scale 0.25: 100x75 input
    # centre (50, 37.5), size (20, 15) input px -> (200, 150), (80, 60) original px
    assert len(out.boxes) == 1
    assert out.boxes[0].tolist() == pytest.approx([160, 120, 240, 180])
    assert out.category_ids.tolist() == [3]


def test_class_map_parsing(tmp_path):
    assert parse_class_map('{"0": 3, "1": 8}') == {0: 3, 1: 8}
    f = tmp_path / "map.json"
    f.write_text('{"2": 6}')
    assert parse_class_map(str(f)) == {2: 6}
    with pytest.raises(ValueError, match="class-map"):
        parse_class_map("cars")
