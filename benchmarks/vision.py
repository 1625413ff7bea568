"""Vision: the service's detection path vs a bare OpenCV loop doing the same segmentation, one run.

1. Throughput on the same 640x480 frames (the shipped photos, resized):
   - bare: blur, HSV, one mask per palette colour plus black and white, open/close, connected components,
     bounding boxes — plain OpenCV;
   - service path: JPEG decode is excluded from both; VisionPipeline.process = the same segmentation plus
     colour naming, tracking, image quality and building the contract objects.
   Target: service >= 0.9x the bare loop's frames/s.
2. End-to-end lag at 30 fps input: camera-like publisher -> router -> vision service -> subscriber; lag =
   receive time - frame stamp, p50/p99 per 10 s slice over 60 s (it must not grow).

Usage: python benchmarks/vision.py [--seconds 60] [--frames 300]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks.lag import frame_benchmark_main, print_throughput  # noqa: E402
from common.schema import Detections  # noqa: E402
from services.vision.color import CHROMATIC, HUE_RANGES  # noqa: E402
from services.vision.core import VisionPipeline  # noqa: E402
from services.vision.segment import ColorSegmenter  # noqa: E402
from tests.harness import DATA  # noqa: E402


def frames_640() -> list[np.ndarray]:
    paths = sorted((DATA / "images" / "tabletop").iterdir()) + sorted((DATA / "demo").glob("*.png"))
    return [cv2.resize(cv2.imread(str(p)), (640, 480)) for p in paths]


def hue_lut() -> np.ndarray:
    lut = np.zeros(256, np.uint8)
    for k, name in enumerate(CHROMATIC):
        for lo, hi in HUE_RANGES[name]:
            lut[lo:hi] = k + 1
    return lut


def bare_segmentation(bgr: np.ndarray, kernel: np.ndarray, lut: np.ndarray) -> list[tuple[int, int, int, int]]:
    """The same masks as the colour backend (one per palette colour, then black and white), plain OpenCV."""
    hsv = cv2.cvtColor(cv2.GaussianBlur(bgr, (5, 5), 0), cv2.COLOR_BGR2HSV)
    index = cv2.bitwise_and(cv2.LUT(hsv[..., 0], lut), cv2.inRange(hsv, (0, 100, 75), (180, 255, 255)))
    masks = [cv2.inRange(index, k, k) for k in range(1, len(CHROMATIC) + 1)]
    masks += [cv2.inRange(hsv, (0, 0, 0), (180, 255, 74)), cv2.inRange(hsv, (0, 0, 180), (180, 59, 255))]
    boxes = []
    for m in masks:
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, kernel)
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, kernel)
        n, _, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        boxes += [tuple(int(v) for v in stats[i, :4]) for i in range(1, n) if stats[i, 4] > 460]
    return boxes


def throughput(frames: list[np.ndarray], n: int, repeats: int = 3) -> None:
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    lut = hue_lut()
    pipeline = VisionPipeline(ColorSegmenter())
    bare_fps, service_fps = [], []
    for _ in range(repeats):  # alternate so drift hits both alike
        t0 = time.perf_counter()
        for i in range(n):
            bare_segmentation(frames[i % len(frames)], kernel, lut)
        bare_fps.append(n / (time.perf_counter() - t0))
        t0 = time.perf_counter()
        for i in range(n):
            pipeline.process("cam0", frames[i % len(frames)])
        service_fps.append(n / (time.perf_counter() - t0))
    print_throughput(f"throughput on {n} frames 640x480", "bare OpenCV segmentation", bare_fps,
                     "vision service path", service_fps)


def main() -> None:
    frame_benchmark_main(__doc__, "vision", "hri/vision/bench/objects", Detections, frames_640, throughput)


if __name__ == "__main__":
    main()
