"""Unit tests of fusion's gestures (services/fusion/gestures.py): one command per gesture episode."""

from __future__ import annotations

from services.fusion.core import Config, FusionCore
from services.fusion.gestures import OPEN_PALM_FRAMES, Gestures
from testkit.scenarios import BASE_STAMP, gesture, hands


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


def test_an_open_palm_during_an_utterance_is_seen_from_the_event_or_from_enough_hand_frames():
    gestures = Gestures(min_score=0.5, episode_gap=1.5, horizon=30.0)
    _, palm = hands(0.5, show="open_palm").build(BASE_STAMP)
    assert not gestures.stop_shown(BASE_STAMP, BASE_STAMP + 2.0, [palm] * (OPEN_PALM_FRAMES - 1))  # may be noise
    assert gestures.stop_shown(BASE_STAMP, BASE_STAMP + 2.0, [palm] * OPEN_PALM_FRAMES)
    key, ev = gesture(1.0, "open_palm", "start").build(BASE_STAMP)
    assert gestures.on_event(key, ev).intent == "stop"
    assert gestures.stop_shown(BASE_STAMP, BASE_STAMP + 2.0, [])
    assert not gestures.stop_shown(BASE_STAMP + 3.0, BASE_STAMP + 5.0, [])
    key, ev = gesture(1.0, "wave", "start").build(BASE_STAMP)
    assert gestures.on_event(key, ev).intent == "come_here" and gestures.waved(BASE_STAMP, BASE_STAMP + 2.0)
    key, weak = gesture(4.0, "wave", "start", score=0.3).build(BASE_STAMP)
    assert gestures.on_event(key, weak) is None
