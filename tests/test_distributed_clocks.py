"""Clocks that differ: fusion's estimate of each source's clock offset (pure) and across namespace hosts."""

from __future__ import annotations

import random
import time

import pytest

from common.schema import Hands
from services.fusion.join import ClockOffsets, clock_verdict
from testkit.harness import Client
from testkit.netns import netns_fixture


def feed(
    clocks: ClockOffsets,
    source: str,
    skew: float,
    n: int,
    rng: random.Random,
    t0: float = 1.0e9,
    router_skew: float = 0.0,
) -> None:
    """`n` samples at 30 Hz from a source whose clock runs `skew` s ahead of ours; each stamped when its frame was
    taken, published after a processing delay of 20-120 ms, 0.2-5 ms on the network to the router (whose clock
    runs `router_skew` ahead), as much again to us."""
    for i in range(n):
        true_t = t0 + i / 30
        published = true_t + rng.uniform(0.02, 0.12)
        at_router = published + rng.uniform(0.0002, 0.005)
        at_us = at_router + rng.uniform(0.0002, 0.005)
        clocks.add(source, true_t + skew, at_router + router_skew, at_us)


@pytest.mark.parametrize("skew", [0.3, -0.3, 0.0])
def test_the_estimate_is_the_skew_less_the_fastest_delay(skew):
    clocks = ClockOffsets()
    feed(clocks, "gesture/a", skew, 200, random.Random(1))
    est = clocks.offset("gesture/a")
    # a source's fastest processing (20 ms) + network reads as its clock being a little behind, never ahead
    assert skew - 0.04 <= est <= skew, est


def test_the_router_clock_cancels_out():
    for router_skew in (0.5, -0.8):
        clocks = ClockOffsets()
        rng = random.Random(2)
        feed(clocks, "vision/a", 0.3, 100, rng, router_skew=router_skew)
        feed(clocks, "gesture/b", -0.3, 100, rng, router_skew=router_skew)
        offsets = clocks.offsets()
        assert 0.26 <= offsets["vision/a"] <= 0.3 and -0.34 <= offsets["gesture/b"] <= -0.3, offsets


def test_without_router_timestamps_arrival_time_is_the_reference():
    clocks = ClockOffsets()
    for i in range(50):
        clocks.add("speech/a", 100.0 + i + 0.3, None, 100.0 + i + 0.01)
    assert clocks.offset("speech/a") == pytest.approx(0.29)
    assert clocks.router_offset() == 0.0


def test_one_slow_sample_does_not_move_it_and_a_step_shows_within_the_window():
    clocks = ClockOffsets(window=16)
    for i in range(16):
        clocks.add("s", i + 0.1, i + 0.12, i + 0.12)
    clocks.add("s", 20.0, 21.5, 21.5)  # 1.5 s late
    assert clocks.offset("s") == pytest.approx(-0.02)
    for i in range(16):  # the source's clock stepped 0.5 s ahead
        clocks.add("s", 30 + i + 0.5, 30 + i + 0.02, 30 + i + 0.02)
    assert clocks.offset("s") == pytest.approx(0.48)


def feed_transcripts(clocks: ClockOffsets, source: str, skew: float, rng: random.Random, t0: float = 1.0e9) -> None:
    """20 utterances from a speech source whose clock runs `skew` ahead: each stamped at its end, published after
    recognition (0.25-1.9 s: the delays measured under load in issue #34), 1-5 ms to the router, as much to us."""
    for i in range(20):
        end = t0 + 6.0 * i
        published = end + rng.uniform(0.25, 1.9)
        at_router = published + rng.uniform(0.001, 0.005)
        clocks.add(source, end + skew, at_router, at_router + rng.uniform(0.001, 0.005), late_by_design=True)


def test_speech_recognition_delay_is_reported_as_delay_not_as_a_clock_behind():
    clocks = ClockOffsets()
    rng = random.Random(3)
    feed(clocks, "gesture/a", 0.0, 200, rng)
    feed_transcripts(clocks, "speech/a", 0.0, rng)
    assert "speech/a" not in clocks.offsets() and clocks.offset("speech/a") is None
    delay = clocks.delay("speech/a")
    assert delay is not None and 0.25 <= delay <= 0.45, delay  # the fastest of 20 recognitions, not a skew
    assert clocks.delays() == {"speech/a": delay}  # a source on time has no delay entry
    assert -0.04 <= clocks.offsets()["gesture/a"] <= 0.0


