"""Gestures without speech: an open palm means stop, a wave come here, once per episode (the events of one hand
and gesture close together; a person waving both arms calls once), and only when the gesture is made *to the
robot*; and the memory of the stops and waves given, which decides what an utterance said meanwhile means.

Deliberate, not incidental (issue #40: people talking with their hands gave 21-30 stops and calls nobody gave on
12 real clips, different from run to run). The gesture service measures the marks it can see on the hand and the
arm (services/gesture/deliberate.py, on the GestureEvent: `still`, `raised`); fusion adds what only it knows (is
the person engaged with the robot, are they speaking now) and decides, over source time, never frame counts:
- a **stop**: the palm held still with the fingers up and turned to the camera for `STOP_STILL_S` (a beat or a
  sweep never is), `SPEAKING_STILL_S` while its person is speaking (a palm while speaking is a beat unless held),
  by a person not seen turned away. An event without the marks (an older gesture service) stops at once, as before;
- a **wave**: waved without a break for `WAVE_HOLD_S`, with the arm raised (the wrist at the shoulder), by a person
  not seen turned away and not speaking (hands swing side to side all the time while people talk; one who waves
  and speaks is heard: "come here", "hello" are commands of their own).
A spoken "stop" never waits for any of this (services/fusion/core.py). An utterance said while a palm is seen is
decided as usual (the palm is counted); only a deliberate stop given while it was said cancels it, or, when it asks
the robot to come to the person ("come here", "follow me"), asks which was meant."""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Any, Iterable

from common.counters import GestureIntent
from common.schema import GestureEvent, Hands

OPEN_PALM_FRAMES = 3  # hand frames showing an open palm during an utterance: a palm was seen (one may be noise)
MEMORY = 64  # stops / waves / episodes remembered
# A stop shown to the robot is held still for a moment; a co-speech beat or a sweep is not (0.3 s: the quickest
# deliberate stop on the intent clips held 0.5 s, docs/gesture.md "Deliberate gestures").
STOP_STILL_S = 0.3
# while the person making it is speaking: a talker's open palm, fingers up, was held still 0.8-1.07 s (by the frames
# processed) on the intent clips; one who speaks can say "stop", which stops at once
SPEAKING_STILL_S = 1.5
# A wave is recognised from 2 side-to-side reversals within 1.5 s (services/gesture/temporal.py), which hands that
# gesture while talking also make; a wave that goes on for a second more is meant. Seconds from the wave's first
# turn (the event's `start`) to its latest frame (`end`).
WAVE_HOLD_S = 1.0
COMMANDS = {"open_palm": "stop", "wave": "come_here"}  # the gestures that are commands alone
CONTRARY_TO_STOP = ("come_here", "follow")  # said during a deliberate stop: which one is meant is asked


@dataclass
class Episode:
    last: float  # the latest stamp of the episode's events
    ended: bool  # its last event was an `end`
    given: bool  # its command went out
    person: str | None = None  # the person making it (GestureEvent.person), None: unknown


@dataclass(frozen=True)
class GestureCommand:
    intent: GestureIntent
    realtime: bool  # a stop goes out at once, at REAL_TIME priority
    why: str


@dataclass(frozen=True)
class Person:
    """What fusion knows of the person making a gesture at its time: engaged with the robot (None: not known) and
    speaking."""

    engaged: bool | None = None
    speaking: bool = False


def deliberate(ev: GestureEvent, person: Person) -> bool:
    """Is this gesture made to the robot (the rules of the module's docstring)?"""
    held = ev.gesture == "open_palm" or ev.end - ev.start >= WAVE_HOLD_S - 1e-9
    if ev.still is None:  # no marks (a gesture service before issue #40): as before, a stop never waits
        return ev.gesture == "open_palm" or (held and person.engaged is not False)
    if person.engaged is False:
        return False
    if ev.gesture == "open_palm":
        return ev.still >= (SPEAKING_STILL_S if person.speaking else STOP_STILL_S) - 1e-9
    return held and ev.raised is True and not person.speaking


def _why(ev: GestureEvent, person: Person) -> str:
    if ev.gesture == "open_palm":
        held = f", held still {ev.still:.1f} s" if ev.still is not None else ""
        return f"open palm shown by the {ev.hand} hand (score {ev.score:.2f}{held}): stop at once"
    facing = ", facing the camera" if person.engaged else ""
    return f"{ev.hand} hand waving for {ev.end - ev.start:.1f} s (score {ev.score:.2f}{facing}): come here"


class Gestures:
    def __init__(self, min_score: float, episode_gap: float, horizon: float):
        self.min_score = min_score  # open_palm / wave events below this are ignored
        self.episode_gap = episode_gap  # s: events of one gesture this close belong to one episode
        self.horizon = horizon
        self.stops: collections.deque[tuple[float, float]] = collections.deque(maxlen=MEMORY)  # (start, given)
        self.waves: collections.deque[float] = collections.deque(maxlen=MEMORY)
        self.episodes: dict[tuple, Episode] = {}  # (key, hand, gesture) -> the episode going on

    def on_event(self, key: str, ev: GestureEvent, person: Person = Person()) -> GestureCommand | None:
        """The command a (buffered, not duplicate) gesture event gives: once per episode, at its first event that
        is deliberate (`deliberate`); `person`: what fusion knows of the person making it."""
        if ev.gesture not in COMMANDS or ev.score < self.min_score:
            return None
        episode = (key, ev.hand, ev.gesture)
        last = self.episodes.get(episode)
        new = (
            last is None or last.ended or ev.start > last.last + self.episode_gap or ev.stamp < last.last - self.horizon
        )
        given = last is not None and not new and last.given
        give = not given and deliberate(ev, person)
        self.episodes[episode] = Episode(
            max(ev.stamp, ev.end, last.last if last and not new else 0.0),
            ev.phase == "end",
            given or give,
            ev.person,
        )
        self._prune_episodes(ev.stamp)
        if not give:
            return None
        if ev.gesture == "wave" and self._other_hand_called(key, ev):
            return None  # both arms waved: one call (its episode counts as given, so it never calls later)
        if ev.gesture == "open_palm":
            self.stops.append((ev.start, ev.stamp))
            return GestureCommand("stop", True, _why(ev, person))
        self.waves.append(ev.start)
        return GestureCommand("come_here", False, _why(ev, person))

    def _other_hand_called(self, key: str, ev: GestureEvent) -> bool:
        """Has the same person's other hand on this camera already called with a wave that overlaps this one (or
        ended within `episode_gap` before it began)? A person waving both arms calls once."""
        return any(
            k == key
            and gesture == "wave"
            and hand != ev.hand
            and e.given
            and e.person == ev.person
            and e.last >= ev.start - self.episode_gap
            for (k, hand, gesture), e in self.episodes.items()
        )

    def _prune_episodes(self, stamp: float) -> None:
        if len(self.episodes) > MEMORY:
            for k in [k for k, e in self.episodes.items() if e.last < stamp - self.horizon]:
                del self.episodes[k]

    def stop_given(self, lo: float, hi: float) -> bool:
        """Was a deliberate stop shown during [lo, hi] (its command went out)?"""
        return any(start <= hi and lo <= given for start, given in self.stops)

    def palm_seen(self, gesture_items: Iterable[Any]) -> bool:
        """An open palm in `OPEN_PALM_FRAMES` or more of the hand frames among `gesture_items` (an utterance's
        window): counted, never a reason to drop what was said."""
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
