"""A recording as the page plays it: samples in receive order, a cursor, play / pause / seek. Pure.

The cursor is in recording time (the recorder's receive clock, as `hri replay` uses); what the page shows at
a position is exactly what a live `hri view` would have shown at that moment of the session. Seeking back
replays the samples from the start into a fresh state (fast: no waiting, frames are not decoded).
"""

from __future__ import annotations

import bisect
from typing import Any

from hri.recording import NS, SessionReader
from hri.view.core import ViewState


class Player:
    def __init__(self, messages: list[tuple[int, str, bytes, int]], state: ViewState):
        """`messages`: (log_ns, key, payload, publish_ns) in log-time order."""
        self.messages = messages
        self.state = state
        self.times = [m[0] for m in messages]
        self.start_ns = self.times[0] if messages else 0
        self.end_ns = self.times[-1] if messages else 0
        self.index = 0  # messages[:index] are in the state
        self.position_ns = self.start_ns
        self.playing = False
        self.speed = 1.0

    @classmethod
    def open(cls, path: str, state: ViewState) -> "Player":
        reader = SessionReader(path)
        try:
            messages = [(m.log_ns, m.key, m.payload, m.publish_ns) for m in reader.messages()]
        finally:
            reader.close()
        return cls(messages, state)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS

    def seek(self, offset_s: float, jump: bool = True) -> None:
        """Show the session as it was `offset_s` seconds after its first sample.

        `jump` (a user's seek): show the newest frame before the cursor at once; while playing, frames keep
        their budget of `max_fps` per camera in recording time."""
        target = self.start_ns + int(max(0.0, min(offset_s, self.duration_s)) * NS)
        if target < self.position_ns:
            self.state.reset()
            self.index = 0
        end = bisect.bisect_right(self.times, target)
        for log_ns, key, payload, _ in self.messages[self.index : end]:
            # frame budget in recording time, so a seek lands on the newest frame before the cursor
            self.state.ingest(key, payload, now=log_ns / NS)
        self.index = max(self.index, end)
        self.position_ns = target
        self.state.tick(target / NS, force=jump)
        if self.position_ns >= self.end_ns:
            self.playing = False

    def advance(self, wall_seconds: float) -> None:
        """Move the cursor on by `wall_seconds` of playing time (called by the shell's clock)."""
        if self.playing:
            self.seek(self.offset_s + wall_seconds * self.speed, jump=False)

    @property
    def offset_s(self) -> float:
        return (self.position_ns - self.start_ns) / NS

    def status(self) -> dict[str, Any]:
        return {
            "duration": self.duration_s,
            "position": self.offset_s,
            "playing": self.playing,
            "speed": self.speed,
            "start": self.start_ns / NS,
            "samples": len(self.messages),
            "index": self.index,
        }

    def at_stamp(self, stamp: float) -> None:
        """Feed every sample whose source stamp is at or before `stamp` (for `--snapshot --at`)."""
        self.state.reset()
        for log_ns, key, payload, publish_ns in self.messages:
            if publish_ns <= stamp * NS:
                self.state.ingest(key, payload, now=log_ns / NS)
        self.state.tick(float("inf"), force=True)
