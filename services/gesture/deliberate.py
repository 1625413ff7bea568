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
  frames a paced stage processed, down to a frame every `UNWATCHED_GAP_S` on a loaded machine);
- **held**: `still_for` = source time since the shaped, still palm was first at that place (0: not now). Fusion
  decides how long is enough (services/fusion/gestures.py); the gesture service only measures;
- **raised** (for a wave): the wrist at or above `RAISED_BELOW_SHOULDER` torso lengths below the shoulder, on the
  person's skeleton (None: no skeleton to judge by);
- **an arm wave** (`ArmSwing`): the skeleton's arm lifted (at the shoulder, or held out sideways) and its wrist
  swinging side to side by a stated number of body scales over source time: a wave the hand stage barely sees.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field

import numpy as np

from services.gesture.body import ARMS, MIN_VISIBILITY, body_scale, torso

FINGERS_UP_DEG = 45.0
FACE_ON = 0.55
THUMB_OUT_PALMS = 0.6  # the thumb's tip at least this far (x palm size) from the middle knuckle: not tucked in
STILL_SPEED = 1.0  # palm sizes per second
SPEED_BASELINE_S = 0.15  # s of source time the palm's displacement is measured over, at least...
SPEED_GAP_S = 0.5  # ...and at most (a hand missing longer than this starts afresh)...
# ...unless no frame processed in between missed the hand: a stage behind on a loaded machine processes a frame a
# second, and a palm held up for seconds is held all the same (a stop must stop when the robot is busy).
UNWATCHED_GAP_S = 2.0
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
    missed: float = -math.inf  # the latest processed frame that did not see this hand

    def miss(self, stamp: float) -> None:
        """A processed frame without this hand (frames a paced stage skipped are not misses: nobody looked)."""
        self.missed = stamp

    def add(self, stamp: float, centre: np.ndarray, size: float, shaped: bool) -> None:
        b = self._baseline(stamp)
        size = max(size, 1.0)
        if not shaped or b is None or _speed(b, stamp, centre, size) > STILL_SPEED:
            self.still_since = None
        elif self.still_since is None:
            self.still_since = b.stamp  # the palm was already at this place then
        self.samples.append(_Sample(stamp, np.asarray(centre, dtype=float), size, shaped))

    def _baseline(self, stamp: float) -> _Sample | None:
        """The latest sample at least `SPEED_BASELINE_S` before `stamp`, if it is at most `SPEED_GAP_S` before, or
        `UNWATCHED_GAP_S` when no frame processed since missed the hand."""
        for s in reversed(self.samples):
            if stamp - s.stamp >= SPEED_BASELINE_S - 1e-9:
                gap = SPEED_GAP_S if self.missed > s.stamp else UNWATCHED_GAP_S
                return s if stamp - s.stamp <= gap + 1e-9 else None
        return None

    def still_for(self, stamp: float) -> float:
        return 0.0 if self.still_since is None else max(0.0, stamp - self.still_since)


def _speed(b: _Sample, stamp: float, centre: np.ndarray, size: float) -> float:
    """Palm sizes per second from the baseline sample `b` to now."""
    return float(np.linalg.norm(np.asarray(centre) - b.centre)) / (stamp - b.stamp) / ((size + b.size) / 2)


# A wave seen by the body alone (issue #40: at ~3 m the waving hand is ~15 px and blurred, MediaPipe Hands finds it
# on a few frames; Pose follows the arm throughout). Lengths in body scales (`body_scale`: the shoulder width).
HELD_OUT_SCALES = 1.0  # a wrist this far sideways from its shoulder, no lower than mid-torso, is held out
HELD_OUT_BELOW_SHOULDER = 0.5  # torso lengths
SWING_REVERSAL_SCALES = 0.5  # a turn of the wrist's sideways path counts past this much back
SWING_MIN_SCALES = 1.0  # a swing with a turn covers at least this much sideways...
SWEEP_MIN_SCALES = 2.0  # ...one without a turn (a sustained sweep) at least this much
SWING_WINDOW_S = 3.0  # s of source time the raised arm's path is looked at, at most
# One arm of one person: a wrist that moves faster than a human arm can (~6 m/s at a 0.4 m shoulder width), or a
# skeleton whose size changes by more than this factor, is another person or a skeleton that jumped (a slide
# change, two people's arms mixed): the swing starts afresh.
MAX_WRIST_SPEED_SCALES = 15.0  # body scales per second of source time
MAX_SCALE_CHANGE = 1.5


