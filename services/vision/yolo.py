"""ONNX object detectors of the common YOLO export families, run with onnxruntime on the CPU.

No model ships with hri-fusion and none is downloaded: give a path (`--model yolox_nano.onnx`). The family is
read from the model's output shape (or given with `--family`) and fixes pre- and post-processing:

- `yolox`: 1×cells×(5+C), cells = Σ (H/s)(W/s) over strides 8, 16, 32; raw heads: cx = (tx+gx)·s,
  w = exp(tw)·s; score obj·cls; input BGR 0–255, letterbox top-left.
- `yolov5`: 1×(3·cells)×(5+C) (three anchors per cell); cx, cy, w, h in input px; score obj·cls; input RGB 0–1,
  letterbox centred.
- `yolov8` (also v11): 1×(4+C)×N (or 1×N×(4+C)); cx, cy, w, h in input px; score cls; input RGB 0–1, centred.

Letterbox: resize keeping the aspect ratio, pad with grey 114. Post-processing keeps boxes whose best class
score reaches `conf_threshold`, maps them back to the frame, clips, and runs class-aware NMS at `iou_threshold`,
then drops a box of another class that overlaps a better one at IoU ≥ 0.7 (one object, two labels).
A model whose outputs fit none of the families is a ModelError naming the shapes it has.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from common.cpu import available_cores
from common.language import COCO_LABELS

COCO_NAMES = COCO_LABELS  # the 80 COCO classes in the standard index order (0 person ... 79 toothbrush)
STRIDES = (8, 16, 32)
FAMILIES = ("yolox", "yolov5", "yolov8")
SAME_OBJECT_IOU = 0.7  # boxes of different classes overlapping this much are one object: the best label stays


class ModelError(RuntimeError):
    """The model file is missing, unreadable or not a detector of a known family; the message says what to do."""


@dataclass(frozen=True)
class Preprocess:
    """How a family wants its input: channel order, value scale, letterbox alignment."""

    channels: str = "rgb"  # "rgb" or "bgr"
    scale: float = 1 / 255.0  # multiply 0–255 pixel values by this (1.0: keep 0–255)
    align: str = "center"  # "center" (pad split on both sides) or "topleft" (image at 0,0)


PREPROCESS = {
    "yolox": Preprocess(channels="bgr", scale=1.0, align="topleft"),
    "yolov5": Preprocess(),
    "yolov8": Preprocess(),
}


@dataclass
class Letterbox:
    scale: float
    pad_x: float
    pad_y: float


def letterbox(
    bgr: np.ndarray, size: int | tuple[int, int], pre: Preprocess = Preprocess()
) -> tuple[np.ndarray, Letterbox]:
    """Resize keeping the aspect ratio, pad to the input size (an int: square; or (height, width)) with grey 114;
    returns the 1×3×H×W float32 tensor and the mapping back to the frame."""
    in_h, in_w = (size, size) if isinstance(size, int) else size
    h, w = bgr.shape[:2]
    scale = min(in_w / w, in_h / h)
    if pre.align == "topleft":
        nw, nh = int(w * scale), int(h * scale)  # YOLOX's own preprocessing truncates
        left = top = 0
    else:
        nw, nh = round(w * scale), round(h * scale)
        left, top = int(round((in_w - nw) / 2 - 0.1)), int(round((in_h - nh) / 2 - 0.1))
    canvas: np.ndarray = np.full((in_h, in_w, 3), 114, np.uint8)
    canvas[top : top + nh, left : left + nw] = cv2.resize(bgr, (nw, nh), interpolation=cv2.INTER_LINEAR)
    if pre.channels == "rgb":
        canvas = cv2.cvtColor(canvas, cv2.COLOR_BGR2RGB)
    tensor = canvas.transpose(2, 0, 1)[None].astype(np.float32)
    if pre.scale != 1.0:
        tensor *= np.float32(pre.scale)
    return tensor, Letterbox(scale, left, top)


def nms(xyxy: np.ndarray, scores: np.ndarray, iou_threshold: float, classes: np.ndarray | None = None) -> np.ndarray:
    """Indices kept by greedy non-maximum suppression (OpenCV's), class by class when `classes` is given."""
    xywh = np.concatenate([xyxy[:, :2], xyxy[:, 2:] - xyxy[:, :2]], 1).tolist()
    if classes is None:
        kept = cv2.dnn.NMSBoxes(xywh, scores.tolist(), 0.0, iou_threshold)
    else:
        kept = cv2.dnn.NMSBoxesBatched(xywh, scores.tolist(), classes.tolist(), 0.0, iou_threshold)
    return np.asarray(kept, np.int64).ravel()


def grid_cells(input_hw: tuple[int, int], strides: tuple[int, ...] = STRIDES) -> int:
    """How many prediction cells an anchor-free head has for this input size (8400 at 640×640, 3549 at 416)."""
    return sum((input_hw[0] // s) * (input_hw[1] // s) for s in strides)


@functools.lru_cache(maxsize=8)
def yolox_grid(input_hw: tuple[int, int], strides: tuple[int, ...] = STRIDES) -> np.ndarray:
    """cells×3 (gx, gy, stride), in YOLOX's row order: stride 8 first, then 16, 32; y outer, x inner."""
    parts = []
    for s in strides:
        gy, gx = np.mgrid[0 : input_hw[0] // s, 0 : input_hw[1] // s]
        parts.append(np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, s)], 1))
    grid = np.concatenate(parts).astype(np.float32)
    grid.flags.writeable = False  # cached: shared by every call
    return grid


def identify_family(shape: tuple[int, ...], classes: int | None, input_hw: tuple[int, int]) -> str | None:
    """The export family of an output of this shape, or None when it fits none.

    1×(4+C)×N with the attributes first is YOLOv8/11. With the attributes last (1×N×A): N one row per grid cell
    and A = 5+C is YOLOX (raw heads); N three rows per cell (anchors) is YOLOv5; A = 4+C is a transposed v8.
    `classes` None: C is whatever the shape implies.
    """
    if len(shape) != 3 or shape[0] != 1:
        return None
    _, a, b = shape
    cells = grid_cells(input_hw)
    if a == 4 + (classes or 0) or (classes is None and 5 <= a < b):
        return "yolov8"
    n, attrs = a, b
    if classes is not None and attrs == 4 + classes:
        return "yolov8"
    if attrs < 6 or n < attrs:
        return None
    if n == 3 * cells and (classes is None or attrs == 5 + classes):
        return "yolov5"
    if n == cells and (classes is None or attrs == 5 + classes):
        return "yolox"
    if classes is None or attrs == 5 + classes:
        return "yolov5"  # anchor-based with another anchor count, or YOLOX decoded in the graph: px boxes + obj
    return None


Found = list[tuple[int, float, tuple[float, float, float, float]]]


def attributes_last(shape: tuple[int, ...], classes: int | None) -> bool:
    """Whether a YOLOv8 output is 1×N×(4+C) (transposed) rather than the usual 1×(4+C)×N."""
    if classes:
        return shape[2] == 4 + classes != shape[1]
    return shape[1] > shape[2]


def candidates(
    output: np.ndarray, family: str, input_hw: tuple[int, int], classes: int | None = None, min_objectness: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """(N×4 cx, cy, w, h in input px, N×C class scores) of one family's raw output."""
    pred = np.asarray(output, np.float32)[0]
    if family == "yolov8":
        if not attributes_last((1, *pred.shape), classes):
            pred = pred.T  # 1×(4+C)×N -> N×(4+C)
        return pred[:, :4], pred[:, 4:]
    if family == "yolox":
        grid = yolox_grid(input_hw)
        if len(grid) != len(pred):
            raise ModelError(
                f"a YOLOX output has one row per grid cell ({len(grid)} at {input_hw[1]}×{input_hw[0]}), "
                f"this one has {len(pred)}: give --family yolov5 if its boxes are already decoded"
            )
    sel = pred[:, 4] >= min_objectness  # score = obj × cls ≤ obj: rows under the threshold cannot reach it
    pred = pred[sel]
    boxes, scores = pred[:, :4], pred[:, 5:] * pred[:, 4:5]  # objectness × class score
    if family == "yolox":
        grid = grid[sel]
        boxes = np.concatenate(
            [(boxes[:, :2] + grid[:, :2]) * grid[:, 2:], np.exp(np.clip(boxes[:, 2:], -20, 20)) * grid[:, 2:]], 1
        )
    return boxes, scores


def decode(
    output: np.ndarray,
    lb: Letterbox,
    image_size: tuple[int, int],
    conf_threshold: float,
    iou_threshold: float,
    classes: int | None = None,
    family: str | None = None,
    input_hw: tuple[int, int] = (640, 640),
) -> Found:
    """(class index, score, (x, y, w, h) in original image px) of one raw model output.

    `family` None: identified from the shape (`identify_family`). Boxes are undone from the letterbox, clipped
    to the image, and suppressed class by class (a cup does not suppress the bottle behind it).
    """
    shape = tuple(np.asarray(output).shape)
    family = family or identify_family(shape, classes, input_hw)
    if family is None:
        raise ModelError(
            f"output shape {shape} fits no detector family: YOLOX 1×cells×(5+C), YOLOv5 "
            f"1×(3·cells)×(5+C), YOLOv8/11 1×(4+C)×N" + (f" (C = {classes})" if classes else "")
        )
    boxes, class_scores = candidates(output, family, input_hw, classes, conf_threshold)
    if not len(boxes):
        return []
    cls = class_scores.argmax(axis=1)
    score = class_scores[np.arange(len(cls)), cls]
    sel = score >= conf_threshold
    if not sel.any():
        return []
    cx, cy, bw, bh = boxes[sel].T
    cls, score = cls[sel], score[sel]
    width, height = image_size
    x1 = np.clip((cx - bw / 2 - lb.pad_x) / lb.scale, 0, width)
    y1 = np.clip((cy - bh / 2 - lb.pad_y) / lb.scale, 0, height)
    x2 = np.clip((cx + bw / 2 - lb.pad_x) / lb.scale, 0, width)
    y2 = np.clip((cy + bh / 2 - lb.pad_y) / lb.scale, 0, height)
    xyxy = np.stack([x1, y1, x2, y2], axis=1)
    kept = nms(xyxy, score, iou_threshold, cls)  # class by class: a cup does not suppress the bottle partly behind it
    # across classes only near-identical boxes: one object the model calls both cup (0.30) and bottle (0.25)
    kept = kept[nms(xyxy[kept], score[kept], SAME_OBJECT_IOU)]
    out = []
    for i in kept:
        a, b, c2, d = (float(v) for v in xyxy[i])
        if c2 > a and d > b:
            out.append((int(cls[i]), float(score[i]), (a, b, c2 - a, d - b)))
    out.sort(key=lambda f: -f[1])
    return out


class YoloDetector:
    """One ONNX detector: frame in, (label, score, box) out. The family is found from the output shape unless
    given; `channels`, `scale`, `align` override the family's preprocessing."""

    def __init__(
        self,
        model_path: str,
        names: tuple[str, ...] | None = None,
        conf_threshold: float = 0.3,
        iou_threshold: float = 0.45,
        family: str | None = None,
        channels: str | None = None,
        scale: float | None = None,
        align: str | None = None,
    ):
        path = Path(model_path)
        if not path.is_file():
            raise ModelError(
                f"ONNX model {model_path!r} not found: give the path of a YOLOX, YOLOv5 or YOLOv8/11 "
                f"detector exported to ONNX, or use --backend color"
            )
        if family not in (None, "auto", *FAMILIES):
            raise ModelError(f"unknown family {family!r}: use one of auto, {', '.join(FAMILIES)}")
        try:
            import onnxruntime as ort
        except ImportError:
            raise ModelError("onnxruntime is not installed: pip install 'hri-fusion[vision]'") from None
        try:
            options = ort.SessionOptions()
            # no busy-waiting of the thread pool between runs: on a robot's few cores it steals the CPU from the
            # service's own post-processing and from the other services (benchmarks/vision.py measures both)
            options.add_session_config_entry("session.intra_op.allow_spinning", "0")
            # its pool sized for the cores this process may use (affinity, a container's quota), not the
            # machine's physical cores, onnxruntime's default
            options.intra_op_num_threads = available_cores()
            self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise ModelError(f"onnxruntime cannot load {model_path!r}: {exc}") from None
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        dims = [d if isinstance(d, int) and d > 0 else None for d in inp.shape]
        if len(dims) != 4:
            raise ModelError(f"{model_path!r} takes a {len(dims)}-D input {inp.shape}; a YOLO detector takes 1×3×H×W")
        side = dims[2] or dims[3] or 640
        self.input_hw = (dims[2] or side, dims[3] or side)
        self.conf_threshold, self.iou_threshold = conf_threshold, iou_threshold
        self.family, self.output_index, classes = self._identify(model_path, names, family)
        self.names = names if names is not None else (COCO_NAMES if classes == len(COCO_NAMES) else ())
        self.classes = classes
        pre = PREPROCESS[self.family]
        self.preprocess = replace(
            pre,
            channels=channels or pre.channels,
            scale=pre.scale if scale is None else scale,
            align=align or pre.align,
        )

    def _identify(self, model_path: str, names: tuple[str, ...] | None, family: str | None) -> tuple[str, int, int]:
        """(family, index of the output to read, class count) from the declared output shapes, or else from one run
        on a grey frame (exports with dynamic output dimensions)."""
        declared = [tuple(d if isinstance(d, int) else None for d in o.shape) for o in self.session.get_outputs()]
        shapes: list[tuple[int, ...]] = [tuple(d for d in s if d is not None) for s in declared]  # when all known
        if any(None in s for s in declared):
            blank = np.full((1, 3, *self.input_hw), 114, np.float32)
            shapes = [tuple(np.asarray(o).shape) for o in self.session.run(None, {self.input_name: blank})]
        # without --labels: the 80 COCO classes first, else whatever class count the shape implies
        tries = (len(names),) if names is not None else (len(COCO_NAMES), None)
        for wanted in tries:
            for k, shape in enumerate(shapes):
                found = (
                    identify_family(shape, wanted, self.input_hw)
                    if family in (None, "auto")
                    else (family if len(shape) == 3 and shape[0] == 1 else None)
                )
                if found:
                    attrs = shape[2] if found != "yolov8" or attributes_last(shape, wanted) else shape[1]
                    return found, k, attrs - (4 if found == "yolov8" else 5)
        wanted = tries[0] if names is not None else None
        outputs = ", ".join(f"{o.name} {list(s)}" for o, s in zip(self.session.get_outputs(), shapes))
        classes = f" with {wanted} classes (--labels)" if wanted else ""
        raise ModelError(
            f"{model_path!r}: outputs {outputs} fit no known detector family{classes}: expected YOLOX "
            f"1×{grid_cells(self.input_hw)}×(5+C), YOLOv5 1×{3 * grid_cells(self.input_hw)}×(5+C) or "
            f"YOLOv8/11 1×(4+C)×N; give --family and --labels if it is one of them"
        )

    def describe(self) -> str:
        pre = self.preprocess
        return (
            f"{self.family} detector, input {self.input_hw[1]}×{self.input_hw[0]} {pre.channels.upper()} "
            f"{'0–255' if pre.scale == 1.0 else '0–1'} letterbox {pre.align}, {self.classes} classes, "
            f"conf ≥ {self.conf_threshold}, NMS IoU {self.iou_threshold}"
        )

    def raw(self, bgr: np.ndarray) -> tuple[np.ndarray, Letterbox]:
        tensor, lb = letterbox(bgr, self.input_hw, self.preprocess)
        return self.session.run(None, {self.input_name: tensor})[self.output_index], lb

    def detect(self, bgr: np.ndarray) -> list[tuple[str, float, tuple[float, float, float, float]]]:
        output, lb = self.raw(bgr)
        found = decode(
            output,
            lb,
            (bgr.shape[1], bgr.shape[0]),
            self.conf_threshold,
            self.iou_threshold,
            self.classes,
            self.family,
            self.input_hw,
        )
        return [(self.names[c] if c < len(self.names) else f"class{c}", s, box) for c, s, box in found]


def read_names(path: str) -> tuple[str, ...]:
    """Class names, one per line (a .txt of the model's classes in index order), or a JSON list of them."""
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise ModelError(f"cannot read class names {path!r}: {exc.strerror}") from None
    stripped = text.strip()
    if stripped.startswith("[") or stripped.startswith("{"):
        import json

        try:
            raw = json.loads(stripped)
        except json.JSONDecodeError as exc:
            raise ModelError(f"class names file {path!r} is not JSON: {exc}") from None
        if isinstance(raw, dict):  # {"0": "person", ...} as some exports write it
            try:
                raw = [raw[k] for k in sorted(raw, key=int)]
            except ValueError:
                raise ModelError(f"class names file {path!r}: a JSON object must map class indices to names") from None
        names = tuple(str(n).strip() for n in raw)
    else:
        names = tuple(line.strip() for line in text.splitlines() if line.strip())
    if not names:
        raise ModelError(f"class names file {path!r} is empty: one name per line, in the model's class order")
    return names
