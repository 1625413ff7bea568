"""Vision test material: the candies of data/images/tabletop/smarties.png boxed and named, a pure-colour patch, and
a tiny ONNX model with YOLO's layout whose output is planted (the detector's decoding tested without a real model)."""

from __future__ import annotations

import cv2
import numpy as np

from testkit.harness import DATA

SMARTIES = DATA / "images" / "tabletop" / "smarties.png"
# Candies of smarties.png, boxed as the colour backend boxes them; the colour as a person names it (by eye).
CANDIES = [
    ((192, 278, 56, 57), "red"),
    ((72, 232, 56, 55), "red"),
    ((261, 188, 54, 52), "red"),
    ((7, 203, 53, 51), "red"),
    ((267, 293, 55, 55), "blue"),
    ((351, 55, 53, 54), "blue"),
    ((321, 212, 53, 53), "blue"),
    ((360, 144, 53, 54), "green"),
    ((242, 91, 54, 54), "green"),
    ((179, 184, 53, 54), "orange"),
    ((125, 247, 52, 51), "brown"),
]


def hsv_patch(h_deg: float, s: float, v: float, size=(60, 60)) -> np.ndarray:
    """A patch of one HSV colour (hue in degrees, saturation and value in 0..1), as BGR."""
    hsv = np.zeros((*size, 3), np.uint8)
    hsv[..., 0], hsv[..., 1], hsv[..., 2] = round(h_deg / 2), round(s * 255), round(v * 255)
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)


def tiny_yolo(path, prediction: np.ndarray, size: int = 640) -> None:
    """An ONNX model with a YOLOv8 input/output layout whose output is `prediction` (1×(4+C)×N) for any image."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    const = numpy_helper.from_array(prediction.astype(np.float32), "planted")
    zero = numpy_helper.from_array(np.zeros((), np.float32), "zero")
    nodes = [
        helper.make_node("ReduceSum", ["images"], ["total"], keepdims=0),
        helper.make_node("Mul", ["total", "zero"], ["nothing"]),
        helper.make_node("Add", ["planted", "nothing"], ["output0"]),
    ]
    graph = helper.make_graph(
        nodes,
        "tiny_yolo",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, size, size])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(prediction.shape))],
        initializer=[const, zero],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.save(model, str(path))
