"""The full-body skeleton between two runs of MediaPipe Pose (issue #34; pure, no MediaPipe here).

Full pose is the gesture service's dearest stage (~21 ms of ~32 ms per frame on a 2-core machine), so it runs at
its own rate (`--pose-max-rate`); on the frames between, the last run's skeleton is carried: torso, head, shoulders
and elbows as they were, and each arm's hand end (wrist, index, pinky, thumb) moved with the hand the hands stage
tracks on this frame (hands run on every frame while one is in view). The hand that was on that arm at the pose
run is followed by how far its wrist moved since; an arm whose hand is not seen keeps its last place. The
skeleton's age (source time since the pose run) travels with it (`Body.pose_age_ms`): nothing carried is
presented as fresh.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from services.gesture.body import MIN_VISIBILITY, WRISTS, body_scale
from services.gesture.rules import WRIST as HAND_WRIST  # hand landmark 0
from services.gesture.temporal import Observation

HAND_END = {"left": (15, 17, 19, 21), "right": (16, 18, 20, 22)}  # pose wrist, pinky, index, thumb of each arm
ON_ARM = 0.5  # x body scale: a hand's wrist this near the pose's wrist is that arm's hand (a palm is 0.25-0.4)
MAX_STEP = 0.75  # x body scale: a hand's wrist that moved further since the pose run is not followed (another hand)


@dataclass(frozen=True)
class PoseRun:
    """What one pose run saw: the skeleton (33x3 px + visibility, or None), its world landmarks, the source stamp
    of its frame and, per arm side, the wrist of the hand on that arm (hand landmark 0, px) on that frame."""

    skeleton: np.ndarray | None
    world: np.ndarray | None
    stamp: float
    hand_wrists: dict[str, np.ndarray] = field(default_factory=dict)


def hands_on_arms(skeleton: np.ndarray, hands: list[Observation]) -> dict[str, np.ndarray]:
    """Per arm side, the wrist of the hand nearest the pose's wrist within `ON_ARM` body scales (the arm's visible
    wrist only); an arm with no hand there has none."""
    scale = body_scale(skeleton)
    out: dict[str, np.ndarray] = {}
    for side, w in WRISTS.items():
        if skeleton[w, 2] < MIN_VISIBILITY or not hands:
            continue
        wrists = [np.asarray(o.landmarks[HAND_WRIST], dtype=float) for o in hands]
        gaps = [float(np.linalg.norm(x - skeleton[w, :2])) for x in wrists]
        best = int(np.argmin(gaps))
        if gaps[best] <= ON_ARM * scale:
            out[side] = wrists[best]
    return out


def carried(run: PoseRun, hands: list[Observation]) -> np.ndarray | None:
    """The skeleton of `run` on a later frame with `hands`: each arm's hand end moved as far as its hand's wrist
    moved since the run (the nearest wrist on this frame within `MAX_STEP` body scales); the rest unchanged. A
    new array: the run's own stays as it was."""
    if run.skeleton is None:
        return None
    out = run.skeleton.copy()
    if not run.hand_wrists or not hands:
        return out
    scale = body_scale(run.skeleton)
    wrists = [np.asarray(o.landmarks[HAND_WRIST], dtype=float) for o in hands]
    for side, then in run.hand_wrists.items():
        steps = [x - then for x in wrists]
        best = min(steps, key=lambda s: float(np.linalg.norm(s)))
        if float(np.linalg.norm(best)) <= MAX_STEP * scale:
            out[list(HAND_END[side]), :2] += best
    return out
