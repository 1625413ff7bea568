"""The detections the golden net's real-photo runs feed fusion: YOLOX-Nano's, rounded so that any CPU writes the same.

onnxruntime promises no digits across CPUs (its kernels pick SIMD paths by CPU; sums run in another order): the
same photo gives boxes that differ by up to 5.5e-4 px and scores by up to 1.8e-6 between graph optimisations on
and off and 1 or 2 threads on one machine, and another CPU differs as much. `GoldenDetector` rounds what the
detector finds before anything else sees it, boxes to PIXEL_STEP and scores to SCORE_STEP, and orders the
detections by the rounded figures; fusion, vision's colours and ids then compute from those alone.

Rounding moves a figure only when it sits on a boundary between two steps, and a decision inside the detector
(a score at the threshold, an overlap at the NMS limit, two candidates of one object with equal scores) flips only
when it sits on its edge. `margins()` measures how far every such figure and decision of a photo sits from its
edge; tests/test_golden.py wants each at least its GUARD away, so a photo that would make the file CPU-dependent
is named, with the figure, instead of failing on some other machine.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from services.vision.yolo import SAME_OBJECT_IOU, YoloDetector, candidates

# A half pixel: the nearest figure of the committed photos sits 2.1e-3 px from a boundary at half pixels, while
# at whole pixels three sit within 6e-4 px of one (461.50006, 80.49954, 218.49939): within the spread above.
PIXEL_STEP = 0.5
SCORE_STEP = 0.01  # the prompt's own precision ("score 0.30")
# how close to an edge a figure may sit: about twice the largest spread measured between onnxruntime settings
PIXEL_GUARD = 1e-3
SCORE_GUARD = 5e-6
IOU_GUARD = 1e-5  # an overlap moves by ~(box spread / box side): 5.5e-4 px on a 50 px box is 1e-5

Found = list[tuple[str, float, tuple[float, float, float, float]]]


@dataclass(frozen=True)
class OrtSettings:
    """onnxruntime's session knobs that change the last digits: intra-op threads (None: the service's own choice,
    the cores this process may use) and the graph optimisations (on: onnxruntime's default, all of them)."""

    threads: int | None = None
    optimise: bool = True

    @staticmethod
    def from_env() -> OrtSettings:
        """HRI_ORT_THREADS=1 and HRI_ORT_GRAPH_OPT=off, to run the golden net under other settings."""
        threads = os.environ.get("HRI_ORT_THREADS")
        return OrtSettings(int(threads) if threads else None, os.environ.get("HRI_ORT_GRAPH_OPT", "on") != "off")

    def __str__(self) -> str:
        return f"threads {self.threads or 'default'}, graph optimisations {'on' if self.optimise else 'off'}"


def on_pixel_grid(value: float) -> float:
    return round(value / PIXEL_STEP) * PIXEL_STEP


def on_score_grid(value: float) -> float:
    return round(value, 2)  # Python's round: correctly rounded at the decimal midpoint


def rounded(found: Found) -> Found:
    """Boxes to PIXEL_STEP, scores to SCORE_STEP, ordered by the rounded figures (best score first): the order, and
    the ids made from it, no longer hang on two raw scores' last digits."""
    out = [
        (label, on_score_grid(score), (on_pixel_grid(x), on_pixel_grid(y), on_pixel_grid(w), on_pixel_grid(h)))
        for label, score, (x, y, w, h) in found
    ]
    return sorted(out, key=lambda f: (-f[1], f[0], f[2]))


def to_edge(value: float, step: float) -> float:
    """How far `value` sits from the nearest rounding boundary (a half step) of a grid of `step`."""
    return abs(value / step % 1.0 - 0.5) * step


class GoldenDetector(YoloDetector):
    """The vision service's YOLOX backend with its detections rounded (`rounded`), under the given OrtSettings.
    Keeps every frame it was given with what it found (`seen`), under the name its caller set in `photo`."""

    def __init__(
        self, model: Path, conf_threshold: float = 0.3, iou_threshold: float = 0.45, ort: OrtSettings = OrtSettings()
    ):
        super().__init__(str(model), conf_threshold=conf_threshold, iou_threshold=iou_threshold)
        if ort != OrtSettings():
            import onnxruntime

            options = onnxruntime.SessionOptions()
            options.add_session_config_entry("session.intra_op.allow_spinning", "0")
            if ort.threads:
                options.intra_op_num_threads = ort.threads
            if not ort.optimise:
                options.graph_optimization_level = onnxruntime.GraphOptimizationLevel.ORT_DISABLE_ALL
            self.session = onnxruntime.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])
        self.photo = ""
        self.seen: list[tuple[str, np.ndarray, Found]] = []

    def raw_detect(self, bgr: np.ndarray) -> Found:
        return super().detect(bgr)

    def detect(self, bgr: np.ndarray) -> Found:
        found = rounded(self.raw_detect(bgr))
        self.seen.append((self.photo, bgr, found))
        return found


