"""The landmark path on real photos beyond single frames: the recorded arrays are what MediaPipe really gives,
the full model holds a gesture over repeated frames, a real palm slid side to side waves."""

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.gesture.landmarks import HandLandmarker, LandmarkError
from services.gesture.rules import classify, pointing_ray
from services.gesture.temporal import GestureTracker
from testkit.harness import DATA
from testkit.images import read_image
from testkit.record_landmarks import SOURCES, record

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
    img = read_image(str(DATA / "demo" / scene))
    landmarker = HandLandmarker("full", max_hands=2, video=True)
    try:
        classes = [[classify(h.landmarks) for h in landmarker.detect(img)] for _ in range(6)]
    finally:
        landmarker.close()
    assert classes == [[expected]] * 6


def test_an_unknown_model_is_a_clear_error():
    with pytest.raises(LandmarkError, match="unknown hand model 'huge'"):
        HandLandmarker("huge")


def moving_palm_events(amplitude_px: float, frames: int = 60, fps: float = 30.0, hz: float = 1.5) -> list:
    """The real open palm of stop.png slid side to side across a wider frame, through MediaPipe and the tracker."""
    img = read_image(str(DATA / "demo" / "stop.png"))
    margin = 120
    landmarker = HandLandmarker("lite", max_hands=2, video=True)
    tracker = GestureTracker()
    events = []
    try:
        for i in range(frames):
            dx = int(round(margin + amplitude_px * math.sin(2 * math.pi * hz * i / fps)))
            canvas = cv2.copyMakeBorder(img, 0, 0, dx, 2 * margin - dx, cv2.BORDER_REPLICATE)
            events += tracker.update(10.0 + i / fps, landmarker.detect(canvas))[1]
    finally:
        landmarker.close()
    return [(e.gesture, e.phase) for e in events if e.phase != "hold"]


def test_a_real_palm_moved_side_to_side_waves():
    # ±100 px is ±0.6 palm sizes (the palm in stop.png is ~170 px): 1.5 waves per second for 2 s
    assert moving_palm_events(100) == [("open_palm", "start"), ("open_palm", "end"), ("wave", "start")]


def test_a_real_palm_held_still_or_trembling_does_not_wave():
    assert moving_palm_events(0) == [("open_palm", "start")]
    assert moving_palm_events(12) == [("open_palm", "start")]  # ±0.07 palm sizes


# image turned by cv2 -> the same turn applied to a direction vector in image axes (x right, y down)
TURNS = {
    "90cw": (lambda im: cv2.rotate(im, cv2.ROTATE_90_CLOCKWISE), lambda d: (-d[1], d[0])),
    "180": (lambda im: cv2.rotate(im, cv2.ROTATE_180), lambda d: (-d[0], -d[1])),
    "90ccw": (lambda im: cv2.rotate(im, cv2.ROTATE_90_COUNTERCLOCKWISE), lambda d: (d[1], -d[0])),
    "mirror": (lambda im: cv2.flip(im, 1), lambda d: (-d[0], d[1])),
}


@pytest.fixture(scope="module")
def still_landmarker():
    landmarker = HandLandmarker("lite", max_hands=2, video=False)
    yield landmarker
    landmarker.close()


@pytest.mark.parametrize("turn", sorted(TURNS))
@pytest.mark.parametrize(
    "photo,expected",
    [
        (DATA / "demo" / "pointing.png", "point"),
        (DATA / "demo" / "stop.png", "open_palm"),
        (DATA / "images" / "hands" / "handSrc.jpg", "open_palm"),
        (DATA / "images" / "hands" / "Back_Projection_Theory0.jpg", "open_palm"),
    ],
)
def test_real_photos_turned_and_mirrored_keep_their_gesture_and_ray(still_landmarker, photo, expected, turn):
    img = read_image(str(photo))
    turn_image, turn_vector = TURNS[turn]
    (upright,), (turned,) = still_landmarker.detect(img), still_landmarker.detect(turn_image(img))
    assert classify(turned.landmarks) == expected
    if expected == "point":
        want = turn_vector(pointing_ray(upright.landmarks)[1])
        got = pointing_ray(turned.landmarks)[1]
        assert math.degrees(math.acos(min(1.0, want[0] * got[0] + want[1] * got[1]))) < 5, (want, got)
