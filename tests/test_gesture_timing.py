"""Gesture timing beyond frame counts: a start after T ms at a low frame rate, and ending gestures when the
stream stops (no frame will ever show the hand gone). Real landmark arrays, pure tracker."""

import json
from pathlib import Path

import numpy as np

from services.gesture.temporal import GestureTracker, Observation

REAL = json.loads((Path(__file__).parent / "data" / "landmarks" / "real_hands.json").read_text())
PALM = np.array(REAL["open_palm_up"]["landmarks"], dtype=float)
POINT = np.array(REAL["point_right"]["landmarks"], dtype=float)


def run(tracker, hands_per_frame, dt, t0=50.0):
    events = []
    for i, hands in enumerate(hands_per_frame):
        events += tracker.update(t0 + i * dt, hands)[1]
    return events


def hand(p):
    return [Observation("right", 0.9, p)]


def test_start_time_starts_a_gesture_before_the_frame_count_at_a_low_frame_rate():
    # 4 fps: 2 frames span 250 ms. With start_time 0.2 s the open palm starts on frame 2, not frame 5.
    frames_only = run(GestureTracker(start_frames=5), [hand(PALM)] * 6, dt=0.25)
    timed = run(GestureTracker(start_frames=5, start_time=0.2), [hand(PALM)] * 6, dt=0.25)
    first = [e for e in frames_only if e.phase == "start"][0]
    assert first.end == 50.0 + 4 * 0.25
    start = [e for e in timed if e.phase == "start"][0]
    assert (start.gesture, start.start, start.end) == ("open_palm", 50.0, 50.25)


def test_start_time_never_starts_on_a_single_frame():
    # one stray frame of point between open palms, however long the gap after it, starts no point
    seq = [hand(PALM)] * 4 + [hand(POINT)] + [hand(PALM)] * 4
    events = run(GestureTracker(start_frames=5, start_time=0.01), seq, dt=0.5)
    assert {e.gesture for e in events if e.phase == "start"} == {"open_palm"}


def test_flush_ends_what_is_going_on_and_forgets_the_hands():
    tracker = GestureTracker()
    events = run(tracker, [hand(POINT)] * 5, dt=0.1)
    assert tracker.active() == ["point"]
    ended = tracker.flush()
    assert [(e.gesture, e.phase, e.start, e.end) for e in ended] == [("point", "end", 50.0, 50.4)]
    assert tracker.active() == [] and tracker.flush() == []
    # the same hand coming back later starts afresh
    again = run(tracker, [hand(POINT)] * 3, dt=0.1, t0=60.0)
    assert [(e.gesture, e.phase, e.start) for e in again if e.phase == "start"] == [("point", "start", 60.0)]
    assert [e.phase for e in events if e.phase != "hold"] == ["start"]
