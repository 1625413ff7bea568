"""Only what is meant for the robot (issue #40), on real clips of ../shared/data/intent/ through the gesture core and
fusion as the services run them (testkit/intent.py; MediaPipe runs in the test, nothing of shared/ is kept):
people talking with their hands or just moving give no gesture command; the close-up deliberate stop stops, the
same whichever frames a loaded service happened to process; an arm waved at room distance calls; a command said
over gesturing hands is answered.
Frames are windows of the clips (their labelled stretches, intent.json) to keep the run short."""

from __future__ import annotations

import pytest

from common.schema import Clarification, FusedCommand
from services.fusion.gestures import STOP_STILL_S
from services.gesture.core import GestureSettings
from testkit.intent import clip_frames, gesture_commands, gesture_samples, run_fusion, subset, transcript
from testkit.shared import shared_path


def _clip(name: str, first_s: float, last_s: float) -> tuple[list, float, int]:
    """The frames of [first_s, last_s) of a clip, its frame rate and the index of its first frame."""
    images, fps = clip_frames(shared_path(f"data/intent/{name}"), int(last_s * 40))
    first, last = int(first_s * fps), int(last_s * fps)
    assert len(images) >= last, name
    return images[first:last], fps, first


def _commands(name: str, first_s: float, last_s: float, keep: str = "all") -> list[tuple[str, float]]:
    images, fps, first = _clip(name, first_s, last_s)
    samples = gesture_samples(GestureSettings(), images, fps, subset(len(images), keep))
    return [(i, t + first / fps) for i, t in gesture_commands(run_fusion(samples))]


@pytest.mark.parametrize(
    "name, first_s, last_s",
    [
        # a woman interviewed, seated: open palms held up to 0.8 s while she talks (she gave 6 commands before)
        ("cat4_tango_1wrQ6_woman_seated.mp4", 0.0, 6.0),
        # repeated swipes across the body at a webcam, each a flash of open palm (2 stops before)
        ("cat2_webcam_swipe_wave_thumbs.mp4", 1.5, 5.5),
        # five people seated at desks, barely moving (a come_here before)
        ("cat5_intel_classroom_preview.gif", 0.0, 2.7),
    ],
)
def test_people_talking_with_their_hands_or_just_moving_give_no_gesture_command(
    name: str, first_s: float, last_s: float
) -> None:
    assert _commands(name, first_s, last_s) == []


def test_a_close_up_deliberate_stop_stops_within_the_hold_whichever_frames_were_processed() -> None:
    """The palm held flat to a handheld phone (labelled 1.25-2.5 s, flat stop 2.25-2.5): a stop before the hold ends
    (plus 0.8 s, the issue's bound), with every frame, every 2nd frame from 0 or 1, or 70 % drawn at random; and
    nothing but stops."""
    stops = {}
    for keep in ("all", "every2+0", "every2+1", "random70/1"):
        commands = _commands("cat1_palm_closeup_phone.mp4", 1.2, 3.0, keep)
        assert commands and {i for i, _ in commands} == {"stop"}, (keep, commands)
        stops[keep] = commands[0][1]
    assert all(1.25 + STOP_STILL_S <= t <= 2.5 + 0.8 for t in stops.values()), stops


def test_a_command_said_over_talking_hands_is_answered() -> None:
    """ "turn left" said while the seated woman's palms move (and are held) as she talks: answered, never dropped;
    "come here" too."""
    images, fps, _ = _clip("cat4_tango_1wrQ6_woman_seated.mp4", 0.0, 6.0)
    said = [transcript(0.2, 1.4, "turn left"), transcript(2.2, 3.4, "turn right"), transcript(4.0, 5.0, "come here")]
    outputs = run_fusion(gesture_samples(GestureSettings(), images, fps, subset(len(images), "every2+0")), said)
    answered = [
        o for o in outputs if isinstance(o, (FusedCommand, Clarification)) and o.stamp in {t.stamp for t in said}
    ]
    assert [getattr(o, "intent", None) for o in answered] == ["turn", "turn", "come_here"]


def test_an_arm_waved_at_room_distance_calls_once_whichever_frames_were_processed() -> None:
    """The KARD clip (intent.json: an arm held out and swept across at the camera at ~3 m, 0.5-2.0 s): the hand is
    ~15 px and blurred, MediaPipe Hands sees it on a few frames; the skeleton's lifted, sweeping arm is the wave
    (services/gesture/deliberate.py `ArmSwing`). One come_here within the labelled wave (+ 0.5 s), with every frame,
    every 2nd frame from 0 or 1, or 70 % at random; no stop."""
    for keep in ("all", "every2+0", "every2+1", "random70/1"):
        commands = _commands("cat2_kard_horizontal_arm_wave_s05.mp4", 0.0, 3.0, keep)
        assert [i for i, _ in commands] == ["come_here"], (keep, commands)
        assert 0.5 <= commands[0][1] <= 2.0 + 0.5, (keep, commands)
