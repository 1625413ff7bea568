"""Unit tests of fusion's gestures (services/fusion/gestures.py): one command per gesture episode."""

from __future__ import annotations

import math

import cv2
import msgspec
import pytest

from common.schema import GestureEvent, GestureName, Handedness
from services.fusion.core import Config, FusionCore
from services.fusion.gestures import (
    OPEN_PALM_FRAMES,
    SPEAKING_STILL_S,
    STOP_STILL_S,
    WAVE_HOLD_S,
    Gestures,
    Person,
)
from services.gesture.landmarks import HandLandmarker
from services.gesture.temporal import GestureTracker
from testkit.harness import DATA
from testkit.images import read_image
from testkit.scenarios import BASE_STAMP, deliver, gesture, hands, say


def test_gesture_episode_gives_one_stop_and_a_new_episode_another():
    core = FusionCore(Config(), "fusion/test")
    outs = []
    for step in [
        gesture(0.5, "open_palm", "start"),
        gesture(0.8, "open_palm", "hold"),
        gesture(1.0, "open_palm", "end"),
        gesture(5.0, "open_palm", "start"),
    ]:
        outs += core.on_gesture_event(*step.build(BASE_STAMP), 1000.0)
    assert [o.sample.intent for o in outs] == ["stop", "stop"] and all(o.realtime for o in outs)
    assert outs[0].sample.id != outs[1].sample.id


def test_a_palm_seen_during_an_utterance_is_only_seen_and_a_deliberate_stop_is_remembered():
    """Issue #40: hand frames with an open palm during an utterance are counted (enough of them), never a stop; a
    stop event given (deliberate) is remembered over its span, from its start to when it went out."""
    gestures = Gestures(min_score=0.5, episode_gap=1.5, horizon=30.0)
    _, palm = hands(0.5, show="open_palm").build(BASE_STAMP)
    assert not gestures.palm_seen([palm] * (OPEN_PALM_FRAMES - 1))  # may be noise
    assert gestures.palm_seen([palm] * OPEN_PALM_FRAMES)
    assert not gestures.stop_given(BASE_STAMP, BASE_STAMP + 2.0)
    key, ev = gesture(1.0, "open_palm", "start", duration=0.4).build(BASE_STAMP)
    assert gestures.on_event(key, ev).intent == "stop"
    assert gestures.stop_given(BASE_STAMP, BASE_STAMP + 2.0)
    assert gestures.stop_given(BASE_STAMP + 0.7, BASE_STAMP + 0.8)  # said while the palm was held
    assert not gestures.stop_given(BASE_STAMP + 3.0, BASE_STAMP + 5.0)
    key, ev = gesture(1.0, "wave", "start", duration=WAVE_HOLD_S).build(BASE_STAMP)
    assert gestures.on_event(key, ev).intent == "come_here" and gestures.waved(BASE_STAMP, BASE_STAMP + 2.0)
    key, weak = gesture(4.0, "wave", "start", score=0.3, duration=WAVE_HOLD_S).build(BASE_STAMP)
    assert gestures.on_event(key, weak) is None


def _wave(t0: float, seconds: float, hand: Handedness = "right", end: bool = True) -> list[tuple[str, GestureEvent]]:
    """A wave as the gesture service reports it: `start` at its first frame, `hold` every 0.1 s, `end`."""
    steps = [gesture(t0, "wave", "start", duration=0.0, hand=hand)]
    steps += [
        gesture(t0 + 0.1 * i, "wave", "hold", duration=0.1 * i, hand=hand) for i in range(1, int(seconds * 10) + 1)
    ]
    if end:
        steps.append(gesture(t0 + seconds, "wave", "end", duration=seconds, hand=hand))
    return [(key, ev) for key, ev in (s.build(BASE_STAMP) for s in steps) if isinstance(ev, GestureEvent)]


def _commands(
    gestures: Gestures, events: list[tuple[str, GestureEvent]], facing: bool | None = None
) -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = []
    for key, ev in events:
        command = gestures.on_event(key, ev, Person(engaged=facing))
        if command is not None:
            out.append((command.intent, ev.stamp - BASE_STAMP))
    return out


