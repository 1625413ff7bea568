"""Nobody waves in a still photo (issue #40): the stack benchmark's slideshow of ../shared people, pointing and home
photos (benchmarks/stack.py, each photo held a few seconds) through the gesture core gave `wave`s that fusion called
`come_here`: each frame's wrist x divided by that frame's jittering body scale made a held skeleton swing, and a slide
change joined one person's arm to another's. A wave is one arm of one person moving side to side over source time;
the real waves stay recognised (tests/test_gesture_arm_wave.py, tests/test_intent_clips.py)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from benchmarks.stack import SCENES, SLIDE_SECONDS
from services.gesture.core import GestureSettings
from testkit.intent import gesture_commands, gesture_samples, run_fusion
from testkit.shared import shared_path

PHOTOS = next(s for s in SCENES if s.photos).photos


def _fitted(path: str, size: tuple[int, int] = (640, 480)) -> np.ndarray:
    """The photo fitted into `size`, padded black, as the benchmark's slideshow shows it."""
    img = cv2.imread(str(shared_path(path)))
    assert img is not None, path
    scale = min(size[0] / img.shape[1], size[1] / img.shape[0])
    w, h = round(img.shape[1] * scale), round(img.shape[0] * scale)
    canvas = np.zeros((size[1], size[0], 3), np.uint8)
    y0, x0 = (size[1] - h) // 2, (size[0] - w) // 2
    canvas[y0 : y0 + h, x0 : x0 + w] = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    return canvas


@pytest.mark.parametrize("fps", [10.0, 15.0])
def test_a_slideshow_of_still_photos_gives_no_wave_and_no_come_here(fps: float) -> None:
    held = round(SLIDE_SECONDS * fps)
    frames = [img for img in (_fitted(p) for p in PHOTOS) for _ in range(held)]
    samples = gesture_samples(GestureSettings(), frames, fps)
    waves = [s for s in samples if getattr(s, "gesture", None) == "wave"]
    assert waves == []
    assert [c for c in gesture_commands(run_fusion(samples)) if c[0] == "come_here"] == []