def arm_lifted(body: np.ndarray, side: str) -> bool:
    """Is this arm raised for a wave on the skeleton alone: the wrist at the shoulder (`arm_raised`) or held out
    sideways, away from the torso (`HELD_OUT_SCALES` from the shoulder, no lower than mid-torso)? False when the
    shoulder or wrist is not seen."""
    p = np.asarray(body, dtype=float).reshape(33, 3)
    s, _, w, _, _ = ARMS[side]
    if min(p[s, 2], p[w, 2]) < MIN_VISIBILITY:
        return False
    if arm_raised(p, side, p[w, :2]):
        return True
    shoulder, _, length = torso(p, side)
    out = abs(float(p[w, 0] - shoulder[0])) >= HELD_OUT_SCALES * body_scale(p)
    return out and bool(p[w, 1] <= shoulder[1] + HELD_OUT_BELOW_SHOULDER * length)


@dataclass
class ArmSwing:
    """One arm's sideways path while it is lifted (`arm_lifted`), over source time: `waving` is the source time the
    lifted arm has been swinging side to side (a turn after `SWING_MIN_SCALES`, or a sweep of `SWEEP_MIN_SCALES`),
    else None. The path is kept in px and judged at one scale (the largest body scale seen along it): dividing each
    frame's x by that frame's scale made a jittering skeleton on a still photo swing (issue #40)."""

    path: collections.deque = field(default_factory=lambda: collections.deque(maxlen=128))  # (stamp, x px, scale px)
    scale: float = 1.0  # px, the person's latest body scale

    def add(self, stamp: float, body: np.ndarray | None, side: str) -> None:
        p = None if body is None else np.asarray(body, dtype=float).reshape(33, 3)
        lifted = p is not None and arm_lifted(p, side)
        if not lifted or (self.path and stamp - self.path[-1][0] > SPEED_GAP_S):
            self.path.clear()  # lowered, unseen or lost a while: a new swing starts afresh
        if p is not None and lifted:
            self.scale = body_scale(p)
            x = float(p[ARMS[side][2], 0])
            if self.path and not _same_arm(self.path[-1], stamp, x, self.scale):
                self.path.clear()
            self.path.append((stamp, x, self.scale))
        while self.path and stamp - self.path[0][0] > SWING_WINDOW_S:
            self.path.popleft()

    def waving(self) -> float | None:
        """The stamp since which the lifted arm has been swinging (None: it is not)."""
        if len(self.path) < 2:
            return None
        scale = max(s for _, _, s in self.path)
        xs = [x / scale for _, x, _ in self.path]
        reach = max(xs) - min(xs)
        if reach >= SWEEP_MIN_SCALES or (reach >= SWING_MIN_SCALES and _turned(xs)):
            return float(self.path[0][0])
        return None


def _same_arm(last: tuple[float, float, float], stamp: float, x: float, scale: float) -> bool:
    """Can this wrist (x px, on a skeleton of `scale` px) be the same arm as the path's `last` sample: no faster than
    `MAX_WRIST_SPEED_SCALES`, the skeleton's size within `MAX_SCALE_CHANGE`?"""
    t, x0, s0 = last
    big, small = max(scale, s0), max(min(scale, s0), 1e-6)
    speed = abs(x - x0) / big / max(stamp - t, 1e-3)
    return big / small <= MAX_SCALE_CHANGE and speed <= MAX_WRIST_SPEED_SCALES


def _turned(xs: list[float]) -> bool:
    """Did the path go `SWING_REVERSAL_SCALES` one way, then as far back?"""
    direction, extreme = 0.0, xs[0]
    for x in xs[1:]:
        if direction == 0.0:
            if abs(x - xs[0]) >= SWING_REVERSAL_SCALES:
                direction, extreme = math.copysign(1.0, x - xs[0]), x
        elif (x - extreme) * direction > 0:
            extreme = x
        elif abs(x - extreme) >= SWING_REVERSAL_SCALES:
            return True
    return False