def test_a_wave_calls_the_robot_only_when_held_and_not_turned_away() -> None:
    """Issue #34: hands moving at a table while people talk make brief waves; a wave meant for the robot goes on."""
    brief = _wave(0.0, 0.6) + _wave(3.0, 0.9, hand="left") + _wave(6.0, 0.5)
    assert _commands(Gestures(0.5, 1.5, 30.0), brief) == []
    held = _wave(0.0, 2.0)
    commands = _commands(Gestures(0.5, 1.5, 30.0), held)
    assert commands == [("come_here", pytest.approx(WAVE_HOLD_S))]  # once, when the hold is reached
    assert _commands(Gestures(0.5, 1.5, 30.0), held, facing=True) == commands  # facing the camera: the same
    assert _commands(Gestures(0.5, 1.5, 30.0), held, facing=False) == []  # back to the robot: not for it
    # a second held wave after the first ended is a new call
    again = _commands(Gestures(0.5, 1.5, 30.0), held + _wave(5.0, 1.5))
    assert [intent for intent, _ in again] == ["come_here", "come_here"]


def test_a_person_waving_both_arms_calls_once() -> None:
    """Both arms waved overhead (held-back intent/cat2_kard_two_hand_wave gave a come_here per arm, 0.04-0.08 s
    apart): one call. Another person's wave, or the other arm waved again after the first call's episode is over,
    is a call of its own."""
    both = sorted(_wave(0.0, 2.0) + _wave(0.1, 2.0, hand="left"), key=lambda ke: ke[1].stamp)
    assert [i for i, _ in _commands(Gestures(0.5, 1.5, 30.0), both)] == ["come_here"]
    later = _wave(0.0, 2.0) + _wave(6.0, 2.0, hand="left")
    assert [i for i, _ in _commands(Gestures(0.5, 1.5, 30.0), later)] == ["come_here", "come_here"]

    def of(person: str, events: list[tuple[str, GestureEvent]]) -> list[tuple[str, GestureEvent]]:
        return [(k, msgspec.structs.replace(ev, person=person)) for k, ev in events]

    two_people = sorted(of("p1", _wave(0.0, 2.0)) + of("p2", _wave(0.1, 2.0, hand="left")), key=lambda ke: ke[1].stamp)
    assert [i for i, _ in _commands(Gestures(0.5, 1.5, 30.0), two_people)] == ["come_here", "come_here"]


def test_a_stop_without_the_marks_of_issue_40_is_never_held_back() -> None:
    """An open palm from a gesture service that does not measure the hold (`still` nil) stops at once, as before."""
    gestures = Gestures(0.5, 1.5, 30.0)
    key, palm = gesture(1.0, "open_palm", "start", duration=0.1).build(BASE_STAMP)
    assert isinstance(palm, GestureEvent) and palm.still is None
    command = gestures.on_event(key, palm, Person(engaged=False))
    assert command is not None and command.intent == "stop" and command.realtime


def _real_palm_events(waving_s: float, still_s: float, fps: float = 30.0) -> list[GestureEvent]:
    """The real open palm of data/demo/stop.png slid side to side (±100 px, 1.5 Hz: a wave) for `waving_s`, then
    held still for `still_s`, through MediaPipe and the gesture service's tracker, as the GestureEvents it sends."""
    img = read_image(DATA / "demo" / "stop.png")
    margin = 120
    landmarker = HandLandmarker("lite", max_hands=2, video=True)
    tracker = GestureTracker()
    out: list[GestureEvent] = []
    try:
        for i in range(int((waving_s + still_s) * fps)):
            t = i / fps
            swing = 100 * math.sin(2 * math.pi * 1.5 * t) if t < waving_s else 0.0
            dx = int(round(margin + swing))
            canvas = cv2.copyMakeBorder(img, 0, 0, dx, 2 * margin - dx, cv2.BORDER_REPLICATE)
            for e in tracker.update(BASE_STAMP + t, landmarker.detect(canvas))[1]:
                h, w = canvas.shape[:2]
                out.append(
                    GestureEvent(
                        stamp=e.end,
                        source="gesture/test",
                        cam="cam0",
                        width=w,
                        height=h,
                        gesture=e.gesture,  # type: ignore[arg-type]  # the tracker's names are the wire's
                        phase=e.phase,  # type: ignore[arg-type]
                        start=e.start,
                        end=e.end,
                        score=e.score,
                        hand=e.hand,  # type: ignore[arg-type]
                    )
                )
    finally:
        landmarker.close()
    return out


def test_a_real_palm_waved_briefly_gives_no_command_and_waved_on_calls_the_robot() -> None:
    """Real hand frames (MediaPipe on a real palm photo, moved as a hand moves): a wave of a second, as hands make
    while talking, is recognised as a wave by the gesture service but calls nobody; waved for 3 s it calls the
    robot, once."""
    brief = _real_palm_events(1.0, 1.0)
    assert any(e.gesture == "wave" for e in brief)  # the gesture service does see a wave
    gestures = Gestures(0.5, 1.5, 30.0)
    assert [c for e in brief if (c := gestures.on_event("k", e)) and c.intent == "come_here"] == []
    held = _real_palm_events(3.0, 0.5)
    gestures = Gestures(0.5, 1.5, 30.0)
    calls = [c for e in held if (c := gestures.on_event("k", e)) and c.intent == "come_here"]
    assert len(calls) == 1, calls


