"""The recorded landmark arrays are what MediaPipe really gives on the photos; the full model works too."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.gesture.landmarks import HandLandmarker, LandmarkError
from services.gesture.record_landmarks import SOURCES, record
from services.gesture.rules import classify
from tests.harness import DATA

RECORDED = json.loads((Path(__file__).parent / "data" / "landmarks" / "real_hands.json").read_text())


def test_recorded_arrays_are_mediapipes_output_on_the_real_photos():
    fresh = record()
    assert set(fresh) == set(RECORDED) == set(SOURCES)
    for name, hand in RECORDED.items():
        assert (fresh[name]["width"], fresh[name]["height"]) == (hand["width"], hand["height"])
        error = np.abs(np.array(fresh[name]["landmarks"]) - np.array(hand["landmarks"])).max()
        assert error < 3.0, (name, error)  # pixels; MediaPipe on another CPU may differ by rounding


@pytest.mark.parametrize("scene,expected", [("stop.png", "open_palm"), ("pointing.png", "point")])
def test_full_model_in_video_mode_keeps_the_gesture_over_repeated_frames(scene, expected):
    img = cv2.imread(str(DATA / "demo" / scene))
    landmarker = HandLandmarker("full", max_hands=2, video=True)
    try:
        classes = [[classify(h.landmarks) for h in landmarker.detect(img)] for _ in range(6)]
    finally:
        landmarker.close()
    assert classes == [[expected]] * 6


def test_an_unknown_model_is_a_clear_error():
    with pytest.raises(LandmarkError, match="unknown hand model 'huge'"):
        HandLandmarker("huge")
