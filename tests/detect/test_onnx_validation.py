"""``detect --onnx``: a model whose graph contradicts the options, or what roadsynth feeds it, is refused before the
first image, naming the model file, the option and the mismatch; non-finite boxes and scores are counted, never
dropped silently. Tiny constant models built with onnx's helper API (and the real YOLOX-nano where present)."""

from __future__ import annotations

import json
import logging
import re

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper

from pipeline.detect.onnx import OnnxDetector
from pipeline.stages.cli import main as cli_main
from tests.conftest import REPO
from tests.detect.test_onnx_heads import CELLS, IMAGE, SIZE, constant_model, yolox_output

YOLOX_NANO = REPO.parent / "shared" / "models" / "yolox_nano.onnx"
needs_yolox = pytest.mark.skipif(not YOLOX_NANO.is_file(), reason=f"{YOLOX_NANO} not present (a development model)")


def cli(argv: list[str]) -> int:
    try:
        return cli_main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)


def graph_model(path, inputs: list[tuple[str, int, list]], outputs: dict[str, np.ndarray]) -> None:
    """Inputs (name, element type, shape); each output a constant (whatever the inputs), declared with its shape."""
    nodes, zero = [], []
    for k, (name, _, _) in enumerate(inputs):
        nodes += [helper.make_node("Cast", [name], [f"f{k}"], to=TensorProto.FLOAT),
                  helper.make_node("ReduceSum", [f"f{k}"], [f"s{k}"], keepdims=0),
                  helper.make_node("Mul", [f"s{k}", "zero"], [f"z{k}"])]
        zero.append(f"z{k}")
    for j, (name, value) in enumerate(outputs.items()):
        tensor = helper.make_tensor(f"v{j}", TensorProto.FLOAT, list(value.shape), value.astype(np.float32).ravel())
        nodes += [helper.make_node("Constant", [], [f"c{j}"], value=tensor)]
        last = f"c{j}"
        for k, z in enumerate(zero):
            nodes.append(helper.make_node("Add", [last, z], [name if k == len(zero) - 1 else f"a{j}_{k}"]))
            last = f"a{j}_{k}"
    graph = helper.make_graph(
        nodes, "constant", [helper.make_tensor_value_info(n, t, s) for n, t, s in inputs],
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, list(v.shape)) for n, v in outputs.items()],
        initializer=[helper.make_tensor("zero", TensorProto.FLOAT, [], [0.0])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def image_input(shape, elem=TensorProto.FLOAT, name="images"):
    return [(name, elem, shape)]


def detections(rows: list[list[float]]) -> dict[str, np.ndarray]:
    return {"det": np.array([rows], np.float32)}


ONE_CAR = [[10, 10, 40, 30, 0.9, 3]]


# --- the input ---------------------------------------------------------------------------------


def test_a_one_channel_input_is_refused_naming_the_model_and_the_channels(tmp_path):
    path = tmp_path / "grey.onnx"
    graph_model(path, image_input([1, 1, 64, 64]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"grey\.onnx: input 'images' \[1, 1, 64, 64\] has 1 channel\(s\) "
                                         r"\(layout nchw, from the shape\); .* expected 3 channels"):
        OnnxDetector(path)


def test_a_layout_that_puts_the_channels_elsewhere_is_refused(tmp_path):
    path = tmp_path / "m.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"m\.onnx: input 'images' \[1, 3, 64, 64\] has 64 channel\(s\) "
                                         r"\(--layout nhwc\).* \(the shape fits --layout nchw\)"):
        OnnxDetector(path, layout="nhwc")
    nhwc = tmp_path / "nhwc.onnx"  # the same model channels last is read as nhwc
    graph_model(nhwc, image_input([1, 64, 64, 3]), detections(ONE_CAR))
    assert OnnxDetector(nhwc).options.layout == "nhwc"


@pytest.mark.parametrize(("size", "message"), [
    ((0, 0), r"--input-size 0 0: expected two integers > 0"),
    ((64, -1), r"--input-size 64 -1: expected two integers > 0"),
    ((32, 64), r"--input-size 32 64 contradicts input 'images' \[1, 3, 64, 64\] \(nchw\), whose size is fixed at "
               r"64x64"),
])
def test_input_sizes_that_are_not_positive_or_not_the_fixed_size_are_refused(tmp_path, size, message):
    path = tmp_path / "m.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"m\.onnx: " + message):
        OnnxDetector(path, input_size=size)
    assert OnnxDetector(path, input_size=(64, 64)).options.input_size == (64, 64)


def test_a_dynamic_input_takes_any_positive_size_and_a_half_dynamic_one_only_its_fixed_side(tmp_path):
    path = tmp_path / "dyn.onnx"
    graph_model(path, image_input(["batch", 3, "height", 64]), detections(ONE_CAR))
    assert OnnxDetector(path, input_size=(64, 48)).options.input_size == (64, 48)
    with pytest.raises(ValueError, match=r"--input-size 48 48 contradicts .* fixed at 64xany"):
        OnnxDetector(path, input_size=(48, 48))
    with pytest.raises(ValueError, match=r"dyn\.onnx: --input-size 0 48"):
        OnnxDetector(path, input_size=(0, 48))


def test_inputs_roadsynth_cannot_feed_are_refused(tmp_path):
    half = tmp_path / "half.onnx"
    graph_model(half, image_input([1, 3, 64, 64], TensorProto.FLOAT16), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"half\.onnx: input 'images' is tensor\(float16\); roadsynth feeds "
                                         r"tensor\(float\) or tensor\(uint8\)"):
        OnnxDetector(half)
    two = tmp_path / "two.onnx"
    graph_model(two, [("images", TensorProto.FLOAT, [1, 3, 64, 64]), ("scale", TensorProto.FLOAT, [1, 2])],
                detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"two\.onnx: the model has 2 inputs \('images' \[1, 3, 64, 64\] "
                                         r"tensor\(float\), 'scale' \[1, 2\] tensor\(float\)\); .* exactly one"):
        OnnxDetector(two)
    flat = tmp_path / "flat.onnx"
    graph_model(flat, image_input([1, 12288]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"flat\.onnx: input 'images' has shape \[1, 12288\]; expected an image"):
        OnnxDetector(flat)
    raw = tmp_path / "u8.onnx"  # uint8 input: raw pixels, accepted
    graph_model(raw, image_input([1, 3, 64, 64], TensorProto.UINT8), detections(ONE_CAR))
    (d,) = OnnxDetector(raw, resize="stretch").predict([np.zeros((64, 64, 3), np.uint8)])
    assert d.boxes.tolist() == [[10, 10, 40, 30]]


def test_a_batch_size_the_fixed_batch_cannot_take_is_refused(tmp_path):
    path = tmp_path / "m.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"m\.onnx: --batch-size 4: input 'images' \[1, 3, 64, 64\] has a fixed "
                                         r"batch of 1; expected --batch-size <= 1"):
        OnnxDetector(path, batch_size=4)
    with pytest.raises(ValueError, match=r"--batch-size 0: expected an integer >= 1"):
        OnnxDetector(path, batch_size=0)
    assert OnnxDetector(path).batch == 1 and OnnxDetector(path, batch_size=1).batch == 1
    dynamic = tmp_path / "dyn.onnx"
    graph_model(dynamic, image_input(["batch", 3, 64, 64]), detections(ONE_CAR))
    assert OnnxDetector(dynamic).batch == 4 and OnnxDetector(dynamic, batch_size=7).batch == 7


@pytest.mark.parametrize(("options", "message"), [
    ({"max_detections": 0}, r"--max-detections 0: expected an integer >= 1"),
    ({"score_threshold": 1.5}, r"--score-threshold 1.5: expected a score in \[0, 1\]"),
    ({"std": (0.0, 1.0, 1.0)}, r"--std 0.0 1.0 1.0: expected finite non-zero divisors"),
    ({"nms_iou": 0.0}, r"--nms-iou 0.0: expected an IoU in \(0, 1\]"),
    ({"scale": -1.0}, r"--scale -1.0: expected a finite multiplier > 0"),
    ({"output_names": ("boxes",)}, r"--output-names boxes: the model has no such output; its outputs: det"),
])
def test_options_that_could_only_fail_late_or_give_nothing_are_refused(tmp_path, options, message):
    path = tmp_path / "m.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"m\.onnx: " + message):
        OnnxDetector(path, **options)


# --- the family against the outputs --------------------------------------------------------------


def test_family_decoded_on_a_raw_yolox_head_is_refused_and_the_head_named(tmp_path):
    path = tmp_path / "yolox.onnx"
    constant_model(path, yolox_output())
    with pytest.raises(ValueError, match=r"yolox\.onnx: --family decoded reads 'detections': one output \(B, N, 6\) "
                                         rf".*; the model's outputs for a {SIZE}x{SIZE} input are output "
                                         rf"\(1, {CELLS}, 85\); they fit family yolox"):
        OnnxDetector(path, family="decoded")
    assert len(OnnxDetector(path).predict([IMAGE])[0].boxes) == 1  # auto: the one car of yolox_output


@pytest.mark.parametrize("family", ["yolox", "yolov5", "yolov8"])
def test_a_raw_family_on_a_decoded_model_is_refused(tmp_path, family):
    path = tmp_path / "ours.onnx"
    graph_model(path, image_input([1, 3, SIZE, SIZE]),
                {"boxes": np.zeros((1, 5, 4)), "scores": np.zeros((1, 5)), "classes": np.zeros((1, 5))})
    with pytest.raises(ValueError, match=rf"ours\.onnx: --family {family} reads one output .*; the model's outputs "
                                         r"for a 96x96 input are boxes \(1, 5, 4\), scores \(1, 5\), classes "
                                         r"\(1, 5\); they fit family decoded"):
        OnnxDetector(path, family=family)


def test_a_raw_family_that_does_not_fit_the_head_is_refused(tmp_path):
    path = tmp_path / "yolox.onnx"
    constant_model(path, yolox_output())
    with pytest.raises(ValueError, match=rf"--family yolov5 reads one output \(B, {3 * CELLS}, 5 \+ C\)"):
        OnnxDetector(path, family="yolov5")
    with pytest.raises(ValueError, match=rf"--family yolov8 reads one output \(B, 4 \+ C, {CELLS}\)"):
        OnnxDetector(path, family="yolov8")
    # other strides: other grids, so the head no longer fits (and no family fits: no hint)
    with pytest.raises(ValueError, match=r"--family yolox reads one output \(B, 36, 5 \+ C\) \(anchors of the grids "
                                         r"at strides \(16,\)\).* output \(1, 189, 85\)$"):
        OnnxDetector(path, family="yolox", strides=(16,))


def test_boxes_scores_classes_of_different_lengths_are_refused(tmp_path):
    path = tmp_path / "m.onnx"
    graph_model(path, image_input([1, 3, 64, 64]),
                {"boxes": np.zeros((1, 5, 4)), "scores": np.zeros((1, 4)), "classes": np.zeros((1, 5))})
    with pytest.raises(ValueError, match=r"m\.onnx: family decoded \(auto: 3 outputs .*\) reads "
                                         r"'boxes-scores-classes': three outputs"):
        OnnxDetector(path)
    with pytest.raises(ValueError, match=r"--family decoded reads 'boxes-scores-classes'"):
        OnnxDetector(path, family="decoded")
    one = tmp_path / "one.onnx"
    graph_model(one, image_input([1, 3, 64, 64]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"one\.onnx: --family decoded reads 'boxes-scores-classes': three outputs"):
        OnnxDetector(one, family="decoded", output_format="boxes-scores-classes")


# --- non-finite outputs ----------------------------------------------------------------------------


def test_a_model_whose_every_box_is_nan_fails_instead_of_finding_nothing(tmp_path):
    path = tmp_path / "nan.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), detections([[np.nan, 10, 40, 30, 0.9, 3],
                                                               [10, np.inf, 40, 30, 0.8, 3]]))
    det = OnnxDetector(path)
    out = det.predict([np.zeros((64, 64, 3), np.uint8)] * 3)
    assert [len(d.boxes) for d in out] == [0, 0, 0] and (det.rows, det.nonfinite_rows) == (6, 6)
    with pytest.raises(ValueError, match=r"nan\.onnx: all 6 of 6 output rows \(anchors or detections\) have a "
                                         r"non-finite \(NaN or inf\) box or score; expected finite outputs"):
        det.check_finite()


