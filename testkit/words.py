"""When to say it: a moment for a test's words to end at so that fusion's window for them holds what the test
needs, whatever the lag of the services (issue #41).

Words that end "now" are joined with whatever the services have published for that stretch of source time; on a
loaded machine vision lags the clock by seconds, its first frames come before any depth, a camera just switched to a
new photo still has the old one's frames in flight. Instead the test picks the capture stamp of a sample already
received, such that every sample of that stream over fusion's window for the words (`window_before` before their
start — and `vision_lookback` before that, where fusion may look — to `window_after` after their end) is `ready`,
and the window is closed: a later sample has arrived on that stream and on every stream in `closed_by`."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from hri.cli import make_transcript
from services.fusion.core import Config as FusionConfig
from testkit.harness import Collector


def words_end_over(
    text: str,
    stream: Collector,
    ready: Callable[[Any], bool],
    what: str,
    *,
    closed_by: Sequence[Collector] = (),
    lookback: bool = False,
    earliest_start: float = float("-inf"),
    timeout: float = 90,
) -> Any:
    """A sample of `stream` whose stamp the words `text` may end at (see the module). `lookback`: the samples fusion
    may read before the window (vision's look-back) must be ready too. `earliest_start`: the words may not start
    before this source time (a question left open must have expired). Raises AssertionError naming `what` and the
    last samples seen when no such moment comes within `timeout` s."""
    cfg = FusionConfig()  # fusion as the tests start it: the default windows
    deadline = time.monotonic() + timeout
    samples: list[Any] = []
    while time.monotonic() < deadline:
        samples = [s for _, s in stream.drain(0.5) if hasattr(s, "stamp")]  # every sample so far
        others = [max((s.stamp for _, s in c.drain() if hasattr(s, "stamp")), default=float("-inf")) for c in closed_by]
        for last in reversed(samples):
            start = make_transcript(text, mic="kbd", end=last.stamp, confidence=0.95, source="test").start
            lo = start - cfg.window_before - (cfg.vision_lookback if lookback else 0.0)
            hi = last.stamp + cfg.window_after
            if start < earliest_start:
                break  # earlier samples start earlier still
            closed = samples[-1].stamp > hi and all(t > hi for t in others)
            if closed and all(ready(s) for s in samples if lo <= s.stamp <= hi):
                return last
    raise AssertionError(
        f"no moment for {text!r} to end at where the window holds {what}: {len(samples)} samples, the last "
        f"{[round(s.stamp, 2) for s in samples[-3:]]}"
    )
