"""Unit tests of fusion's join (services/fusion/join.py): buffers, the readiness policy, liveness; through the core,
waiting for a live modality until the deadline."""

from __future__ import annotations

from services.fusion.core import Config, FusionCore
from services.fusion.join import Join, Liveness, Ready, SeenOnce, StreamBuffer, Wait, ready
from testkit.scenarios import BASE_STAMP, say, scene
from testkit.scenarios.suite import TWO_CUPS


def test_stream_buffer_orders_dedupes_and_stays_bounded():
    buf = StreamBuffer(horizon=5.0)
    for s in (3.0, 1.0, 2.0, 2.0):
        buf.add(s, s)
    assert buf.stamps == [1.0, 2.0, 3.0]
    assert buf.add(2.0, "again") == "duplicate"
    for i in range(1000):
        buf.add(1000.0 + i * 0.1, i)
    assert buf.stamps[0] >= buf.watermark - 5.0 and len(buf) <= 51
    assert buf.add(buf.watermark - 6.0, "old") == "late"
    restart = buf.watermark - 500.0
    verdicts = [buf.add(restart + 0.1 * i, "replay restarted") for i in range(buf.reset_run)]
    assert verdicts == ["late"] * (buf.reset_run - 1) + ["reset"] and len(buf) == 1
    assert buf.add(restart + 1.0, "new timeline") == "added" and buf.watermark == restart + 1.0


def test_stream_buffer_keeps_what_a_pending_window_needs():
    buf = StreamBuffer(horizon=5.0)
    buf.add(1.0, "needed")
    buf.add(100.0, "jump", keep_from=0.5)
    assert buf.between(0.0, 2.0) == ["needed"]


def test_ready_waits_for_live_watermarks_or_the_deadline():
    marks = {"vision": 10.0, "gesture": 9.0}
    assert ready(9.5, 0.0, 0.1, 0.5, marks, ["vision", "gesture"]) == Wait(behind=("gesture",))
    assert ready(9.5, 0.0, 0.1, 0.5, marks, ["vision"]) == Ready("watermarks")  # gesture not live: not waited for
    why = ready(9.5, 0.0, 0.6, 0.5, marks, ["vision", "gesture"])
    assert why == Ready("deadline", behind=("gesture",)) and "gesture" in str(why)


def test_liveness_token_or_recent_samples():
    live = Liveness(recent_s=2.0)
    assert not live.live("vision", 100.0)
    live.arrived("vision", 100.0)
    assert live.live("vision", 101.0) and not live.live("vision", 103.0)
    live.token("vision", "a", True)
    assert live.live("vision", 500.0)
    live.token("vision", "a", False)
    assert not live.live("vision", 500.0)


def test_a_vision_token_makes_fusion_wait_until_the_deadline():
    core = FusionCore(Config(max_wait=0.5), "fusion/test")
    core.on_liveliness("vision", "v1", True)
    key, t = say(0.0, 1.0, "hello").build(BASE_STAMP)
    core.on_transcript(key, t, 1000.0)
    assert core.tick(1000.1) == []
    (out,) = core.tick(1000.6)
    assert out.sample.intent == "greet" and out.sample.inputs["vision"] is None
    core.on_liveliness("vision", "v1", False)
    key, t = say(5.0, 6.0, "hello").build(BASE_STAMP)
    core.on_transcript(key, t, 1001.0)
    assert len(core.tick(1001.0)) == 1  # the token is gone: no waiting


def test_deadline_decides_with_what_is_there_and_says_what_is_missing():
    core = FusionCore(Config(max_wait=0.5), "fusion/test")
    for step in scene(TWO_CUPS, -1.5, 0.5):  # vision stalls before the utterance ends
        core.on_detections(*step.build(BASE_STAMP), 1000.0)
    key, t = say(0.0, 1.5, "pick up the red cup").build(BASE_STAMP)
    core.on_transcript(key, t, 1000.0)
    assert core.tick(1000.2) == []
    (out,) = core.tick(1000.6)
    assert out.sample.target.id == "cup_red" and "deadline" in out.sample.explanation


class _Window:
    def __init__(self, lo, hi, arrived, order):
        self.lo, self.hi, self.arrived, self.order = lo, hi, arrived, order


def test_join_decides_windows_in_order_and_a_waiting_head_holds_back_the_later_ones():
    join = Join(horizon=30.0, lookback=2.0, max_wait=0.5, live_recent_s=2.0)
    later, first = _Window(5.0, 6.0, 100.0, 2), _Window(1.0, 2.0, 100.0, 1)
    join.open(later)
    join.open(first)
    join.add("vision", "cam0", 5.0, "frame", 100.0)  # past the first window's end, not the second's
    join.add("gesture", "cam0", 1.5, "hand", 100.0)  # behind the first window's end
    assert join.due(100.1) == []  # the first waits for gesture, so the second (ready or not) waits too
    join.add("gesture", "cam0", 7.0, "hand", 100.2)
    assert join.due(100.2) == [(first, Ready("watermarks"))]
    assert join.due(100.7) == [(later, Ready("deadline", behind=("vision",)))]  # vision never reached 6.0
    assert len(join) == 0


def test_join_buffers_keep_what_a_pending_window_needs_and_no_more():
    join = Join(horizon=5.0, lookback=2.0, max_wait=0.5, live_recent_s=2.0)
    join.add("vision", "cam0", 1.0, "needed", 100.0)
    join.open(_Window(2.5, 3.0, 100.0, 1))
    assert join.obsolete_before() == 0.5  # the window's start less the vision lookback
    join.add("vision", "cam0", 50.0, "far later", 100.0)  # 1.0 is beyond the horizon, yet still needed
    assert join.streams.between("vision", 0.5, 3.0) == [("cam0", "needed")]
    assert [w for w, _ in join.due(101.0)] and join.obsolete_before() is None
    join.add("vision", "cam0", 51.0, "next", 101.0)  # the window is decided: the horizon alone prunes
    assert join.streams.between("vision", 0.0, 3.0) == []


def test_seen_once_drops_a_redelivered_transcript_and_forgets_beyond_the_horizon():
    seen = SeenOnce(horizon=30.0, cap=3)
    assert seen.first(("speech/mic0", 10.0), 10.0) and not seen.first(("speech/mic0", 10.0), 10.0)
    assert seen.first(("speech/mic0", 50.0), 50.0) and len(seen) == 1  # 10.0 is 40 s behind: forgotten
    for stamp in (51.0, 52.0, 53.0):
        assert seen.first(("speech/mic0", stamp), stamp)
    assert len(seen) == 3 and seen.first(("speech/mic0", 50.0), 53.0)  # the cap pushed the oldest out


def test_a_motion_does_not_wait_for_gestures_after_the_words_but_a_phrase_that_names_something_does():
    """The after-window (--window-after) is where a point completing the words is looked for: a motion or an answer
    names nothing to look at, so it is decided once the inputs have passed the utterance's end."""
    for text, waits in (("turn left", False), ("go forward one meter", False), ("pick up that cup", True)):
        core = FusionCore(Config(max_wait=0.5, window_after=0.3), "fusion/test")
        for step in scene(TWO_CUPS, -1.0, 1.6):  # vision has passed the end (1.5) but not the after-window (1.8)
            core.on_detections(*step.build(BASE_STAMP), 1000.0)
        key, t = say(0.5, 1.5, text).build(BASE_STAMP)
        core.on_transcript(key, t, 1000.0)
        decided = core.tick(1000.05)
        assert (decided == []) == waits, text
        if waits:  # decided at the deadline, with what is there
            assert len(core.tick(1000.6)) == 1