def test_some_non_finite_rows_are_dropped_and_counted(tmp_path, caplog):
    path = tmp_path / "some.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), detections([*ONE_CAR, [10, 10, 40, 30, np.nan, 3],
                                                               [0, 0, 20, 20, 0.7, np.nan],
                                                               [0, 0, 20, 20, 0.01, 8]]))
    det = OnnxDetector(path, resize="stretch")
    (d,) = det.predict([np.zeros((64, 64, 3), np.uint8)])
    assert d.boxes.tolist() == [[10, 10, 40, 30]] and d.category_ids.tolist() == [3]
    assert (det.rows, det.nonfinite_rows) == (4, 2)  # the 0.01 row is finite, below the threshold
    caplog.set_level(logging.WARNING, "pipeline.detect.onnx")
    det.check_finite()
    assert "some.onnx: dropped 2 of 4 output rows (anchors or detections) with a non-finite" in caplog.text


def test_non_finite_anchors_of_a_raw_head_are_counted_and_the_others_kept(tmp_path):
    out = yolox_output()
    out[0, 5, 4], out[0, 5, 5 + 2] = np.nan, 0.9  # objectness NaN: its score is NaN
    out[0, 7, 2], out[0, 7, 4], out[0, 7, 5 + 2] = 1e6, 0.9, 0.9  # exp(1e6) overflows: an infinite box
    path = tmp_path / "m.onnx"
    constant_model(path, out)
    det = OnnxDetector(path)
    with np.errstate(over="ignore"):
        (d,) = det.predict([IMAGE])
    assert len(d.boxes) == 1 and d.boxes[0].tolist() == pytest.approx([48.0, 8.0, 112.0, 40.0], abs=1e-4)
    assert (det.rows, det.nonfinite_rows) == (CELLS, 2)


