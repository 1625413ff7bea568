"""Hands and bodies for the gesture tests: the real landmark arrays of tests/data/landmarks/real_hands.json (written
by testkit/record_landmarks.py) turned every way, a standing person's pose landmarks with arms placed by hand, and
the tracker run over frames."""

from __future__ import annotations

import json
import math

import numpy as np

from services.gesture.rules import palm_size
from services.gesture.temporal import Observation
from testkit.harness import ROOT

REAL = json.loads((ROOT / "tests" / "data" / "landmarks" / "real_hands.json").read_text())


def real(name: str) -> np.ndarray:
    return np.array(REAL[name]["landmarks"], dtype=float)


def rotate(p: np.ndarray, degrees: float, scale: float = 1.0, flip: bool = False) -> np.ndarray:
    q = p - p[0]
    if flip:
        q = q * [-1, 1]
    a = math.radians(degrees)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return q @ rot.T * scale + [500, 500]


def fold_index(p: np.ndarray) -> np.ndarray:
    """A fist from a real pointing hand: the index joints take the curled middle finger's shape."""
    q = p.copy()
    for j in (1, 2, 3):
        q[5 + j] = p[5] + (p[9 + j] - p[9])
    return q


W, H = 640, 480


def person(right_arm=None, left_arm=None, vis=1.0, eyes=True) -> np.ndarray:
    """A standing person facing the camera, 33x3 [x, y, visibility]; the person's right is on the image left.
    `right_arm` / `left_arm`: (elbow, wrist, index) pixels; default: hanging beside the body."""
    p = np.zeros((33, 3))
    p[:, 2] = vis
    p[0] = (320, 120, vis)
    p[2], p[5] = (310, 110, vis), (330, 110, vis)  # right eye on the image left
    p[11], p[12] = (360, 180, vis), (280, 180, vis)  # left shoulder on the image right
    p[23], p[24] = (350, 340, vis), (290, 340, vis)
    p[25], p[26] = (352, 420, vis), (288, 420, vis)  # knees (the legs go on below the frame)
    right_arm = right_arm or ((272, 250), (270, 320), (270, 340))
    left_arm = left_arm or ((368, 250), (370, 320), (370, 340))
    for (e, w, i), arm_ids in ((right_arm, (14, 16, 20)), (left_arm, (13, 15, 19))):
        for pt, k in zip((e, w, i), arm_ids):
            p[k] = (*pt, vis)
    if not eyes:
        p[[2, 5], 1] = -30  # the head is out of frame
    return p


RIGHT_OUT = ((210, 185), (140, 190), (115, 191))  # the person's right arm straight out to the image left


LEFT_OUT = ((430, 185), (500, 190), (525, 191))  # left arm straight out to the image right


RIGHT_BENT = ((250, 260), (300, 230), (310, 215))  # elbow bent, hand in front of the chest


def run(tracker, frames, t0=100.0, dt=1 / 30):
    events = []
    for i, (hands, body) in enumerate(frames):
        _, ev = tracker.update(t0 + i * dt, hands, body, (W, H))
        events += ev
    return events


def hand_at(p: np.ndarray, wrist, palm_px: float, hand="left") -> Observation:
    """A real hand moved to `wrist` and scaled so that its palm is about `palm_px` pixels."""
    q = (p - p[0]) * (palm_px / palm_size(p)) + wrist
    return Observation(hand, 0.9, q)


def starts(events):
    return [(e.gesture, e.hand, e.ray.source if e.ray else None) for e in events if e.phase == "start"]
