"""Speech first (issue #42, common/speech_first.py): the decision to ease video while speech decodes, the eased
frame plan of gesture (services/gesture/schedule.py `eased`), and the recogniser worker's decode notices
(services/speech/pipeline.py) — pure, no Zenoh."""

from __future__ import annotations

import threading

import numpy as np

from common.speech_first import EASED_PERIOD_S, HOLD_S, EasedRate, SpeechFirst
from services.gesture.schedule import Due, FramePlan, StageCosts, StageScheduler, eased
from services.speech.pipeline import RecognitionWorker
from services.speech.recognizers import Recognition


def test_easing_lasts_from_true_to_false() -> None:
    first = SpeechFirst()
    assert not first.easing(10.0)
    first.heard("mic0", True, 10.0)
    assert first.easing(10.3)
    first.heard("mic0", False, 10.4)
    assert not first.easing(10.4)


def test_a_lost_false_eases_at_most_the_hold() -> None:
    first = SpeechFirst()
    first.heard("mic0", True, 10.0)
    assert first.easing(10.0 + HOLD_S - 0.01)
    assert not first.easing(10.0 + HOLD_S + 0.01)
    assert not first.easing(10.0 + HOLD_S - 0.01)  # forgotten, not revived


def test_each_microphone_eases_until_its_own_decode_ends() -> None:
    first = SpeechFirst()
    first.heard("a", True, 1.0)
    first.heard("b", True, 1.1)
    first.heard("a", False, 1.2)
    assert first.easing(1.3)
    first.heard("b", False, 1.4)
    assert not first.easing(1.4)
    first.heard("c", False, 1.5)  # an end without a start changes nothing
    assert not first.easing(1.5)


def test_vision_takes_one_frame_a_period_while_easing_and_every_frame_otherwise() -> None:
    rate = EasedRate()
    frames = [k / 30.0 for k in range(60)]  # 2 s at 30 fps
    assert all(rate.take(t, easing=False) for t in frames)
    rate = EasedRate()
    taken = [t for t in frames if rate.take(t, easing=True)]
    assert len(taken) == int(2.0 / EASED_PERIOD_S)  # one a period (a period is 7.5 frames: every 8th)
    assert all(b - a >= EASED_PERIOD_S for a, b in zip(taken, taken[1:]))


def test_the_eased_plan_keeps_hands_and_faces_and_drops_the_heavy_stages() -> None:
    costs = StageCosts()
    plan = FramePlan(True, True, True, True, costs.pose + costs.faces + costs.hands + costs.persons)
    out = eased(plan)
    # the face stage is kept: the mouths of whoever speaks next are read while the last utterance decodes
    assert (out.pose, out.faces, out.hand_search, out.persons) == (False, True, True, False)
    assert out.cost == costs.hands + costs.faces
    light = FramePlan(False, True, True, False, costs.hands + costs.faces)
    assert eased(light) is light
    # from the scheduler: a frame every stage is due on
    scheduler = StageScheduler()
    planned = scheduler.plan(Due(pose=True, hands_tracked=True, faces=True, hand_search=True, persons=True))
    assert not eased(planned).pose and eased(planned).faces and not eased(planned).persons


class SlowRecogniser:
    name, min_confidence, speculative, matches = "slow", 0.0, False, None

    def __init__(self) -> None:
        self.go = threading.Event()

    def recognise(self, audio: np.ndarray) -> Recognition | None:
        self.go.wait(5.0)
        return None


def test_the_worker_tells_when_each_decode_starts_and_ends() -> None:
    recogniser = SlowRecogniser()
    worker = RecognitionWorker(recogniser)
    told: list[tuple[bool, str]] = []
    started = threading.Event()

    def on_busy(busy: bool, mic: str) -> None:
        told.append((busy, mic))
        started.set()

    worker.on_busy = on_busy
    try:
        future = worker.submit(np.zeros(1600, np.float32), "mic0")
        assert started.wait(5.0)
        assert told == [(True, "mic0")]  # while it decodes
        recogniser.go.set()
        future.result(5.0)
        assert told == [(True, "mic0"), (False, "mic0")]
    finally:
        worker.close()
