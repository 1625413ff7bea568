"""The marks of a gesture made *to* the robot, measured on one hand over source time (issue #40) — pure.

People talking move their hands: open-palm beats, sweeps, a hand raised while explaining. A stop shown to the robot
differs in three marks the hand stage can see, and a wave in one more the body stage can:
- **shape**: an open palm with the fingers up (wrist -> middle knuckle within `FINGERS_UP_DEG` of image-up), the
  palm turned to the camera (its width x 1.45 at least `FACE_ON` of its length; a palm seen edge-on, the usual
  beat, is narrow) and the thumb out, not folded across the palm (its tip `THUMB_OUT_PALMS` palm sizes from the
  middle knuckle: four fingers counted, HaGRID's "four", read 0.17-0.37, stop palms 0.82-1.11). An arm seen only
  by pose (`raised_hand`: above the shoulder, forearm up) has this shape;
- **still**: the palm's centre moves less than `STILL_SPEED` palm sizes per second, measured over at least
  `SPEED_BASELINE_S` of source time (not frame to frame: the figure does not depend on the frame rate or on which
  frames a paced stage processed);
- **held**: `still_for` = source time since the shaped, still palm was first at that place (0: not now). Fusion
  decides how long is enough (services/fusion/gestures.py); the gesture service only measures;
- **raised** (for a wave): the wrist at or above `RAISED_BELOW_SHOULDER` torso lengths below the shoulder, on the
  person's skeleton (None: no skeleton to judge by).
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field

import numpy as np

from services.gesture.body import ARMS, MIN_VISIBILITY, torso

FINGERS_UP_DEG = 45.0
FACE_ON = 0.55
THUMB_OUT_PALMS = 0.6  # the thumb's tip at least this far (x palm size) from the middle knuckle: not tucked in
STILL_SPEED = 1.0  # palm sizes per second
SPEED_BASELINE_S = 0.15  # s of source time the palm's displacement is measured over, at least...
SPEED_GAP_S = 0.5  # ...and at most (a hand missing longer than this starts afresh)
RAISED_BELOW_SHOULDER = 0.25  # torso lengths: a wrist no lower than this below the shoulder is raised
PALM_POINTS = (0, 5, 9, 13, 17)  # wrist and knuckles: the palm's centre, not the moving fingertips
THUMB_TIP, MIDDLE_MCP, INDEX_MCP, LITTLE_MCP = 4, 9, 5, 17
PALM_LENGTH_PER_WIDTH = 1.45


def palm_shaped(landmarks: np.ndarray) -> bool:
    """An open hand shown as a stop: fingers up and the palm turned to the camera (not edge-on)."""
    p = np.asarray(landmarks, dtype=float).reshape(21, 2)
    d = p[MIDDLE_MCP] - p[0]
    length = float(np.linalg.norm(d))
    if length <= 0:
        return False
    up = math.degrees(math.acos(max(-1.0, min(1.0, -d[1] / length))))  # image y grows downwards
    width = float(np.linalg.norm(p[LITTLE_MCP] - p[INDEX_MCP]))
    thumb = float(np.linalg.norm(p[THUMB_TIP] - p[MIDDLE_MCP])) / max(length, PALM_LENGTH_PER_WIDTH * width)
    return up <= FINGERS_UP_DEG and PALM_LENGTH_PER_WIDTH * width / length >= FACE_ON and thumb >= THUMB_OUT_PALMS


def palm_centre(landmarks: np.ndarray) -> np.ndarray:
    return np.asarray(landmarks, dtype=float).reshape(21, 2)[list(PALM_POINTS)].mean(axis=0)


def arm_raised(body: np.ndarray | None, side: str, wrist: np.ndarray) -> bool | None:
    """Is this wrist (px) raised on the person's skeleton: no lower than `RAISED_BELOW_SHOULDER` torso lengths below
    the shoulder? None when the skeleton cannot tell (none, or the shoulder unseen)."""
    if body is None:
        return None
    p = np.asarray(body, dtype=float).reshape(33, 3)
    s = ARMS[side][0]
    if p[s, 2] < MIN_VISIBILITY:
        return None
    shoulder, hip, _ = torso(p, side)
    length = float(np.linalg.norm(hip - shoulder)) or 1.0
    return bool(wrist[1] <= shoulder[1] + RAISED_BELOW_SHOULDER * length)


@dataclass
class _Sample:
    stamp: float
    centre: np.ndarray
    size: float
    shaped: bool


@dataclass
class HoldMeter:
    """One hand's recent positions: how long it has been held still in a stop's shape (`still_for`)."""

    samples: collections.deque = field(default_factory=lambda: collections.deque(maxlen=64))
    still_since: float | None = None

    def add(self, stamp: float, centre: np.ndarray, size: float, shaped: bool) -> None:
        b = self._baseline(stamp)
        size = max(size, 1.0)
        if not shaped or b is None or _speed(b, stamp, centre, size) > STILL_SPEED:
            self.still_since = None
        elif self.still_since is None:
            self.still_since = b.stamp  # the palm was already at this place then
        self.samples.append(_Sample(stamp, np.asarray(centre, dtype=float), size, shaped))

    def _baseline(self, stamp: float) -> _Sample | None:
        """The latest sample at least `SPEED_BASELINE_S` before `stamp`, if it is at most `SPEED_GAP_S` before."""
        for s in reversed(self.samples):
            if stamp - s.stamp >= SPEED_BASELINE_S - 1e-9:
                return s if stamp - s.stamp <= SPEED_GAP_S + 1e-9 else None
        return None

    def still_for(self, stamp: float) -> float:
        return 0.0 if self.still_since is None else max(0.0, stamp - self.still_since)


def _speed(b: _Sample, stamp: float, centre: np.ndarray, size: float) -> float:
    """Palm sizes per second from the baseline sample `b` to now."""
    return float(np.linalg.norm(np.asarray(centre) - b.centre)) / (stamp - b.stamp) / ((size + b.size) / 2)