UNKNOWN = Person()  # nothing known of the person making the gesture


def _marked(
    t: float, name: GestureName, still: float, raised: bool | None = True, duration: float = 0.4
) -> tuple[str, GestureEvent]:
    """A gesture event of a gesture service that measures the marks of issue #40."""
    key, ev = gesture(t, name, "hold", duration=duration).build(BASE_STAMP)
    assert isinstance(ev, GestureEvent)
    return key, msgspec.structs.replace(ev, still=still, raised=raised)


def test_a_stop_needs_a_palm_held_still_longer_while_its_person_speaks_and_not_turned_away() -> None:
    """Issue #40: a beat or a sweep (not held) is no stop; a palm held `STOP_STILL_S` is, `SPEAKING_STILL_S` while
    its person speaks; a person seen turned away gives none."""

    def stop(still: float, person: Person = UNKNOWN) -> bool:
        command = Gestures(0.5, 1.5, 30.0).on_event(*_marked(1.0, "open_palm", still), person)
        return command is not None and command.intent == "stop" and command.realtime

    assert not stop(0.0) and not stop(STOP_STILL_S - 0.05)
    assert stop(STOP_STILL_S)
    assert not stop(STOP_STILL_S, Person(speaking=True)) and stop(SPEAKING_STILL_S, Person(speaking=True))
    assert stop(STOP_STILL_S, Person(engaged=True)) and not stop(1.0, Person(engaged=False))


def test_a_wave_calls_only_with_the_arm_raised_and_its_person_not_speaking() -> None:
    def calls(raised: bool | None, person: Person = UNKNOWN, duration: float = WAVE_HOLD_S) -> bool:
        command = Gestures(0.5, 1.5, 30.0).on_event(*_marked(2.0, "wave", 0.0, raised, duration), person)
        return command is not None and command.intent == "come_here"

    assert calls(True) and calls(True, Person(engaged=True))
    assert not calls(False) and not calls(None)  # at the chest, or no skeleton to tell
    assert not calls(True, Person(speaking=True))  # hands swing while people talk; their words are heard
    assert not calls(True, duration=WAVE_HOLD_S - 0.2) and not calls(True, Person(engaged=False))


def _decide(text: str, palm_still: float | None, given_at: float = 0.8) -> tuple[list, dict]:
    """`text` said over [0, 1.5] s while an open palm is seen in the hand frames and (if `palm_still` is not None)
    an open palm event held still that long is sent; fusion's outputs and counters."""
    counts: dict = {}
    core = FusionCore(Config(), "fusion/test", count=lambda name: counts.__setitem__(name, counts.get(name, 0) + 1))
    core.on_liveliness("gesture", "test", True)
    steps = [hands(0.1 * i, show="open_palm").build(BASE_STAMP) for i in range(1, 20)]
    if palm_still is not None:
        steps.append(_marked(given_at, "open_palm", palm_still, duration=0.5))
    steps.append(say(0.0, 1.5, text).build(BASE_STAMP))
    out = []
    for key, sample in sorted(steps, key=lambda ks: ks[1].stamp):
        out += [o.sample for o in deliver(core, key, sample, 1000.0 + sample.stamp - BASE_STAMP)]
        out += [o.sample for o in core.tick(1000.0 + sample.stamp - BASE_STAMP)]
    out += [o.sample for o in core.tick(2000.0)]
    return out, counts


def test_a_command_said_while_a_palm_is_seen_is_answered_and_the_palm_counted() -> None:
    """Issue #40: "turn left" said while an open palm moves (a beat, not held: no stop) is decided as usual."""
    for still in (None, 0.1):
        out, counts = _decide("turn left", still)
        assert [(type(o).__name__, o.intent) for o in out] == [("FusedCommand", "turn")], still
        assert counts.get("palm_during_utterance") == 1 and "cancelled_by_stop_gesture" not in counts


def test_a_deliberate_stop_during_a_command_cancels_it_and_during_come_here_asks() -> None:
    out, counts = _decide("turn left", STOP_STILL_S)
    assert [(o.intent, o.text) for o in out] == [("stop", None)] and counts["cancelled_by_stop_gesture"] == 1
    out, counts = _decide("come here", STOP_STILL_S)
    assert [type(o).__name__ for o in out] == ["FusedCommand", "Clarification"]
    assert out[0].intent == "stop" and out[1].reason == "conflict" and counts["stop_gesture_conflict"] == 1
