"""Gestures over time: per-hand tracks, hysteresis, wave detection, a steadied pointing ray — pure.

Feed `GestureTracker.update(stamp, observations)` once per processed frame (stamps increasing). It returns
each observation's track (with the steadied ray when the hand points) and the GestureEvents to publish:
- a gesture **starts** once the per-frame class has held for `start_frames` frames in a row, or (if
  `start_time` > 0) for `start_time` seconds over at least 2 frames, whichever comes first;
- it **holds** (an event at most every `hold_interval` s) while it lasts;
- it **ends** once the hand has shown something else, or been missing, for `end_frames` frames, or when
  `flush()` says the stream stopped (no frames come to show it is gone);
- **wave**: an open palm whose wrist moved side to side with at least `wave_reversals` direction changes,
  each swing at least `wave_amplitude` palm sizes, within the last `wave_window` seconds. A wave replaces the
  open palm it grew out of (the open palm ends, the wave starts).
Hands are tracked by wrist position (nearest within `match_palms` palm sizes, same handedness first), so two
hands do not flicker into each other.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from services.gesture.rules import classify, palm_size, pointing_ray


@dataclass
class Observation:
    """One hand in one frame."""
    hand: str  # "left" / "right"
    score: float
    landmarks: np.ndarray  # 21×2 px


@dataclass
class Ray:
    origin: tuple[float, float]
    direction: tuple[float, float]
    confidence: float


@dataclass
class Event:
    gesture: str
    phase: str  # start / hold / end
    start: float
    end: float
    score: float
    hand: str
    ray: Ray | None


@dataclass
class TrackedHand:
    """What one observation became: its track, this frame's class and (if pointing) the steadied ray."""
    track_id: int
    gesture: str | None
    ray: Ray | None


@dataclass
class _Track:
    id: int
    hand: str
    wrist: np.ndarray
    palm: float
    last_seen: float
    run_class: str | None = None
    run_len: int = 0
    run_start: float = 0.0
    active: str | None = None
    active_start: float = 0.0
    active_last: float = 0.0
    last_emit: float = 0.0
    misses: int = 0
    scores: deque = field(default_factory=lambda: deque(maxlen=15))
    wrist_x: deque = field(default_factory=lambda: deque(maxlen=90))  # (stamp, x / palm)
    rays: deque = field(default_factory=lambda: deque(maxlen=5))  # (origin, direction)


