"""The runner's inbox policies and counters, without Zenoh."""

import logging

from common.runner import Counters, Delivery, Inbox


def make_inbox():
    counters = Counters(logging.getLogger("test"))
    return Inbox(counters), counters


def test_latest_policy_keeps_only_the_newest_per_key_and_counts_skips():
    inbox, counters = make_inbox()
    handler = object()
    for seq in range(5):
        inbox.put_latest(handler, Delivery("hri/camera/a/frame", seq, 0.0))
    inbox.put_latest(handler, Delivery("hri/camera/b/frame", 100, 0.0))
    got = [inbox.get(0.01)[1] for _ in range(2)]
    assert [(d.key, d.sample) for d in got] == [("hri/camera/a/frame", 4), ("hri/camera/b/frame", 100)]
    assert inbox.get(0.01) is None
    assert counters.snapshot()["skipped"] == 4


def test_fifo_policy_is_lossless_in_order_and_comes_before_frames():
    inbox, counters = make_inbox()
    inbox.put_latest("frames", Delivery("hri/camera/a/frame", "frame", 0.0))
    for i in range(3):
        inbox.put_fifo("speech", Delivery("hri/speech/m/transcript", i, 0.0), channel=0, maxlen=10)
    order = [inbox.get(0.01)[1].sample for _ in range(4)]
    assert order == [0, 1, 2, "frame"]
    assert counters.snapshot()["skipped"] == 0


def test_fifo_overflow_drops_the_oldest_of_that_channel_and_counts_it():
    inbox, counters = make_inbox()
    for i in range(5):
        inbox.put_fifo("h", Delivery("k", i, 0.0), channel=0, maxlen=3)
    inbox.put_fifo("h", Delivery("other", "x", 0.0), channel=1, maxlen=3)
    drained = [inbox.get(0.01)[1].sample for _ in range(4)]
    assert drained == [2, 3, 4, "x"]
    assert counters.snapshot()["other"]["dropped_overflow"] == 2


def test_reject_counts_by_reason_and_rate_limits_its_log(caplog):
    counters = Counters(logging.getLogger("test"))
    with caplog.at_level(logging.WARNING):
        for _ in range(250):
            counters.reject("not_msgpack", "Unpack failed", "hri/x")
        counters.reject("not_finite", "stamp: nan", "hri/x")
    assert counters.snapshot()["rejected"] == {"not_msgpack": 250, "not_finite": 1}
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2  # one line per reason within the interval; the count comes in the next one
    assert "hri/x" in lines[0] and "not_msgpack" in lines[0]
