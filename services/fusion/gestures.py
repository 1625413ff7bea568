"""Gestures without speech: an open palm means stop, a wave come here, once per episode (the events of one hand
and gesture close together); and the memory of the stops and waves shown, which decides what an utterance said
meanwhile means (an open palm cancels it; a spoken "come here" during a wave is not said twice).

A wave only calls the robot when it is deliberate (issue #34: hands moving at a table while people talk gave
`come_here` nobody asked for): waved without a break for `WAVE_HOLD_S`, by a person not seen turned away from the
camera. A stop is never held back: stopping must not wait, and a wrong stop costs a restart, not a collision."""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Any, Iterable

from common.counters import GestureIntent
from common.schema import GestureEvent, Hands

OPEN_PALM_FRAMES = 3  # hand frames showing an open palm during an utterance cancel it (one frame may be noise)
MEMORY = 64  # stops / waves / episodes remembered
# A wave is recognised from 2 side-to-side reversals within 1.5 s (services/gesture/temporal.py), which hands that
# gesture while talking also make; a wave that goes on for a second more is meant. Seconds from the first wave
# frame (the event's `start`) to the latest (`end`).
WAVE_HOLD_S = 1.0
HOLD_S = {"open_palm": 0.0, "wave": WAVE_HOLD_S}  # the gestures that are commands alone, and their hold


@dataclass
class Episode:
    last: float  # the latest stamp of the episode's events
    ended: bool  # its last event was an `end`
    given: bool  # its command went out


@dataclass(frozen=True)
class GestureCommand:
    intent: GestureIntent
    realtime: bool  # a stop goes out at once, at REAL_TIME priority
    why: str


def deliberate(ev: GestureEvent, facing: bool | None) -> bool:
    """Is this gesture meant for the robot? Held for its HOLD_S, and (but for a stop) by a person who is not seen
    turned away from the camera."""
    if ev.end - ev.start < HOLD_S[ev.gesture] - 1e-9:
        return False
    return ev.gesture == "open_palm" or facing is not False


class Gestures:
    def __init__(self, min_score: float, episode_gap: float, horizon: float):
        self.min_score = min_score  # open_palm / wave events below this are ignored
        self.episode_gap = episode_gap  # s: events of one gesture this close belong to one episode
        self.horizon = horizon
        self.stops: collections.deque[float] = collections.deque(maxlen=MEMORY)
        self.waves: collections.deque[float] = collections.deque(maxlen=MEMORY)
        self.episodes: dict[tuple, Episode] = {}  # (key, hand, gesture) -> the episode going on

    def on_event(self, key: str, ev: GestureEvent, facing: bool | None = None) -> GestureCommand | None:
        """The command a (buffered, not duplicate) gesture event gives: once per episode, at its first event that
        is deliberate (`deliberate`). `facing`: does the person face the camera (None: not seen)."""
        if ev.gesture not in HOLD_S or ev.score < self.min_score:
            return None
        episode = (key, ev.hand, ev.gesture)
        last = self.episodes.get(episode)
        new = (
            last is None or last.ended or ev.start > last.last + self.episode_gap or ev.stamp < last.last - self.horizon
        )
        given = last is not None and not new and last.given
        give = not given and deliberate(ev, facing)
        self.episodes[episode] = Episode(
            max(ev.stamp, ev.end, last.last if last and not new else 0.0), ev.phase == "end", given or give
        )
        self._prune_episodes(ev.stamp)
        if not give:
            return None
        if ev.gesture == "open_palm":
            self.stops.append(ev.start)
            return GestureCommand(
                "stop", True, f"open palm shown by the {ev.hand} hand (score {ev.score:.2f}): stop at once"
            )
        self.waves.append(ev.start)
        return GestureCommand(
            "come_here",
            False,
            f"{ev.hand} hand waving for {ev.end - ev.start:.1f} s (score {ev.score:.2f}"
            f"{', facing the camera' if facing else ''}): come here",
        )

    def _prune_episodes(self, stamp: float) -> None:
        if len(self.episodes) > MEMORY:
            for k in [k for k, e in self.episodes.items() if e.last < stamp - self.horizon]:
                del self.episodes[k]

    def stop_shown(self, lo: float, hi: float, gesture_items: Iterable[Any]) -> bool:
        """An open palm during [lo, hi]: from a stop event, or from the hand frames among `gesture_items` (they
        arrive in order with the gesture watermark, so the answer does not depend on whether the event overtook
        the transcript)."""
        if any(lo <= s <= hi for s in self.stops):
            return True
        frames = 0
        for item in gesture_items:
            if isinstance(item, Hands) and any(
                h.gesture == "open_palm" and h.score >= self.min_score for h in item.hands
            ):
                frames += 1
        return frames >= OPEN_PALM_FRAMES

    def waved(self, lo: float, hi: float) -> bool:
        return any(lo <= s <= hi for s in self.waves)

    def __len__(self) -> int:
        return len(self.episodes)
