"""One frame in, the Detections content out: detector, colour attribute, tracking, quality."""

from __future__ import annotations

import cv2
import numpy as np

from common.language import canonical_label
from common.schema import DetectedObject, ImageQuality
from services.vision.color import color_name
from services.vision.quality import image_quality
from services.vision.segment import ColorSegmenter, Detection
from services.vision.track import Tracker
from services.vision.yolo import YoloDetector


def box_color(hsv: np.ndarray, bbox: tuple[float, float, float, float], inner: float = 0.6) -> str | None:
    """The colour of the central part of a box (its edges are mostly background)."""
    x, y, w, h = bbox
    cx, cy = x + w / 2, y + h / 2
    x0, x1 = int(max(0, cx - w * inner / 2)), int(min(hsv.shape[1], cx + w * inner / 2 + 1))
    y0, y1 = int(max(0, cy - h * inner / 2)), int(min(hsv.shape[0], cy + h * inner / 2 + 1))
    return color_name(hsv[y0:y1, x0:x1])[0]


class VisionPipeline:
    """Per camera: detect, name colours, keep ids stable. Not thread-safe: one worker calls it."""

    def __init__(self, detector: ColorSegmenter | YoloDetector):
        self.detector = detector
        self.trackers: dict[str, Tracker] = {}

    def detections(self, bgr: np.ndarray) -> list[Detection]:
        if isinstance(self.detector, ColorSegmenter):
            return self.detector.detect(bgr)  # colours come from the segmentation itself
        hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
        # the language's class where one fits ("wine glass" -> "cup"), so "the cup" finds it
        return [Detection(canonical_label(label), box_color(hsv, box), score, box)
                for label, score, box in self.detector.detect(bgr)]

    def process(self, cam: str, bgr: np.ndarray) -> tuple[list[DetectedObject], ImageQuality]:
        tracker = self.trackers.setdefault(cam, Tracker(prefix=f"{cam}-o"))
        objects = [
            DetectedObject(id=obj_id, label=d.label, color=d.color, score=round(d.score, 4),
                           bbox=[round(v, 1) for v in d.bbox], center=[round(v, 1) for v in d.center])
            for obj_id, d in tracker.update(self.detections(bgr))
        ]
        brightness, contrast, sharpness = image_quality(bgr)
        return objects, ImageQuality(brightness=brightness, contrast=contrast, sharpness=sharpness)
