"""Stamp rules every receiver applies: one definition for every service and for fusion's join. Pure.

- A stamp more than `max_skew` seconds ahead of the receiver's clock is rejected as `future_stamp`; it
  never moves a high mark or watermark (one forged or broken sample must not blind a stream for good).
- Per stream (key), a stamp older than the stream's high mark minus `tolerance` is `out_of_order`.
- A stream that went back in time (a camera's clock stepped back, a replay restarted) is followed again after
  `reset_run` consecutive samples that are all behind the high mark and consistent among themselves
  (non-decreasing, each within `max_gap` of the previous): the last of them is accepted as `timeline_reset`
  and becomes the new high mark. The run's earlier samples are dropped as `out_of_order`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Final

DEFAULT_MAX_SKEW_S = 5.0  # NTP-synced machines differ by milliseconds; 5 s leaves room for a sloppy clock
DEFAULT_RESET_RUN = 5  # 1/6 s of a 30 fps camera; a stray old sample or two never resets a timeline
DEFAULT_MAX_GAP_S = 10.0  # samples of one new timeline are close together

FUTURE: Final = "future_stamp"
OUT_OF_ORDER: Final = "out_of_order"
ACCEPTED: Final = "accepted"
RESET: Final = "timeline_reset"


@dataclass
class _Stream:
    high: float
    run: list[float] = field(default_factory=list)  # consecutive behind-the-mark stamps, non-decreasing


@dataclass
class StampGuard:
    """Per-key high marks with future and timeline rules. `check` says what to do with one sample."""

    max_skew: float = DEFAULT_MAX_SKEW_S
    reset_run: int = DEFAULT_RESET_RUN
    tolerance: float = 0.0  # how far behind the high mark a sample may be and still be accepted (reordering)
    max_gap: float = DEFAULT_MAX_GAP_S
    max_keys: int = 4096  # bounds memory under a flood of made-up keys
    streams: dict[str, _Stream] = field(default_factory=dict)

    def is_future(self, stamp: float, now: float) -> bool:
        return stamp > now + self.max_skew

    def check(self, key: str, stamp: float, now: float | None) -> str:
        """ACCEPTED, RESET (accepted, a new timeline), FUTURE or OUT_OF_ORDER (both: drop the sample).

        `now` is the receiver's wall clock; None skips the future rule (pure replays of recorded stamps)."""
        if now is not None and self.is_future(stamp, now):
            return FUTURE
        s = self.streams.get(key)
        if s is None:
            if len(self.streams) >= self.max_keys:
                self.streams.pop(next(iter(self.streams)))
            self.streams[key] = _Stream(stamp)
            return ACCEPTED
        if stamp >= s.high - self.tolerance:
            s.high = max(s.high, stamp)
            s.run.clear()
            return ACCEPTED
        if s.run and not (s.run[-1] <= stamp <= s.run[-1] + self.max_gap):
            s.run.clear()  # not one consistent timeline: start counting again from this sample
        s.run.append(stamp)
        if len(s.run) >= self.reset_run:
            s.high = stamp
            s.run.clear()
            return RESET
        return OUT_OF_ORDER

    def high(self, key: str) -> float | None:
        s = self.streams.get(key)
        return None if s is None else s.high

    def forget(self, key: str) -> None:
        self.streams.pop(key, None)
