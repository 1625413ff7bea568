"""Arm pointing and raised palms from MediaPipe Pose's 33 body landmarks — pure, ratios of distances only.

An arm **points** when it is extended away from the body: the elbow is straight (shoulder–elbow–wrist angle at
least `EXTENDED_DEG`, kept down to `RELEASE_DEG` once pointing: hysteresis) and the arm is raised away from the
torso line: the angle between shoulder → wrist and shoulder → hip (same side) at least `AWAY_DEG` (`RELEASE_AWAY_DEG`
to keep it). A relaxed arm hangs within about 25° of the torso line on the people photos, however straight. An arm whose
shoulder, elbow or wrist is not visible (MediaPipe visibility < `MIN_VISIBILITY`) cannot be judged: not pointing.

The **ray** goes from the eyes through the index fingertip when both eyes are inside the image and visible (the
eye, fingertip and target are on one line in 3-D, so their images are on one line too, whatever the depth), else
along the forearm (elbow → index fingertip). On the shared real pointing photos the eye line is the more accurate
(docs/gesture.md, `python benchmarks/gesture.py --rays`).

**With depth** (`joints3d`: the landmarks lifted to metres, `services/gesture/space.py` `lift_pose`) the same two
angles are taken in 3-D: an arm aimed at the camera is short and crooked in the image but straight and away from
the torso in 3-D. A segment whose lifted length is not an arm's (`UPPER_ARM_M`, `FOREARM_M`: a window that saw the
wall behind the wrist) is not trusted: the image decides.

**A hand held at the body is shown to nobody** (issue #31, `held_at_body`): hands at the chest or in the lap with
the elbow folded (< `FOLDED_DEG`, judged in 3-D, or in the image when both arm segments are plainly long there:
a foreshortened arm's image angle means nothing), and a wrist at a knee or on a thigh (seated, a hand on the
knee, the lap, or hanging along the leg) are neither a point nor a grasp; a pointing arm is neither. A hand lifted
on a folded arm (`held_up`: above the middle of the torso, the forearm rising) may still be shown on purpose: the
gesture tracker lets a clear point made so count (issue #40, temporal.py `deliberate_point`).

Pose landmarks are the person's own left/right (11/13/15/19 left shoulder/elbow/wrist/index), not mirrored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LEFT_EYE, RIGHT_EYE = 2, 5
ARMS = {"left": (11, 13, 15, 19, 23), "right": (12, 14, 16, 20, 24)}  # shoulder, elbow, wrist, index, hip
WRISTS = {side: joints[2] for side, joints in ARMS.items()}  # the pose wrist of each arm
MIDDLE_MCP = 9  # hand landmark

MIN_VISIBILITY = 0.5
EXTENDED_DEG = 150.0  # elbow at least this straight to start pointing...
RELEASE_DEG = 135.0  # ...and to keep pointing
# In 3-D the lifted points lie on the arm's front surface, a few cm off the joint centres: over a 25-30 cm segment
# 2-3 cm bend a straight arm's measured elbow by 5-10 deg, so the 3-D thresholds are 10 deg lower.
EXTENDED_3D_DEG, RELEASE_3D_DEG = 140.0, 125.0
AWAY_DEG = 35.0  # arm (shoulder -> wrist) away from the torso line (shoulder -> hip) to start...
RELEASE_AWAY_DEG = 25.0  # ...and to keep
TORSO_PER_SHOULDERS = 1.4  # torso length / shoulder width, when the hips are out of frame
FINGERS_UP_DEG = 60.0  # a raised palm: wrist -> middle knuckle within this of image-up
RAISED_ABOVE_SHOULDER = 0.3  # a raised hand (no hand seen): wrist this many body scales above its shoulder...
FOREARM_UP_DEG = 45.0  # ...and the forearm (elbow -> wrist) within this of image-up
THIGHS = ((23, 25), (24, 26))  # pose landmarks (hip, knee) of each leg
FOLDED_DEG = 110.0  # elbow angle below this: the hand is held at the body (every real point: >= 126 deg)
PLAIN_SEGMENT = 0.5  # x body scale: an arm segment at least this long in the image is not foreshortened
ON_KNEE = 0.6  # x shoulder width: a wrist this near a knee rests on it (seated: 0.43-0.45; points: >= 1.6)
ON_THIGH = 0.35  # x shoulder width: a wrist this near the hip -> knee segment lies on the thigh or the lap
ON_LEG_M = 0.12  # m: the same in 3-D (a hand is ~0.1 m thick, the lifted points are on the surfaces)
HEAD = tuple(range(11))  # pose landmarks of the face: nose, eyes, ears, mouth
FOREARM_RISE_DEG = 30.0  # elbow -> wrist at least this above the image's horizontal: the hand is lifted (issue #40;
# a forearm lying across the belly or in the lap is within ~15 deg of horizontal: none_00c84257 -3 deg)
UPPER_ARM_M = (0.12, 0.5)  # plausible lifted lengths, m (adults and children, with depth noise)
FOREARM_M = (0.1, 0.45)


@dataclass(frozen=True)
class Arm:
    side: str  # the person's own "left" / "right"
    pointing: bool
    visibility: float  # weakest of shoulder, elbow, wrist
    elbow_deg: float | None
    away_deg: float | None  # angle between shoulder -> wrist and shoulder -> hip
    wrist: tuple[float, float]
    forearm: float  # elbow -> wrist, px
    ray: tuple[tuple[float, float], tuple[float, float]] | None  # (origin = fingertip, unit direction)
    ray_from: str | None  # "eyes" or "forearm"
    confidence: float  # visibility x extension (steadiness is added over time)


def _angle(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Angle at b, degrees."""
    u, v = a - b, c - b
    nu, nv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
    if nu == 0 or nv == 0:
        return 0.0
    return math.degrees(math.acos(max(-1.0, min(1.0, float(u @ v) / (nu * nv)))))


