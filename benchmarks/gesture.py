"""Gesture: the service's per-frame path vs bare MediaPipe `Hands.process` on the same frames, one run.

1. Throughput on the same 640x480 real hand photos (decoded once, before timing):
   - bare: `mediapipe.solutions.hands.Hands(...).process(rgb)` in a loop (video mode, lite model, 2 hands);
   - service path: HandLandmarker.detect (the same call plus landmark conversion and handedness) followed by
     GestureTracker.update (rules, hysteresis, wave, ray).
   Target: service >= 0.9x the bare loop's frames/s.
2. End-to-end lag at 30 fps input into a real gesture process: p50/p99 per slice (it must not grow).

Usage: python benchmarks/gesture.py [--seconds 60] [--frames 300]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import cv2  # noqa: E402

from benchmarks.lag import frame_benchmark_main, print_throughput  # noqa: E402
from common.schema import Hands  # noqa: E402
from services.gesture.landmarks import HandLandmarker  # noqa: E402
from services.gesture.temporal import GestureTracker  # noqa: E402
from tests.harness import DATA  # noqa: E402


def hand_frames() -> list:
    paths = [DATA / "demo" / "pointing.png", DATA / "demo" / "stop.png", *sorted((DATA / "images" / "hands").glob("*.jpg"))]
    return [cv2.resize(cv2.imread(str(p)), (640, 480)) for p in paths]


def throughput(frames: list, n: int, repeats: int = 3) -> None:
    from mediapipe.python.solutions import hands as mp_hands
    bare_fps, service_fps = [], []
    # each photo is shown for 10 frames in a row, as a camera would: MediaPipe tracks between frames
    sequence = [f for f in frames for _ in range(10)]
    for _ in range(repeats):  # alternate so drift hits both alike
        bare = mp_hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=0)
        t0 = time.perf_counter()
        for i in range(n):
            bare.process(cv2.cvtColor(sequence[i % len(sequence)], cv2.COLOR_BGR2RGB))
        bare_fps.append(n / (time.perf_counter() - t0))
        bare.close()
        landmarker, tracker = HandLandmarker("lite", 2), GestureTracker()
        t0 = time.perf_counter()
        for i in range(n):
            tracker.update(i / 30.0, landmarker.detect(sequence[i % len(sequence)]))
        service_fps.append(n / (time.perf_counter() - t0))
        landmarker.close()
    print_throughput(f"throughput on {n} frames 640x480 of real hands", "bare MediaPipe Hands.process", bare_fps,
                     "gesture service path", service_fps)


def main() -> None:
    frame_benchmark_main(__doc__, "gesture", "hri/gesture/bench/hands", Hands, hand_frames, throughput)


if __name__ == "__main__":
    main()
