"""The plug-in point with an ONNX model: a tiny model built here, run through onnxruntime, its
masks turned into world detections by the same geometry as the baseline's."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from detector.detector import Detector
from detector.errors import ModelFileError
from detector.instances import Segmenter
from detector.onnx_segmenter import OnnxSegmenter
from detector.synthetic import Piece, render
from interfaces.camera import RgbdFrame

onnx = pytest.importorskip("onnx")
from onnx import TensorProto, helper  # noqa: E402

RED = (200, 40, 30)
GREEN = (40, 190, 60)
CLASSES = ["brick", "wood", "concrete"]


def _tiny_model(path: Path, *, fixed_size: tuple[int, int] | None = None) -> Path:
    """A 1x1 convolution: mask 0 = red minus green (red pixels), mask 1 = green minus red;
    constant class scores (mask 0: brick, mask 1: wood)."""
    h, w = fixed_size if fixed_size else ("H", "W")
    image = helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, h, w])
    masks = helper.make_tensor_value_info("masks", TensorProto.FLOAT, [2, h, w])
    scores = helper.make_tensor_value_info("scores", TensorProto.FLOAT, [2, 3])
    weight = helper.make_tensor(
        "weight", TensorProto.FLOAT, [2, 3, 1, 1], [1.0, -1.0, 0.0, -1.0, 1.0, 0.0]
    )
    bias = helper.make_tensor("bias", TensorProto.FLOAT, [2], [-0.2, -0.2])
    axes = helper.make_tensor("axes", TensorProto.INT64, [1], [0])
    table = helper.make_tensor("table", TensorProto.FLOAT, [2, 3], [0.9, 0.05, 0.05, 0.1, 0.8, 0.1])
    graph = helper.make_graph(
        [
            helper.make_node("Conv", ["image", "weight", "bias"], ["logits"]),
            helper.make_node("Squeeze", ["logits", "axes"], ["masks"]),
            helper.make_node("Constant", [], ["scores"], value=table),
        ],
        "tiny",
        [image],
        [masks, scores],
        initializer=[weight, bias, axes],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def _frame() -> tuple[RgbdFrame, list[Piece]]:
    pieces = [
        Piece(x_m=-0.2, y_m=-0.1, yaw_rad=0.4, length_m=0.14, width_m=0.06, height_m=0.04, rgb=RED),
        Piece(
            x_m=0.15, y_m=0.2, yaw_rad=-0.7, length_m=0.12, width_m=0.05, height_m=0.03, rgb=GREEN
        ),
    ]
    return render(pieces, seed=3), pieces


def test_an_onnx_model_plugs_in_and_gets_world_geometry(tmp_path: Path) -> None:
    segmenter = OnnxSegmenter(_tiny_model(tmp_path / "tiny.onnx"), class_names=CLASSES)
    assert isinstance(segmenter, Segmenter)
    assert segmenter.mode == "colour"
    frame, pieces = _frame()
    output = Detector(segmenter=segmenter).detect(frame)
    by_class = {i.class_name: i for i in output.instances}
    assert sorted(by_class) == ["brick", "wood"]
    for name, piece in zip(["brick", "wood"], pieces, strict=True):
        inst = by_class[name]
        d = inst.detection
        assert d is not None
        assert inst.score == pytest.approx(0.9 if name == "brick" else 0.8, abs=1e-6)
        assert math.hypot(d.x_m - piece.x_m, d.y_m - piece.y_m) < 0.003
        assert d.length_m == pytest.approx(piece.length_m, abs=0.005)
        assert d.height_m == pytest.approx(piece.height_m, abs=0.002)
    assert output.mode == "colour"  # the model's mode: it did not look at depth


def test_class_names_beside_the_model_and_a_fixed_input_size(tmp_path: Path) -> None:
    path = _tiny_model(tmp_path / "fixed.onnx", fixed_size=(240, 320))
    (tmp_path / "fixed.json").write_text(json.dumps({"class_names": CLASSES}), encoding="utf-8")
    segmenter = OnnxSegmenter(path)
    frame, _ = _frame()
    instances = segmenter.segment(frame.rgb)
    assert [i.class_name for i in instances] == ["brick", "wood"]
    assert all(i.mask.shape == (480, 640) for i in instances)
    assert frame.instance_ids is not None
    truth = frame.instance_ids == 1
    iou = (truth & instances[0].mask).sum() / (truth | instances[0].mask).sum()
    assert iou > 0.8  # resized to 320x240 and back


def test_a_model_without_class_names_or_that_is_not_onnx_is_refused(tmp_path: Path) -> None:
    path = _tiny_model(tmp_path / "nameless.onnx")
    with pytest.raises(ModelFileError, match="class_names"):
        OnnxSegmenter(path)
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ModelFileError, match="cannot load"):
        OnnxSegmenter(junk, class_names=CLASSES)
    with pytest.raises(ModelFileError, match="no such"):
        OnnxSegmenter(tmp_path / "missing.onnx", class_names=CLASSES)


def test_scores_not_matching_the_class_names_are_an_error(tmp_path: Path) -> None:
    segmenter = OnnxSegmenter(_tiny_model(tmp_path / "tiny.onnx"), class_names=["a", "b"])
    frame, _ = _frame()
    with pytest.raises(ModelFileError, match="do not match"):
        segmenter.segment(frame.rgb)


def test_the_node_options_plug_in_an_onnx_model_or_a_users_segmenter(tmp_path: Path) -> None:
    """``cdw-twin detector-node --onnx MODEL`` / ``--segmenter MODULE:CALLABLE`` build a detector
    around the user's model (what the node then runs on every frame)."""
    import argparse
    import sys

    from detector.cmd_node import configure, detector_of
    from detector.errors import DetectorConfigError
    from interfaces.camera import RgbdCameraSpec

    parser = argparse.ArgumentParser()
    configure(parser)
    path = _tiny_model(tmp_path / "tiny.onnx")
    (tmp_path / "tiny.json").write_text(json.dumps({"class_names": CLASSES}), encoding="utf-8")
    args = parser.parse_args(["--onnx", str(path)])
    detector = detector_of(args, 0.0)(RgbdCameraSpec())
    frame, pieces = _frame()
    names = sorted(i.class_name for i in detector.detect(frame).instances)
    assert names == ["brick", "wood"]
    (tmp_path / "my_models.py").write_text(
        "from detector.onnx_segmenter import OnnxSegmenter\n"
        f"def make():\n    return OnnxSegmenter({str(path)!r})\n"
        "def wrong():\n    return 42\n",
        encoding="utf-8",
    )
    sys.path.insert(0, str(tmp_path))
    try:
        args = parser.parse_args(["--segmenter", "my_models:make"])
        detector = detector_of(args, 0.0)(RgbdCameraSpec())
        assert len(detector.detect(frame).instances) == len(pieces)
        with pytest.raises(DetectorConfigError, match="returned a int, not a Segmenter"):
            detector_of(parser.parse_args(["--segmenter", "my_models:wrong"]), 0.0)
        with pytest.raises(DetectorConfigError, match="expected MODULE:CALLABLE"):
            detector_of(parser.parse_args(["--segmenter", "my_models"]), 0.0)
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("my_models", None)
