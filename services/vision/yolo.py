"""YOLO-format ONNX detector (v8/v11 output layout 1×(4+C)×N), run with onnxruntime.

No model ships with hri-fusion and none is downloaded: give a path (`--model yolov8n.onnx`, exported with
`yolo export model=yolov8n.pt format=onnx`). Pre-processing is the usual letterbox to the model's square
input (grey padding 114), RGB, 0–1; post-processing keeps boxes whose best class score reaches
`conf_threshold` and runs class-aware non-maximum suppression at `iou_threshold`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

COCO_NAMES = (
    "person bicycle car motorcycle airplane bus train truck boat traffic_light fire_hydrant stop_sign "
    "parking_meter bench bird cat dog horse sheep cow elephant bear zebra giraffe backpack umbrella handbag tie "
    "suitcase frisbee skis snowboard sports_ball kite baseball_bat baseball_glove skateboard surfboard "
    "tennis_racket bottle wine_glass cup fork knife spoon bowl banana apple sandwich orange broccoli carrot "
    "hot_dog pizza donut cake chair couch potted_plant bed dining_table toilet tv laptop mouse remote keyboard "
    "cell_phone microwave oven toaster sink refrigerator book clock vase scissors teddy_bear hair_drier toothbrush"
)
COCO_NAMES = tuple(n.replace("_", " ") for n in COCO_NAMES.split())


class ModelError(RuntimeError):
    """The model file is missing, unreadable or not a YOLO detector; the message says what to do."""


@dataclass
class Letterbox:
    scale: float
    pad_x: float
    pad_y: float


def letterbox(bgr: np.ndarray, size: int) -> tuple[np.ndarray, Letterbox]:
    """Resize keeping the aspect ratio, pad to size×size; returns the NCHW float tensor and the mapping."""
    h, w = bgr.shape[:2]
    scale = min(size / w, size / h)
    nw, nh = round(w * scale), round(h * scale)
    pad_x, pad_y = (size - nw) / 2, (size - nh) / 2
    canvas = np.full((size, size, 3), 114, np.uint8)
    left, top = int(round(pad_x - 0.1)), int(round(pad_y - 0.1))
    canvas[top:top + nh, left:left + nw] = cv2.resize(bgr, (nw, nh), interpolation=cv2.INTER_LINEAR)
    tensor = cv2.cvtColor(canvas, cv2.COLOR_BGR2RGB).astype(np.float32).transpose(2, 0, 1)[None] / 255.0
    return tensor, Letterbox(scale, left, top)


def nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float) -> list[int]:
    """Indices kept by greedy non-maximum suppression; boxes are N×4 x1,y1,x2,y2."""
    order = np.argsort(-scores)
    keep = []
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    while order.size:
        i = order[0]
        keep.append(int(i))
        rest = order[1:]
        xx1 = np.maximum(boxes[i, 0], boxes[rest, 0])
        yy1 = np.maximum(boxes[i, 1], boxes[rest, 1])
        xx2 = np.minimum(boxes[i, 2], boxes[rest, 2])
        yy2 = np.minimum(boxes[i, 3], boxes[rest, 3])
        inter = np.clip(xx2 - xx1, 0, None) * np.clip(yy2 - yy1, 0, None)
        iou = inter / (areas[i] + areas[rest] - inter + 1e-9)
        order = rest[iou < iou_threshold]
    return keep


Found = list[tuple[int, float, tuple[float, float, float, float]]]


def decode(output: np.ndarray, lb: Letterbox, image_size: tuple[int, int], conf_threshold: float,
           iou_threshold: float, classes: int | None = None) -> Found:
    """(class index, score, (x, y, w, h) in original image px) for a 1×(4+C)×N YOLO output (or 1×N×(4+C) when
    `classes` says which axis holds the 4+C attributes)."""
    pred = np.asarray(output)[0]
    if pred.ndim == 2 and not (classes and pred.shape[1] == 4 + classes != pred.shape[0]):
        pred = pred.T  # 1×(4+C)×N (v8/v11 export) -> N × (4+C); some exports are already 1×N×(4+C)
    if pred.ndim != 2 or pred.shape[1] < 5:
        raise ModelError(f"expected a 1×(4+C)×N YOLO output, got shape {np.asarray(output).shape}")
    class_scores = pred[:, 4:]
    cls = class_scores.argmax(axis=1)
    score = class_scores[np.arange(len(cls)), cls]
    sel = score >= conf_threshold
    if not sel.any():
        return []
    cx, cy, bw, bh = (pred[sel, i] for i in range(4))
    cls, score = cls[sel], score[sel]
    x1 = (cx - bw / 2 - lb.pad_x) / lb.scale
    y1 = (cy - bh / 2 - lb.pad_y) / lb.scale
    x2 = (cx + bw / 2 - lb.pad_x) / lb.scale
    y2 = (cy + bh / 2 - lb.pad_y) / lb.scale
    width, height = image_size
    boxes = np.stack([np.clip(x1, 0, width), np.clip(y1, 0, height), np.clip(x2, 0, width),
                      np.clip(y2, 0, height)], axis=1)
    out = []
    for c in np.unique(cls):  # class-aware: a cup does not suppress the bottle behind it
        idx = np.flatnonzero(cls == c)
        for k in nms(boxes[idx], score[idx], iou_threshold):
            i = idx[k]
            x1_, y1_, x2_, y2_ = (float(v) for v in boxes[i])
            if x2_ > x1_ and y2_ > y1_:
                out.append((int(c), float(score[i]), (x1_, y1_, x2_ - x1_, y2_ - y1_)))
    out.sort(key=lambda d: -d[1])
    return out


class YoloDetector:
    def __init__(self, model_path: str, names: tuple[str, ...] = COCO_NAMES, conf_threshold: float = 0.35,
                 iou_threshold: float = 0.45):
        path = Path(model_path)
        if not path.is_file():
            raise ModelError(f"ONNX model {model_path!r} not found: give the path of a YOLOv8/v11 detector exported "
                             f"to ONNX (e.g. `yolo export model=yolov8n.pt format=onnx`), or use --backend color")
        try:
            import onnxruntime as ort
        except ImportError:
            raise ModelError("onnxruntime is not installed: pip install 'hri-fusion[vision]'") from None
        try:
            self.session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise ModelError(f"onnxruntime cannot load {model_path!r}: {exc}") from None
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        dims = [d if isinstance(d, int) else None for d in inp.shape]
        if len(dims) != 4:
            raise ModelError(f"{model_path!r} takes a {len(dims)}-D input; a YOLO detector takes 1×3×H×W")
        self.size = dims[2] or dims[3] or 640
        self.names = names
        self.conf_threshold, self.iou_threshold = conf_threshold, iou_threshold

    def detect(self, bgr: np.ndarray) -> list[tuple[str, float, tuple[float, float, float, float]]]:
        tensor, lb = letterbox(bgr, self.size)
        (output,) = self.session.run(None, {self.input_name: tensor})[:1]
        found = decode(output, lb, (bgr.shape[1], bgr.shape[0]), self.conf_threshold, self.iou_threshold,
                       len(self.names))
        return [(self.names[c] if c < len(self.names) else f"class{c}", s, box) for c, s, box in found]


def read_names(path: str) -> tuple[str, ...]:
    try:
        names = tuple(line.strip() for line in Path(path).read_text().splitlines() if line.strip())
    except OSError as exc:
        raise ModelError(f"cannot read class names {path!r}: {exc}") from None
    if not names:
        raise ModelError(f"class names file {path!r} is empty: one name per line")
    return names