def test_a_late_by_design_source_whose_clock_runs_ahead_is_still_an_offset():
    clocks = ClockOffsets()
    feed_transcripts(clocks, "speech/a", 0.8, random.Random(4))  # 0.8 s ahead outweighs its fastest 0.25 s delay
    offset = clocks.offset("speech/a")
    assert offset is not None and 0.8 - 0.45 <= offset <= 0.8 - 0.25, offset  # less the fastest delay of 20
    assert clocks.delay("speech/a") is None
    verdict = clock_verdict(offset, 0.15, 0.5)
    assert verdict == "ahead"


def test_a_source_that_left_is_forgotten():
    clocks = ClockOffsets()
    clocks.add("vision/a", 10.3, 10.0, 10.0)
    clocks.forget("vision/a")
    assert clocks.offset("vision/a") is None and clocks.offsets() == {}
    clocks.add("speech/a", 10.0, 10.5, 10.5, late_by_design=True)
    clocks.forget("speech/a")
    clocks.add("speech/a", 20.3, 20.0, 20.0)  # a new instance under the same name, not late: an offset again
    assert clocks.delays() == {} and clocks.offset("speech/a") == pytest.approx(0.3)


def test_a_silent_source_expires_so_one_shot_sources_do_not_pile_up():
    clocks = ClockOffsets(idle_s=60)
    for i in range(100):  # `hri say` 100 times: 100 sources of one sample each
        clocks.add(f"cli/{i}", 100.0 + i, None, 100.0 + i)
    clocks.add("gesture/a", 200.0, None, 200.0)
    assert len(clocks.expire(200.0)) == 40  # silent for more than 60 s
    assert len(clocks.offsets()) == 61 and "gesture/a" in clocks.offsets()
    clocks.expire(1000.0)
    assert clocks.offsets() == {}


def test_verdict_against_the_window_margins():
    assert clock_verdict(0.3, 0.15, 0.5) == "ahead"
    assert clock_verdict(0.1, 0.15, 0.5) is None
    assert clock_verdict(-0.3, 0.15, 0.5) is None
    assert clock_verdict(-0.6, 0.15, 0.5) == "behind"


netns_group = pytest.fixture(netns_fixture)


@pytest.mark.integration
def test_fusion_reports_sources_300_ms_ahead_and_behind_and_warns(netns_group):
    g = netns_group
    g.router()
    fusion = g.service("fusion", "--window-before", "0.5", host="speech")  # tolerates 250 ms behind
    client = Client(g.endpoint)
    try:
        client.wait_alive("fusion", timeout=90)
        time.sleep(0.5)
        for i in range(40):  # 2 s of hands from three sources: in step, ahead and behind
            for cam, skew in (("ok", 0.0), ("ahead", 0.3), ("behind", -0.3)):
                client.publish(
                    f"hri/gesture/{cam}/hands",
                    Hands(
                        stamp=time.time() + skew,
                        source=f"gesture/{cam}",
                        seq=i,
                        cam=cam,
                        width=640,
                        height=480,
                        hands=[],
                    ),
                )
            time.sleep(0.05)
        time.sleep(1.5)  # fusion updates its stats every second
        other = client.stats("fusion")["other"]
        ms = {s: other.get(f"clock_offset_ms:gesture/{s}") for s in ("ok", "ahead", "behind")}
        print("clock offsets (ms):", ms)
        # across the namespaces the delays are the network's and the router's: milliseconds
        assert -40 <= ms["ok"] <= 5 and 260 <= ms["ahead"] <= 305 and -340 <= ms["behind"] <= -295, ms
        log = fusion.output()
        assert "gesture/ahead's stamps run" in log and "ahead of this machine's clock" in log, log[-3000:]
        assert "gesture/behind's stamps run" in log and "gesture/ok's stamps" not in log, log[-3000:]
    finally:
        client.close()