def _iou(box: np.ndarray, others: np.ndarray) -> np.ndarray:
    """IoU of one x1y1x2y2 box with each of `others` (OpenCV's NMS definition: no +1 on the sides)."""
    w = np.clip(np.minimum(box[2], others[:, 2]) - np.maximum(box[0], others[:, 0]), 0, None)
    h = np.clip(np.minimum(box[3], others[:, 3]) - np.maximum(box[1], others[:, 1]), 0, None)
    inter = w * h
    area = (box[2] - box[0]) * (box[3] - box[1])
    union = area + (others[:, 2] - others[:, 0]) * (others[:, 3] - others[:, 1]) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)


def _suppression_margins(
    xyxy: np.ndarray, score: np.ndarray, cls: np.ndarray | None, limit: float
) -> tuple[float, float, np.ndarray]:
    """Greedy NMS as the detector runs it (best score first; a box goes when it overlaps a kept one of its class by
    more than `limit`), with (the nearest overlap to `limit` of a decision, the smallest score gap between a
    suppressed box and the kept box that suppressed it, the kept indices)."""
    order = np.argsort(-score, kind="stable")
    kept: list[int] = []
    overlap_edge = gap_edge = 1.0
    for i in order:
        same = [k for k in kept if cls is None or cls[k] == cls[i]]
        if same:
            overlaps = _iou(xyxy[i], xyxy[same])
            overlap_edge = min(overlap_edge, float(np.min(np.abs(overlaps - limit))))
            if overlaps.max() > limit:
                gap_edge = min(gap_edge, float(score[same[int(overlaps.argmax())]] - score[i]))
                continue
        kept.append(int(i))
    return overlap_edge, gap_edge, np.asarray(kept, np.int64)


def margins(detector: GoldenDetector, bgr: np.ndarray) -> list[tuple[str, float, float]]:
    """(what, how far it sits from its edge, the GUARD it needs) for the photo: the smallest of each kind."""
    output, lb = detector.raw(bgr)
    boxes, class_scores = candidates(output, detector.family, detector.input_hw, detector.classes)
    top2 = np.sort(class_scores, axis=1)[:, -2:]
    best = top2[:, 1]
    conf = detector.conf_threshold
    near = best >= conf - SCORE_GUARD
    out = [
        ("a score at the threshold", float(np.min(np.abs(best - conf))), SCORE_GUARD),
        ("two classes' scores of one box", float(np.min(top2[near, 1] - top2[near, 0], initial=1.0)), SCORE_GUARD),
    ]
    sel = best >= conf
    cls = class_scores[sel].argmax(axis=1)
    score = best[sel]
    cx, cy, bw, bh = boxes[sel].T
    h, w = bgr.shape[:2]
    xyxy = np.stack(
        [
            np.clip((cx - bw / 2 - lb.pad_x) / lb.scale, 0, w),
            np.clip((cy - bh / 2 - lb.pad_y) / lb.scale, 0, h),
            np.clip((cx + bw / 2 - lb.pad_x) / lb.scale, 0, w),
            np.clip((cy + bh / 2 - lb.pad_y) / lb.scale, 0, h),
        ],
        axis=1,
    )
    overlap, gap, kept = _suppression_margins(xyxy, score, cls, detector.iou_threshold)
    out += [("an overlap at the NMS limit", overlap, IOU_GUARD), ("two candidates of one object", gap, SCORE_GUARD)]
    overlap, gap, _ = _suppression_margins(xyxy[kept], score[kept], None, SAME_OBJECT_IOU)
    out += [("an overlap at the one-object limit", overlap, IOU_GUARD), ("two labels of one object", gap, SCORE_GUARD)]
    found = detector.raw_detect(bgr)
    figures = [v for _, _, box in found for v in box]
    out.append(
        (
            "a box figure at a rounding boundary",
            min((to_edge(v, PIXEL_STEP) for v in figures), default=1.0),
            PIXEL_GUARD,
        )
    )
    out.append(
        ("a score at a rounding boundary", min((to_edge(s, SCORE_STEP) for _, s, _ in found), default=1.0), SCORE_GUARD)
    )
    return out