def _unit(v: np.ndarray) -> tuple[float, float] | None:
    n = float(np.linalg.norm(v))
    return None if n < 1e-6 else (float(v[0] / n), float(v[1] / n))


def torso(p: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(shoulder, hip, torso length) of one side; the hip is estimated below the shoulder when out of sight."""
    s, _, _, _, hip = ARMS[side]
    shoulders = float(np.linalg.norm(p[11, :2] - p[12, :2]))
    if p[hip, 2] >= MIN_VISIBILITY:
        return p[s, :2], p[hip, :2], float(np.linalg.norm(p[hip, :2] - p[s, :2])) or 1.0
    length = TORSO_PER_SHOULDERS * shoulders or 1.0
    return p[s, :2], p[s, :2] + np.array([0.0, length]), length


def eyes_in_view(p: np.ndarray, width: int, height: int) -> np.ndarray | None:
    eyes = p[[LEFT_EYE, RIGHT_EYE]]
    if (eyes[:, 2] < MIN_VISIBILITY).any():
        return None
    if not ((0 <= eyes[:, 0]) & (eyes[:, 0] < width) & (0 <= eyes[:, 1]) & (eyes[:, 1] < height)).all():
        return None  # MediaPipe guesses a head out of frame with high "visibility": not a real eye
    return eyes[:, :2].mean(axis=0)


def arm(
    landmarks: np.ndarray | list,
    side: str,
    width: int,
    height: int,
    was_pointing: bool = False,
    ray_from: str = "eyes",
    joints3d: np.ndarray | None = None,
) -> Arm:
    """One arm of a 33x3 [x px, y px, visibility] skeleton. `was_pointing`: the hysteresis state of this arm.
    `joints3d`: the same landmarks in metres (33x3, NaN where unknown): the angles are then judged in 3-D."""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    s, e, w, i, _ = ARMS[side]
    vis = float(min(p[s, 2], p[e, 2], p[w, 2]))
    wrist = (float(p[w, 0]), float(p[w, 1]))
    forearm = float(np.linalg.norm(p[w, :2] - p[e, :2]))
    if vis < MIN_VISIBILITY:
        return Arm(side, False, vis, None, None, wrist, forearm, None, None, 0.0)
    elbow, away, in3d = arm_angles(p, side, joints3d)
    if in3d:
        min_deg, min_away = (RELEASE_3D_DEG, RELEASE_AWAY_DEG) if was_pointing else (EXTENDED_3D_DEG, AWAY_DEG)
    else:
        min_deg, min_away = (RELEASE_DEG, RELEASE_AWAY_DEG) if was_pointing else (EXTENDED_DEG, AWAY_DEG)
    pointing = elbow >= min_deg and away >= min_away and held_at_body(p, side, joints3d) is None
    ray, source = arm_ray(p, side, width, height, ray_from) if pointing else (None, None)
    pointing = pointing and ray is not None
    release = RELEASE_3D_DEG if in3d else RELEASE_DEG
    extension = max(0.0, min(1.0, (elbow - release) / (180.0 - release)))
    confidence = round(vis * (0.5 + 0.5 * extension), 4) if pointing else 0.0
    return Arm(side, pointing, vis, elbow, away, wrist, forearm, ray, source if pointing else None, confidence)


def arm3d(p: np.ndarray, side: str, joints3d: np.ndarray | None) -> np.ndarray | None:
    """Shoulder, elbow, wrist (3x3, m) of one arm when all three were lifted and both segments have an arm's length."""
    if joints3d is None:
        return None
    s, e, w, _, _ = ARMS[side]
    j = np.asarray(joints3d, dtype=float).reshape(33, 3)[[s, e, w]]
    if not np.isfinite(j).all():
        return None
    upper, fore = float(np.linalg.norm(j[1] - j[0])), float(np.linalg.norm(j[2] - j[1]))
    if not (UPPER_ARM_M[0] <= upper <= UPPER_ARM_M[1] and FOREARM_M[0] <= fore <= FOREARM_M[1]):
        return None  # a window saw the wall behind the wrist, or the chair under the elbow
    return j


def arm_angles(p: np.ndarray, side: str, joints3d: np.ndarray | None = None) -> tuple[float, float, bool]:
    """(elbow angle, angle between shoulder -> wrist and shoulder -> hip, in 3-D?), degrees: in 3-D when the arm
    and that side's hip were lifted, else in the image (the hip estimated below the shoulder when out of sight)."""
    s, e, w, _, hip = ARMS[side]
    j = arm3d(p, side, joints3d)
    if j is not None:
        hip3 = np.asarray(joints3d, dtype=float).reshape(33, 3)[hip]
        if p[hip, 2] >= MIN_VISIBILITY and np.isfinite(hip3).all():
            return _angle(j[0], j[1], j[2]), _angle(hip3, j[0], j[2]), True
    shoulder, hip2, _ = torso(p, side)
    return _angle(p[s, :2], p[e, :2], p[w, :2]), _angle(hip2, shoulder, p[w, :2]), False


def body_scale(p: np.ndarray) -> float:
    """The person's size in px: the shoulder width, or the torso length / 1.4 when that is larger (a person turned
    sideways has narrow shoulders in the image, not a short torso)."""
    shoulders = float(np.linalg.norm(p[11, :2] - p[12, :2]))
    torsos = [
        float(np.linalg.norm(p[hip, :2] - p[s, :2]))
        for s, hip in ((11, 23), (12, 24))
        if min(p[s, 2], p[hip, 2]) >= MIN_VISIBILITY
    ]
    return max([shoulders, *(t / TORSO_PER_SHOULDERS for t in torsos)]) or 1.0


def folded(p: np.ndarray, side: str, joints3d: np.ndarray | None = None) -> bool:
    """Is the elbow bent more than `FOLDED_DEG` (hands at the chest, in the lap with bent arms)? In 3-D when the arm
    was lifted; else in the image only when both segments are plainly long there (`PLAIN_SEGMENT` x the body's
    size): a foreshortened arm's image angle says nothing about its real one."""
    s, e, w, _, _ = ARMS[side]
    j = arm3d(p, side, joints3d)
    if j is not None:
        return _angle(j[0], j[1], j[2]) < FOLDED_DEG
    plain = PLAIN_SEGMENT * body_scale(p)
    segments = (float(np.linalg.norm(p[e, :2] - p[s, :2])), float(np.linalg.norm(p[w, :2] - p[e, :2])))
    return min(segments) >= plain and _angle(p[s, :2], p[e, :2], p[w, :2]) < FOLDED_DEG


def _segment_distance(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = float(np.clip((x - a) @ ab / (float(ab @ ab) or 1.0), 0.0, 1.0))
    return float(np.linalg.norm(x - (a + t * ab)))


def on_leg(p: np.ndarray, side: str, joints3d: np.ndarray | None = None) -> bool:
    """Does this wrist rest at a knee or on a thigh (either leg: a hand may lie on the other knee)? In 3-D (within
    `ON_LEG_M`) when the wrist and the leg were lifted, else in the image (`ON_KNEE`, `ON_THIGH` shoulder widths)."""
    w = ARMS[side][2]
    j = None if joints3d is None else np.asarray(joints3d, dtype=float).reshape(33, 3)
    shoulders = float(np.linalg.norm(p[11, :2] - p[12, :2])) or 1.0
    for hip, knee in THIGHS:
        if min(p[hip, 2], p[knee, 2]) < MIN_VISIBILITY:
            continue
        if j is not None and np.isfinite(j[[w, hip, knee]]).all():
            if _segment_distance(j[w], j[hip], j[knee]) <= ON_LEG_M:
                return True
            continue
        if float(np.linalg.norm(p[w, :2] - p[knee, :2])) <= ON_KNEE * shoulders:
            return True
        if _segment_distance(p[w, :2], p[hip, :2], p[knee, :2]) <= ON_THIGH * shoulders:
            return True
    return False


def held_at_body(landmarks: np.ndarray | list, side: str, joints3d: np.ndarray | None = None) -> str | None:
    """Why this arm's hand is held at the body rather than shown, or None: "folded" (the elbow bent: hands at the
    chest or in the lap), "on_leg" (the wrist at a knee or on a thigh). Needs the shoulder, elbow and wrist seen."""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    s, e, w, _, _ = ARMS[side]
    if min(p[s, 2], p[e, 2], p[w, 2]) < MIN_VISIBILITY:
        return None
    if folded(p, side, joints3d):
        return "folded"
    return "on_leg" if on_leg(p, side, joints3d) else None


def lowered(landmarks: np.ndarray | list, side: str, wrist: np.ndarray | tuple) -> bool:
    """Is this wrist (px) below the middle of the torso (halfway between shoulder and hip)? A shown hand (a raised
    palm, a fist held up as a grasp sign) is above it; a hand on a hip, a leg, an armrest or hanging is below."""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    shoulder, hip, _ = torso(p, side)
    return bool(wrist[1] >= (shoulder[1] + hip[1]) / 2)


def held_up(landmarks: np.ndarray | list, side: str, wrist: np.ndarray | tuple) -> bool:
    """Is this hand lifted in front of the body, as a hand is held up to show it (issue #40): the wrist (px) above
    the middle of the torso (not `lowered`) and the forearm (elbow -> wrist) rising at least `FOREARM_RISE_DEG` above
    the image's horizontal? A forearm folded across the belly, a hand in the lap or on a hip lies flat or hangs."""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    e = ARMS[side][1]
    rise = p[e, 1] - float(wrist[1])  # image y grows downwards
    run = abs(float(wrist[0]) - p[e, 0])
    return bool(not lowered(p, side, wrist) and math.degrees(math.atan2(rise, run)) >= FOREARM_RISE_DEG)


def arm_ray(
    landmarks: np.ndarray | list, side: str, width: int, height: int, ray_from: str = "eyes"
) -> tuple[tuple[tuple[float, float], tuple[float, float]] | None, str | None]:
    """((origin = index fingertip, or the wrist when the fingertip is unseen; unit direction), "eyes"/"forearm"):
    eyes -> fingertip when `ray_from` is "eyes" and both eyes are in view, else elbow -> fingertip."""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    _, e, w, i, _ = ARMS[side]
    tip = p[i, :2] if p[i, 2] >= MIN_VISIBILITY else p[w, :2]
    eyes = eyes_in_view(p, width, height) if ray_from == "eyes" else None
    direction = _unit(tip - eyes) if eyes is not None else None
    source = "eyes" if direction is not None else "forearm"
    direction = direction or _unit(tip - p[e, :2])
    if direction is None:
        return None, None
    return ((float(tip[0]), float(tip[1])), direction), source


def raised_palm(landmarks: np.ndarray | list, side: str, hand: np.ndarray | list) -> bool:
    """Is this open hand raised (a stop), not resting on a hip, a leg or a table? The wrist above the middle of
    the torso and the fingers up (wrist -> middle knuckle within 60° of image-up)."""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    q = np.asarray(hand, dtype=float).reshape(21, 2)
    up = _unit(q[MIDDLE_MCP] - q[0])
    if up is None:
        return False
    fingers_up = math.degrees(math.acos(max(-1.0, min(1.0, -up[1])))) <= FINGERS_UP_DEG
    return bool(not lowered(p, side, q[0]) and fingers_up)


def arm_judged(landmarks: np.ndarray | list, side: str) -> bool:
    """Are the shoulder and elbow of this arm seen well enough to say where the hand is on the body?"""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    s, e, _, _, _ = ARMS[side]
    return bool(p[s, 2] >= MIN_VISIBILITY and p[e, 2] >= MIN_VISIBILITY)


def raised_hand(landmarks: np.ndarray | list, side: str, scale: float) -> bool:
    """A hand raised above the shoulder with the forearm up (the 'stop' / 'attention' arm), judged on the body
    alone — for a person too far for the hand stage to see the hand (a 10 px hand at 4 m). The wrist at least
    `RAISED_ABOVE_SHOULDER` x `scale` (the person's size, px) above the shoulder: a hand at the ear ('call me',
    a phone) stays below that on the people photos (at most 0.15), a hand raised above the head is well above."""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)
    s, e, w, _, _ = ARMS[side]
    if min(p[s, 2], p[e, 2], p[w, 2]) < MIN_VISIBILITY:
        return False
    forearm = _unit(p[w, :2] - p[e, :2])
    if forearm is None:
        return False
    up = math.degrees(math.acos(max(-1.0, min(1.0, -forearm[1]))))
    return bool(p[s, 1] - p[w, 1] >= RAISED_ABOVE_SHOULDER * scale and up <= FOREARM_UP_DEG)


def at_head(landmarks: np.ndarray | list, point: np.ndarray | tuple, margin: float) -> bool:
    """Is this point (px, a hand's centre) at the person's head: inside the box of the face's seen landmarks (nose,
    eyes, ears, mouth) grown by `margin` px on every side (the chin and the cheeks lie beyond the landmarks)?"""
    p = np.asarray(landmarks, dtype=float).reshape(33, 3)[list(HEAD)]
    seen = p[p[:, 2] >= MIN_VISIBILITY, :2]
    if len(seen) < 3:
        return False
    low, high = seen.min(axis=0) - margin, seen.max(axis=0) + margin
    return bool((low <= np.asarray(point, dtype=float)).all() and (np.asarray(point, dtype=float) <= high).all())