@dataclass
class GestureTracker:
    start_frames: int = 3
    end_frames: int = 3
    start_time: float = 0.0  # s; 0: frames only
    hold_interval: float = 0.1
    wave_window: float = 1.5
    wave_reversals: int = 2
    wave_amplitude: float = 0.3
    match_palms: float = 1.5
    forget_after: float = 2.0
    ray_frames: int = 5
    tracks: list[_Track] = field(default_factory=list)
    _next_id: int = 1

    def update(self, stamp: float, observations: list[Observation]) -> tuple[list[TrackedHand], list[Event]]:
        events: list[Event] = []
        assigned = self._associate(observations)
        tracked: list[TrackedHand] = []
        seen_ids = set()
        for obs, track in zip(observations, assigned):
            seen_ids.add(track.id)
            track.wrist, track.palm, track.last_seen = obs.landmarks[0].copy(), palm_size(obs.landmarks), stamp
            track.scores.append(obs.score)
            track.wrist_x.append((stamp, float(obs.landmarks[0, 0]) / track.palm))
            raw = classify(obs.landmarks)
            ray = None
            if raw == "point":
                track.rays.append(pointing_ray(obs.landmarks))
                ray = self._steady_ray(track)
            else:
                track.rays.clear()
            if raw == "open_palm" and self._waving(track, stamp):
                raw = "wave"
            events += self._step(track, stamp, raw, ray)
            tracked.append(TrackedHand(track.id, "wave" if raw == "wave" else raw, ray))
        for track in self.tracks:
            if track.id not in seen_ids:
                events += self._step(track, stamp, None, None)
        self.tracks = [t for t in self.tracks if stamp - t.last_seen <= self.forget_after or t.active]
        return tracked, events

    def _associate(self, observations: list[Observation]) -> list[_Track]:
        free = list(self.tracks)
        out = []
        for obs in observations:
            palm = palm_size(obs.landmarks)
            best, best_d = None, float("inf")
            for t in free:
                d = float(np.linalg.norm(t.wrist - obs.landmarks[0])) / max(palm, t.palm)
                d += 0.0 if t.hand == obs.hand else 0.5  # prefer the same hand, do not insist (labels flicker)
                if d < best_d and d <= self.match_palms:
                    best, best_d = t, d
            if best is None:
                best = _Track(self._next_id, obs.hand, obs.landmarks[0].copy(), palm, 0.0)
                self._next_id += 1
                self.tracks.append(best)
            else:
                free.remove(best)
            out.append(best)
        return out

    def _steady_ray(self, track: _Track) -> Ray:
        origins = np.array([o for o, _ in track.rays])
        dirs = np.array([d for _, d in track.rays])
        mean = dirs.mean(axis=0)
        resultant = float(np.linalg.norm(mean))  # 1 when every frame pointed the same way
        direction = mean / (resultant or 1.0)
        frames = len(track.rays) / self.ray_frames  # a ray seen for one frame is less sure than one held
        # steadiness only: consumers weigh the hand's own landmark score separately
        confidence = max(0.0, min(1.0, resultant ** 8 * (0.5 + 0.5 * frames)))
        o = origins.mean(axis=0)
        return Ray((float(o[0]), float(o[1])), (float(direction[0]), float(direction[1])), round(confidence, 4))

    def _waving(self, track: _Track, stamp: float) -> bool:
        xs = [x for t, x in track.wrist_x if stamp - t <= self.wave_window]
        if len(xs) < 4:
            return False
        reversals, direction, extreme = 0, 0, xs[0]
        for x in xs[1:]:
            if direction >= 0 and x < extreme - self.wave_amplitude:
                reversals += direction > 0
                direction, extreme = -1, x
            elif direction <= 0 and x > extreme + self.wave_amplitude:
                reversals += direction < 0
                direction, extreme = 1, x
            elif (direction >= 0 and x > extreme) or (direction < 0 and x < extreme):
                extreme = x
        return reversals >= self.wave_reversals

    def _step(self, track: _Track, stamp: float, raw: str | None, ray: Ray | None) -> list[Event]:
        events = []
        score = round(float(np.mean(track.scores)) if track.scores else 0.0, 4)
        if raw == track.run_class:
            track.run_len += 1
        else:
            track.run_class, track.run_len, track.run_start = raw, 1, stamp
        if track.active is not None:
            if raw == track.active:
                track.misses, track.active_last = 0, stamp
                if stamp - track.last_emit >= self.hold_interval - 1e-9:
                    events.append(Event(track.active, "hold", track.active_start, stamp, score, track.hand, ray))
                    track.last_emit = stamp
            else:
                track.misses += 1
                replaced = raw == "wave" and track.active == "open_palm"
                if track.misses >= self.end_frames or replaced:
                    events.append(Event(track.active, "end", track.active_start, track.active_last, score,
                                        track.hand, None))
                    track.active = None
        if track.active is None and raw is not None and (self._held(track, stamp) or raw == "wave"):
            track.active, track.active_start, track.active_last = raw, track.run_start, stamp
            track.misses, track.last_emit = 0, stamp
            events.append(Event(raw, "start", track.run_start, stamp, score, track.hand, ray))
        return events


    def _held(self, track: _Track, stamp: float) -> bool:
        """Has the current per-frame class lasted long enough to start? Never on a single frame."""
        if track.run_len >= self.start_frames:
            return True
        return self.start_time > 0 and track.run_len >= 2 and stamp - track.run_start >= self.start_time - 1e-9

    def active(self) -> list[str]:
        """The gestures going on now, one per hand that shows one."""
        return [t.active for t in self.tracks if t.active is not None]

    def flush(self) -> list[Event]:
        """End every gesture going on and forget all hands: the stream stopped, so nothing will end them."""
        events = [Event(t.active, "end", t.active_start, t.active_last,
                        round(float(np.mean(t.scores)) if t.scores else 0.0, 4), t.hand, None)
                  for t in self.tracks if t.active is not None]
        self.tracks = []
        return events


def angle_between(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Degrees between two unit vectors (for tests and diagnostics)."""
    return math.degrees(math.acos(max(-1.0, min(1.0, a[0] * b[0] + a[1] * b[1]))))
