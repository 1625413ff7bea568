"""Gestures without speech: an open palm means stop, a wave come here, once per episode (the events of one hand
and gesture close together); and the memory of the stops and waves shown, which decides what an utterance said
meanwhile means (an open palm cancels it; a spoken "come here" during a wave is not said twice)."""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Any, Iterable

from common.counters import GestureIntent
from common.schema import GestureEvent, Hands

OPEN_PALM_FRAMES = 3  # hand frames showing an open palm during an utterance cancel it (one frame may be noise)
MEMORY = 64  # stops / waves / episodes remembered


@dataclass(frozen=True)
class GestureCommand:
    intent: GestureIntent
    realtime: bool  # a stop goes out at once, at REAL_TIME priority
    why: str


class Gestures:
    def __init__(self, min_score: float, episode_gap: float, horizon: float):
        self.min_score = min_score  # open_palm / wave events below this are ignored
        self.episode_gap = episode_gap  # s: events of one gesture this close belong to one episode
        self.horizon = horizon
        self.stops: collections.deque[float] = collections.deque(maxlen=MEMORY)
        self.waves: collections.deque[float] = collections.deque(maxlen=MEMORY)
        self.episodes: dict[tuple, tuple[float, bool]] = {}  # (key, hand, gesture) -> (last stamp, ended)

    def on_event(self, key: str, ev: GestureEvent) -> GestureCommand | None:
        """The command a (buffered, not duplicate) gesture event gives: the first of its episode only."""
        if ev.gesture not in ("open_palm", "wave") or ev.score < self.min_score:
            return None
        episode = (key, ev.hand, ev.gesture)
        last = self.episodes.get(episode)
        new = last is None or last[1] or ev.start > last[0] + self.episode_gap or ev.stamp < last[0] - self.horizon
        self.episodes[episode] = (max(ev.stamp, ev.end, last[0] if last and not new else 0.0), ev.phase == "end")
        self._prune_episodes(ev.stamp)
        if not new:
            return None
        if ev.gesture == "open_palm":
            self.stops.append(ev.start)
            return GestureCommand(
                "stop", True, f"open palm shown by the {ev.hand} hand (score {ev.score:.2f}): stop at once"
            )
        self.waves.append(ev.start)
        return GestureCommand("come_here", False, f"{ev.hand} hand waving (score {ev.score:.2f}): come here")

    def _prune_episodes(self, stamp: float) -> None:
        if len(self.episodes) > MEMORY:
            for k in [k for k, (s, _) in self.episodes.items() if s < stamp - self.horizon]:
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
