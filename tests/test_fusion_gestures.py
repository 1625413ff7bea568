"""Unit tests of fusion's gestures (services/fusion/gestures.py): one command per gesture episode."""

from __future__ import annotations

from services.fusion.core import Config, FusionCore
from tests.scenarios import BASE_STAMP, gesture


def test_gesture_episode_gives_one_stop_and_a_new_episode_another():
    core = FusionCore(Config(), "fusion/test")
    outs = []
    for step in [gesture(0.5, "open_palm", "start"), gesture(0.8, "open_palm", "hold"),
                 gesture(1.0, "open_palm", "end"), gesture(5.0, "open_palm", "start")]:
        outs += core.on_gesture_event(*step.build(BASE_STAMP), 1000.0)
    assert [o.sample.intent for o in outs] == ["stop", "stop"] and all(o.realtime for o in outs)
    assert outs[0].sample.id != outs[1].sample.id