def test_the_cli_fails_on_an_all_nan_model_and_writes_nothing(tmp_path, tiny_coco, capsys):
    path = tmp_path / "nan.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), detections([[np.nan, np.nan, np.nan, np.nan, 0.9, 3]]))
    out = tmp_path / "r.json"
    assert cli(["detect", "--onnx", str(path), "--coco", str(tiny_coco), "--out", str(out), "--no-progress"]) == 2
    assert "nan.onnx: all 8 of 8 output rows" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(("channels", "flags", "message"), [
    (3, ["--input-size", "0", "0"], r"m\.onnx: --input-size 0 0: expected two integers > 0"),
    (3, ["--family", "yolox"], r"m\.onnx: --family yolox reads one output \(B, 84, 5 \+ C\)"),
    (3, ["--batch-size", "2"], r"m\.onnx: --batch-size 2: input 'images' \[1, 3, 64, 64\] has a fixed batch of 1"),
    (1, [], r"m\.onnx: input 'images' \[1, 1, 64, 64\] has 1 channel"),
])
def test_the_cli_refuses_with_one_line_naming_the_model(tmp_path, tiny_coco, capsys, channels, flags, message):
    path = tmp_path / "m.onnx"
    graph_model(path, image_input([1, channels, 64, 64]), detections(ONE_CAR))
    out = tmp_path / "r.json"
    assert cli(["detect", "--onnx", str(path), "--coco", str(tiny_coco), "--out", str(out), *flags]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert re.search(message, err) and not out.exists()


# --- the real YOLOX-nano -------------------------------------------------------------------------


@needs_yolox
@pytest.mark.parametrize(("options", "message"), [
    ({"family": "decoded"}, r"--family decoded reads 'detections'.* output \(1, 3549, 85\); they fit family yolox"),
    ({"input_size": (320, 320)}, r"--input-size 320 320 contradicts input 'images' \[1, 3, 416, 416\]"),
    ({"batch_size": 2}, r"--batch-size 2: input 'images' \[1, 3, 416, 416\] has a fixed batch of 1"),
    ({"layout": "nhwc"}, r"input 'images' \[1, 3, 416, 416\] has 416 channel\(s\) \(--layout nhwc\)"),
])
def test_yolox_nano_refuses_contradicting_options(options, message):
    with pytest.raises(ValueError, match=r"yolox_nano\.onnx: " + message):
        OnnxDetector(YOLOX_NANO, **options)


@needs_yolox
def test_yolox_nano_through_the_cli_with_its_defaults(tmp_path, tiny_coco):
    out = tmp_path / "r.json"
    assert cli(["detect", "--onnx", str(YOLOX_NANO), "--coco", str(tiny_coco), "--out", str(out),
                "--no-progress"]) == 0
    assert isinstance(json.loads(out.read_text()), list)


def test_a_grey_channels_last_input_is_read_as_nhwc_and_refused_for_its_one_channel(tmp_path):
    path = tmp_path / "grey.onnx"
    graph_model(path, image_input([1, 64, 64, 1]), detections(ONE_CAR))
    with pytest.raises(ValueError, match=r"grey\.onnx: input 'images' \[1, 64, 64, 1\] has 1 channel\(s\) "
                                         r"\(layout nhwc, from the shape\)"):
        OnnxDetector(path)


def test_several_images_per_run_are_refused_when_the_outputs_have_no_batch_axis(tmp_path):
    path = tmp_path / "flat.onnx"
    graph_model(path, image_input(["batch", 3, 64, 64]), {"det": np.array(ONE_CAR, np.float32)})  # (N, 6)
    with pytest.raises(ValueError, match=r"flat\.onnx: 4 images per run \(--batch-size\), but the outputs det \(1, 6\) "
                                         r"have no batch axis.*expected --batch-size 1"):
        OnnxDetector(path)
    det = OnnxDetector(path, batch_size=1, resize="stretch")
    assert [d.boxes.tolist() for d in det.predict([np.zeros((64, 64, 3), np.uint8)] * 2)] == [[[10, 10, 40, 30]]] * 2


def test_outputs_that_fit_no_family_are_refused_naming_the_model(tmp_path):
    path = tmp_path / "odd.onnx"
    graph_model(path, image_input([1, 3, 64, 64]), {"out": np.zeros((1, 10, 9))})
    with pytest.raises(ValueError, match=r"odd\.onnx: family auto: output shapes \[\(1, 10, 9\)\] fit no known head "
                                         r"for a 64x64 input"):
        OnnxDetector(path)
