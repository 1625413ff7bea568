"""Speech first (issue #42): while speech decodes an utterance, the video services ease their heavy stages. Pure,
no Zenoh: the shells feed it the `SpeechDecoding` samples (topic `decoding`) and ask it before each frame.

Every word of a command waits for Whisper's decode (~0.3-0.5 s on 2 cores), and nothing else on the robot is
that urgent: a frame service that falls behind only skips to the newest frame. Niceness (`--nice`, common/cpu.py)
shares a core by weight but cannot stop a video thread from running on the other half of a hyperthreaded core, nor
from filling the memory bandwidth both use: in issue #42's run (a busy scene, 2 cores, the niceness in place) the
last word -> command p50 went from 417 ms to 797 ms. So
for the decode's length the video services do less: vision runs its model on at most one frame every
`EASED_PERIOD_S` (fusion still gets a watermark from it), gesture skips full pose and the person stage (the
skeleton is carried, pose_track.py); hands, their stop palms and the face stage keep running (the next utterance
often starts while the last one decodes: its speaker is read from the mouths seen while it is said).

A decode is eased from its `decoding: true` sample until its `false` sample, and at most `HOLD_S` after the true:
a lost `false` (or a speech service that died) never keeps video eased.
"""

from __future__ import annotations

from dataclasses import dataclass, field

HOLD_S = 2.0  # the longest a decode eases video (Whisper tiny.en on an utterance of 30 s decodes in ~1.5 s)
EASED_PERIOD_S = 0.25  # vision: at most one frame this often while easing (a watermark for fusion's join)


@dataclass
class SpeechFirst:
    """The decodes in progress, per microphone, by the local monotonic time their `true` sample came."""

    hold_s: float = HOLD_S
    since: dict[str, float] = field(default_factory=dict)  # mic -> monotonic time its decode started
    eased: int = 0  # frames or stages eased so far (the service's stats)

    def heard(self, mic: str, decoding: bool, now: float) -> None:
        """A `SpeechDecoding` sample of `mic` arrived at monotonic time `now`."""
        if decoding:
            self.since[mic] = now
        else:
            self.since.pop(mic, None)

    def easing(self, now: float) -> bool:
        """Whether some decode is in progress at `now` (started at most `hold_s` before)."""
        for mic, start in list(self.since.items()):
            if now - start > self.hold_s or now < start:
                del self.since[mic]
        return bool(self.since)


@dataclass
class EasedRate:
    """Vision while easing: one frame in every `period_s` of local time is processed, the others skipped."""

    period_s: float = EASED_PERIOD_S
    last: float | None = None  # monotonic time of the last frame processed

    def take(self, now: float, easing: bool) -> bool:
        """Whether to process the frame arriving at `now`: always when not easing; else one a period."""
        if easing and self.last is not None and 0.0 <= now - self.last < self.period_s:
            return False
        self.last = now
        return True
