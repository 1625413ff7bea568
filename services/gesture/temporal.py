"""Gestures over time: per-hand tracks, hysteresis, wave detection, a steadied pointing ray — pure.

Feed `GestureTracker.update(stamp, observations[, body, size])` once per processed frame (stamps increasing);
with the body stage, `body` is the person's 33x3 pose landmarks (None: nobody seen) and each hand is first fused
with its arm (`fuse_arms`: the hand's class decides, the more reliable ray wins, an arm can point alone). It returns
each observation's track (with the steadied ray when the hand points) and the GestureEvents to publish:
- a gesture **starts** once the per-frame class has held for `start_frames` frames in a row, or (if
  `start_time` > 0) for `start_time` seconds over at least 2 frames, whichever comes first;
- it **holds** (an event at most every `hold_interval` s) while it lasts;
- it **ends** once the hand has shown something else, or been missing, for `end_frames` frames, or when
  `flush()` says the stream stopped (no frames come to show it is gone);
- **wave**: an open palm whose wrist moved side to side with at least `wave_reversals` direction changes,
  each swing at least `wave_amplitude` palm sizes, within the last `wave_window` seconds. A wave replaces the
  open palm it grew out of (the open palm ends, the wave starts). With the body stage, an arm lifted on the
  skeleton whose wrist swings side to side (deliberate.py `ArmSwing`) is a wave too, whatever the hand stage shows
  (a hand at room distance is too small and blurred to see), dated from the arm's lifting.
Hands are tracked by wrist position (nearest within `match_palms` palm sizes, same handedness first), so two
hands do not flicker into each other.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import cast

import numpy as np

from services.gesture.body import (
    MIN_VISIBILITY,
    Arm,
    arm,
    arm_judged,
    at_head,
    body_scale as _body_scale,
    held_at_body,
    held_up,
    lowered,
    raised_hand,
    raised_palm,
)
from services.gesture.deliberate import ArmSwing, HoldMeter, arm_raised, palm_centre, palm_shaped
from services.gesture.rules import classify, finger_states, palm_size, pointing_ray

HAND_RAY_MIN_PALM = 40.0  # px: a smaller hand's finger ray is less reliable than the arm's (a 30-50 px hand)
CLOSE_UP_PALM_PER_BODY = 0.75  # palm / body_scale at least this: a close-up hand, the skeleton is no reference
TOGETHER_PALMS = 1.5  # two wrists this near (x the larger palm) are hands held together: clasped, holding a thing
SAME_HAND_PALMS = 0.25  # mean landmark distance below this (x palm): one hand found twice, not two hands
AT_HEAD_PALMS = 1.0  # a hand's centre within this (x palm) of the face's landmarks' box: the hand is at the head


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
    source: str = "hand"  # "hand" (index finger) or "body" (arm)


@dataclass
class Cue:
    """One hand-or-arm in one frame, after fusing the hand stage with the body stage."""

    hand: str
    score: float
    wrist: np.ndarray
    size: float  # px: the palm size, or half the forearm for an arm seen only by pose
    raw: str | None  # this frame's gesture class
    ray: tuple | None  # (origin, direction) when pointing
    source: str  # "hand" / "body": where the ray comes from
    ray_confidence: float = 1.0  # the body ray's visibility x extension (1 for a hand ray)
    observation: int | None = None  # index of the hand observation, None for an arm seen only by pose
    arm: Arm | None = None


def body_scale(body: np.ndarray) -> float:
    """The person's size in px for comparing a hand with: the shoulder width, or the torso length / 1.4 when
    that is larger (a person turned sideways has narrow shoulders in the image, not a short torso)."""
    return _body_scale(np.asarray(body, dtype=float).reshape(33, 3))


def close_up(palm: float, body: np.ndarray | None) -> bool:
    """Is this hand much nearer the camera than the body (or the body a skeleton MediaPipe guessed around it)? A
    palm is about 0.25-0.4 shoulder widths on people at 1-3 m; at `CLOSE_UP_PALM_PER_BODY` or more the skeleton is no
    reference for where the hand is or what it does."""
    return body is not None and palm >= CLOSE_UP_PALM_PER_BODY * body_scale(body)


def clearly_seen(landmarks: np.ndarray, palm: float, hand_ray_min_palm: float = HAND_RAY_MIN_PALM) -> bool:
    """A hand large enough for its fingers to be read (palm >= `hand_ray_min_palm` px) with every finger clearly
    extended or curled: its own class decides, the body does not overrule it."""
    return palm >= hand_ray_min_palm and "unclear" not in finger_states(landmarks)


def body_may_point(landmarks: np.ndarray, palm: float, hand_ray_min_palm: float = HAND_RAY_MIN_PALM) -> bool:
    """May a pointing arm make this hand (no class of its own) a point? Only a hand the hand stage cannot read (small
    at room distance, or a finger unclear) and that shows no other finger than the index extended: a hand with the
    middle, ring or little finger out ("call me", peace/V, rock, an open hand) is not a pointing hand, whatever the
    arm does."""
    if clearly_seen(landmarks, palm, hand_ray_min_palm):
        return False
    return "extended" not in finger_states(landmarks)[1:]


def same_hand(a: Observation, b: Observation, palm: float) -> bool:
    """Are these one hand found twice: mean landmark distance below `SAME_HAND_PALMS` x `palm`?"""
    return float(np.mean(np.linalg.norm(a.landmarks - b.landmarks, axis=1))) < SAME_HAND_PALMS * palm


def hands_together(observations: list[Observation], palms: list[float]) -> set[int]:
    """Indices of hands held together with another (wrists within `TOGETHER_PALMS` palm sizes: clasped at the chest
    or in the lap, holding one thing): neither a point nor a grasp. One hand found twice is not two hands."""
    out = set()
    for a in range(len(observations)):
        for b in range(a + 1, len(observations)):
            palm = max(palms[a], palms[b], 1.0)
            la, lb = observations[a].landmarks, observations[b].landmarks
            if same_hand(observations[a], observations[b], palm):
                continue
            if float(np.linalg.norm(la[0] - lb[0])) <= TOGETHER_PALMS * palm:
                out |= {a, b}
    return out


def found_twice(observations: list[Observation], palms: list[float]) -> set[int]:
    """Indices of hands that repeat another hand of the frame (mean landmark distance below `SAME_HAND_PALMS` palm
    sizes): MediaPipe's video mode sometimes finds a tracked hand again beside itself. The repeat shows nothing, so
    one hand starts one gesture stream, not two; of the two copies the one the hand stage reads a class from is
    kept (the other is the blurred or half-found copy), else the first."""
    classes = [classify(o.landmarks) for o in observations]
    out = set()
    for b in range(len(observations)):
        for a in range(b):
            if a not in out and same_hand(observations[a], observations[b], max(palms[a], palms[b], 1.0)):
                out.add(a if classes[a] is None and classes[b] is not None else b)
    return out


def shown(
    raw: str | None,
    body: np.ndarray | None,
    side: str,
    wrist: np.ndarray,
    joints3d: np.ndarray | None,
    deliberate: bool = False,
) -> bool:
    """Is this point or fist shown to someone, not a hand held at the body? A point needs an arm that is neither
    folded nor resting on a leg (`held_at_body`) — or, on a folded arm, a `deliberate` point (`deliberate_point`:
    the robot's-eye point, a finger aimed at the camera from in front of the chest); a grasp sign (fist) also a hand
    held up, above the middle of the torso, like a stop. Other classes, or a body that cannot judge the arm, are not
    questioned here."""
    if raw not in ("point", "fist") or body is None or not arm_judged(body, side):
        return True
    held = held_at_body(body, side, joints3d)
    if held == "folded" and raw == "point" and deliberate:
        return True
    if held is not None:
        return False
    return raw == "point" or not lowered(body, side, wrist)


def clear_point(landmarks: np.ndarray, palm: float, hand_ray_min_palm: float = HAND_RAY_MIN_PALM) -> bool:
    """A point the hand stage reads beyond doubt: the `point` class on a hand large enough for its fingers to be
    read (palm >= `hand_ray_min_palm` px) with the middle, ring and little finger clearly curled. The index may be
    foreshortened (aimed at the camera: `rules.index_out`), so it is not asked to be clearly extended."""
    return (
        palm >= hand_ray_min_palm
        and classify(landmarks) == "point"
        and all(s == "curled" for s in finger_states(landmarks)[1:])
    )


def deliberate_point(
    hand: _HandSeen, body: np.ndarray, side: str, hand_ray_min_palm: float = HAND_RAY_MIN_PALM
) -> bool:
    """A point held up on purpose although the elbow is folded (issue #40: the robot's-eye point, the index aimed
    at the camera from in front of the chest, or raised beside the face): a `clear_point`, lifted (`held_up`: above
    the middle of the torso, the forearm rising), not held together with the other hand and not at a head (a finger
    on the lips, the temple, the chin). Hands folded at the belly, in the lap or on a knee are not lifted."""
    wrist = hand.obs.landmarks[0]
    return (
        not hand.together
        and not hand.at_head
        and clear_point(hand.obs.landmarks, hand.palm, hand_ray_min_palm)
        and held_up(body, side, wrist)
    )


def fuse_arms(
    observations: list[Observation],
    arms: list[Arm],
    body: np.ndarray | None,
    hand_ray_min_palm: float = HAND_RAY_MIN_PALM,
    joints3d: np.ndarray | None = None,
    others: Sequence[np.ndarray] = (),
) -> list[Cue]:
    """Hands and arms of one frame -> cues. A hand whose wrist is at the arm's wrist is that arm's hand. Its class
    decides (a fist on an extended arm is not pointing; an open palm never becomes a point); the arm adds only
    what the hand stage cannot see: a small or unclear hand with no other finger out on a pointing arm points
    (`body_may_point`), and a pointing arm without a hand still points. An open palm that is not raised is resting
    (no stop) — unless the hand is a close-up (`close_up`), where the skeleton is no reference. An arm whose hand
    is not seen at all and that is raised above the shoulder, forearm up (`raised_hand`), is a stop: safety first,
    at room distance the hand itself is a few pixels. A close-up hand in view also turns pose-only cues off
    (MediaPipe Pose then often guesses a skeleton around the hand). The more reliable ray wins: the finger's when
    the palm is at least `hand_ray_min_palm` px, else the arm's. Hands held at the body (issue #31: together,
    folded at the chest, on a knee, a fist hanging or on an armrest) are neither a point nor a grasp (`shown`).
    `others`: the skeletons (33x3) of the other persons in view (the person stage's). A hand matched to no arm of
    `body` is judged on its own person's arm when it lies at the wrist of one of theirs: the same resting rules
    (held at the body, a lowered fist, a resting palm), but no arm of theirs makes it a point. A fist at anyone's
    head (`at_head`: a phone, a "call me" sign, a hand scratching or eating) is not a grasp sign."""
    free = [a for a in arms if a.visibility >= MIN_VISIBILITY]  # an arm pose cannot see has no wrist to match
    palms = [palm_size(obs.landmarks) for obs in observations]
    together = hands_together(observations, palms)
    repeats = found_twice(observations, palms)
    bodies = [*([] if body is None else [body]), *others]
    cues = []
    for k, obs in enumerate(observations):
        if k in repeats:  # one hand found twice: the repeat shows nothing and takes no arm
            cues.append(Cue(obs.hand, obs.score, obs.landmarks[0].copy(), palms[k], None, None, "hand", observation=k))
            continue
        near = [a for a in free if _wrist_gap(a, obs) <= max(1.5 * palms[k], 0.5 * a.forearm)]
        match = min(near, key=lambda a: _wrist_gap(a, obs), default=None)
        if match is not None:
            free.remove(match)  # its hand is in view: no second, pose-only cue for the same arm
        hand = _HandSeen(k, obs, palms[k], k in together, _hand_at_head(obs, palms[k], bodies))
        if match is None:
            cues.append(_lone_hand_cue(hand, None, _own_arm(obs, palms[k], others)))
        elif close_up(palms[k], body):
            cues.append(_lone_hand_cue(hand, match))
        else:
            cues.append(_arm_hand_cue(hand, match, body, hand_ray_min_palm, joints3d))
    if not any(close_up(palm, body) for palm in palms):
        cues += _arm_only_cues(free, body)
    return cues


@dataclass(frozen=True)
class _HandSeen:
    index: int  # of the observation
    obs: Observation
    palm: float
    together: bool  # held together with another hand
    at_head: bool = False  # its centre at someone's head (`at_head`)

    def held(self, raw: str | None) -> bool:
        """Is this class, on this hand, a hand held rather than a sign: a point or fist held together with the other
        hand, or a fist at the head?"""
        return (self.together and raw in ("point", "fist")) or (self.at_head and raw == "fist")


@dataclass(frozen=True)
class _OwnArm:
    """The arm of another person (not the tracker's) that a hand lies at the wrist of."""

    body: np.ndarray  # that person's 33x3 skeleton
    arm: Arm


def _wrist_gap(a: Arm, obs: Observation) -> float:
    return float(np.hypot(*(np.array(a.wrist) - obs.landmarks[0])))


def _hand_at_head(obs: Observation, palm: float, bodies: list[np.ndarray]) -> bool:
    """Is this hand at the head of a person it is not a close-up beside (a skeleton guessed around a close-up hand
    puts a "head" anywhere)?"""
    centre = obs.landmarks.mean(axis=0)
    return any(at_head(b, centre, AT_HEAD_PALMS * palm) for b in bodies if not close_up(palm, b))


def _own_arm(obs: Observation, palm: float, others: Sequence[np.ndarray]) -> _OwnArm | None:
    """The arm of another person whose wrist this hand is at (the same match as the tracker's own arms), unless
    the hand is a close-up beside that skeleton."""
    best: tuple[float, _OwnArm] | None = None
    for b in others:
        if close_up(palm, b):
            continue
        for side in ("left", "right"):
            a = arm(b, side, 0, 0)  # (no size: the ray is not wanted, only where the arm is)
            gap = _wrist_gap(a, obs)
            if a.visibility >= MIN_VISIBILITY and gap <= max(1.5 * palm, 0.5 * a.forearm):
                if best is None or gap < best[0]:
                    best = (gap, _OwnArm(b, a))
    return best[1] if best else None


def _at_rest_on_own_arm(raw: str | None, hand: _HandSeen, own: _OwnArm) -> bool:
    """The resting rules of a hand on its own person's arm: held at the body (`shown`), or a palm not raised."""
    side, wrist = own.arm.side, hand.obs.landmarks[0]
    deliberate = raw == "point" and deliberate_point(hand, own.body, side)
    if not shown(raw, own.body, side, wrist, None, deliberate):
        return True
    return raw == "open_palm" and arm_judged(own.body, side) and not raised_palm(own.body, side, hand.obs.landmarks)


def _lone_hand_cue(hand: _HandSeen, match: Arm | None, own: _OwnArm | None = None) -> Cue:
    """A hand with no arm of the tracker's person, or a close-up one (the skeleton is no reference): the hand stage
    decides, but a hand at the wrist of another person's arm (`own`) keeps that person's resting rules."""
    raw = classify(hand.obs.landmarks)
    if hand.held(raw) or (own is not None and _at_rest_on_own_arm(raw, hand, own)):
        raw = None
    ray = pointing_ray(hand.obs.landmarks) if raw == "point" else None
    side = hand.obs.hand if match is None else match.side
    return Cue(side, hand.obs.score, hand.obs.landmarks[0].copy(), hand.palm, raw, ray, "hand", observation=hand.index)


def _arm_hand_cue(
    hand: _HandSeen, match: Arm, body: np.ndarray | None, hand_ray_min_palm: float, joints3d: np.ndarray | None
) -> Cue:
    """A hand on its arm: the hand's class decides; the arm makes a point of a hand it cannot read, tells a raised
    palm from a resting one, and tells a hand shown from one held at the body."""
    obs, palm = hand.obs, hand.palm
    raw = hand_class = classify(obs.landmarks)
    deliberate = raw == "point" and body is not None and deliberate_point(hand, body, match.side, hand_ray_min_palm)
    if hand.held(raw) or not shown(raw, body, match.side, obs.landmarks[0], joints3d, deliberate):
        raw = hand_class = None  # held at the body; and then no arm makes it a point either
    elif raw == "open_palm":
        # (an arm is judged only on a body: `body is not None` is said for the type checker)
        if body is not None and arm_judged(body, match.side) and not raised_palm(body, match.side, obs.landmarks):
            raw = None  # resting on a hip, a leg or a table; never a point
    elif raw is None and match.pointing and body_may_point(obs.landmarks, palm, hand_ray_min_palm):
        raw = "point"
    ray, source, conf = None, "hand", 1.0
    if raw == "point":
        if hand_class == "point" and (palm >= hand_ray_min_palm or match.ray is None):
            ray = pointing_ray(obs.landmarks)
        else:
            ray, source, conf = match.ray, "body", match.confidence
    return Cue(match.side, obs.score, obs.landmarks[0].copy(), palm, raw, ray, source, conf, hand.index, match)


def _arm_only_cues(free: list[Arm], body: np.ndarray | None) -> list[Cue]:
    """Arms whose hand is not seen: a pointing arm points; a hand raised at room distance, too small to be seen,
    is a stop."""
    cues = []
    for a in free:
        size = max(0.5 * a.forearm, 1.0)
        if a.pointing:
            cues.append(
                Cue(a.side, a.visibility, np.array(a.wrist), size, "point", a.ray, "body", a.confidence, None, a)
            )
        elif body is not None and raised_hand(body, a.side, body_scale(body)):
            cues.append(Cue(a.side, a.visibility, np.array(a.wrist), size, "open_palm", None, "body", 1.0, None, a))
    return cues


@dataclass
class Event:
    gesture: str
    phase: str  # start / hold / end
    start: float
    end: float
    score: float
    hand: str
    ray: Ray | None
    # the marks of a gesture made to the robot (services/gesture/deliberate.py), on open_palm and wave events
    still: float | None = None  # s the hand has been held still in a stop's shape
    raised: bool | None = None  # the wrist raised on the person's skeleton (None: no skeleton)


@dataclass
class TrackedHand:
    """What one observation became: its track, this frame's class and (if pointing) the steadied ray."""

    track_id: int
    gesture: str | None
    ray: Ray | None


MAX_WRIST_SPEED_PALMS = 60.0  # palm sizes per second of source time: ~6 m/s, faster than a waving hand moves


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
    wrist_x: deque = field(default_factory=lambda: deque(maxlen=90))  # (stamp, wrist x px, palm px)
    rays: deque = field(default_factory=lambda: deque(maxlen=5))  # (origin, direction)
    ray_source: str = "hand"
    hold: HoldMeter = field(default_factory=HoldMeter)
    raised: bool | None = None
    wave_since: float | None = None  # the start of the lifted arm's swing, when the body sees a wave


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
    hand_ray_min_palm: float = HAND_RAY_MIN_PALM
    ray_from: str = "eyes"  # body ray: "eyes" (eyes -> fingertip, forearm when the eyes are unseen) or "forearm"
    tracks: list[_Track] = field(default_factory=list)
    last_arms: list = field(default_factory=list)  # [(Arm, steadied Ray | None)] of the last frame's body
    _arm_pointing: dict = field(default_factory=dict)
    _swings: dict = field(default_factory=lambda: {"left": ArmSwing(), "right": ArmSwing()})  # side -> its path
    _next_id: int = 1

    def update(
        self,
        stamp: float,
        observations: list[Observation],
        body: np.ndarray | None = None,
        size: tuple[int, int] = (0, 0),
        joints3d: np.ndarray | None = None,
        others: Sequence[np.ndarray] = (),
    ) -> tuple[list[TrackedHand], list[Event]]:
        """One frame: the hands seen and, if the body stage runs, the person's 33x3 pose landmarks (None: no
        body seen) in an image of `size` (width, height); `joints3d`, with depth, the same landmarks in metres
        (33x3, NaN where unknown: space.lift_pose), so that arms are judged in 3-D. Hand and arm of one side
        become one cue (fuse_arms). `others`: the other persons' skeletons (the person stage's), whose hands keep the
        resting rules of their own arms."""
        arms = self._judge_arms(body, size, joints3d)
        for side, swing in self._swings.items():
            swing.add(stamp, body, side)
        cues = fuse_arms(observations, arms, body, self.hand_ray_min_palm, joints3d, others)
        cues += self._waving_arms(arms, cues)
        self.last_arms = [(a, None) for a in arms]
        events: list[Event] = []
        assigned = self._associate(cues)
        tracked: list[TrackedHand | None] = [None] * len(observations)
        seen_ids = set()
        for cue, track in zip(cues, assigned):
            seen_ids.add(track.id)
            # the track keeps the hand it was created with: one stream carries one `hand` from start to end
            track.wrist, track.palm, track.last_seen = cue.wrist, cue.size, stamp
            track.scores.append(cue.score)
            track.wrist_x.append((stamp, float(cue.wrist[0]), track.palm))
            raw, ray = cue.raw, None
            if raw == "point" and cue.ray is not None:
                if track.rays and track.ray_source != cue.source:
                    track.rays.clear()  # a hand ray and a body ray are not averaged together
                track.ray_source = cue.source
                track.rays.append(cue.ray)
                ray = self._steady_ray(track, cue.source, cue.ray_confidence)
            else:
                track.rays.clear()
            raw = self._body_wave(track, cue, self._wave_or(track, stamp, raw))
            self._measure(track, stamp, cue, observations, body)
            track.raised = True if track.wave_since is not None else track.raised  # lifted: at or out of the shoulder
            events += self._marked(track, stamp, self._step(track, stamp, raw, ray))
            if cue.observation is not None:
                tracked[cue.observation] = TrackedHand(track.id, raw, ray)
            if cue.arm is not None and ray is not None and ray.source == "body":
                self.last_arms = [(a, ray if a is cue.arm else r) for a, r in self.last_arms]
        for track in self.tracks:
            if track.id not in seen_ids:
                track.hold.miss(stamp)
                events += self._marked(track, stamp, self._step(track, stamp, None, None))
        self.tracks = [t for t in self.tracks if stamp - t.last_seen <= self.forget_after or t.active]
        return cast("list[TrackedHand]", tracked), events  # every observation made a cue (fuse_arms): no None

    def _judge_arms(
        self, body: np.ndarray | None, size: tuple[int, int], joints3d: np.ndarray | None = None
    ) -> list[Arm]:
        if body is None:
            self._arm_pointing = {}
            return []
        arms = [
            arm(body, side, size[0], size[1], self._arm_pointing.get(side, False), self.ray_from, joints3d)
            for side in ("left", "right")
        ]
        self._arm_pointing = {a.side: a.pointing for a in arms}
        return arms

    def _associate(self, cues: list[Cue]) -> list[_Track]:
        free = list(self.tracks)
        out = []
        for cue in cues:
            best, best_d = None, float("inf")
            reach = self._swing_reach(cue)
            for t in free:
                d = float(np.linalg.norm(t.wrist - cue.wrist)) / max(reach or cue.size, t.palm)
                d += 0.0 if t.hand == cue.hand else 0.5  # prefer the same hand, do not insist (labels flicker)
                d -= self.match_palms if reach and t.active == "wave" else 0.0  # a swinging arm goes on waving
                if d < best_d and d <= self.match_palms:
                    best, best_d = t, d
            if best is None:
                best = _Track(self._next_id, cue.hand, cue.wrist.copy(), cue.size, 0.0)
                self._next_id += 1
                self.tracks.append(best)
            else:
                free.remove(best)
            out.append(best)
        return out

    def _swing_reach(self, cue: Cue) -> float:
        """px: the body scale of the cue's arm while it swings (its wrist moves a body scale in a few frames, and
        is followed at that scale), else 0."""
        swing = self._swings[cue.arm.side] if cue.arm is not None else None
        return max(cue.size, swing.scale) if swing is not None and swing.waving() is not None else 0.0

    def _steady_ray(self, track: _Track, source: str = "hand", weight: float = 1.0) -> Ray:
        origins = np.array([o for o, _ in track.rays])
        dirs = np.array([d for _, d in track.rays])
        mean = dirs.mean(axis=0)
        resultant = float(np.linalg.norm(mean))  # 1 when every frame pointed the same way
        direction = mean / (resultant or 1.0)
        frames = len(track.rays) / self.ray_frames  # a ray seen for one frame is less sure than one held
        # steadiness only: consumers weigh the hand's own landmark score separately
        confidence = max(0.0, min(1.0, weight * resultant**8 * (0.5 + 0.5 * frames)))
        o = origins.mean(axis=0)
        return Ray((float(o[0]), float(o[1])), (float(direction[0]), float(direction[1])), round(confidence, 4), source)

    def _waving(self, track: _Track, stamp: float) -> bool:
        """Has this hand's wrist swung side to side (`wave_reversals` turns of `wave_amplitude` palms) within the
        last `wave_window` s, since its last jump (faster than a hand moves: another hand, a slide change)?

        Swings are measured in pixels and scaled by the window's median palm size: a position divided by each
        frame's own palm size moves whenever the size estimate jitters (a still hand 10 palms from the image edge
        whose size wavers by 10 % "swings" a palm; issue #40, a wave from a still photo)."""
        window: list[tuple[float, float]] = []  # (x px, palm px)
        last = None
        for t, x, palm in track.wrist_x:
            if last is not None and abs(x - last[1]) > MAX_WRIST_SPEED_PALMS * max(palm, last[2]) * max(
                t - last[0], 1e-3
            ):
                window = []  # not the same hand's motion: the swing starts afresh
            last = (t, x, palm)
            if stamp - t <= self.wave_window:
                window.append((x, palm))
        if len(window) < 4:
            return False
        swing = self.wave_amplitude * float(np.median([palm for _, palm in window]))
        xs = [x for x, _ in window]
        reversals, direction, extreme = 0, 0, xs[0]
        for x in xs[1:]:
            if direction >= 0 and x < extreme - swing:
                reversals += direction > 0
                direction, extreme = -1, x
            elif direction <= 0 and x > extreme + swing:
                reversals += direction < 0
                direction, extreme = 1, x
            elif (direction >= 0 and x > extreme) or (direction < 0 and x < extreme):
                extreme = x
        return reversals >= self.wave_reversals

    def _wave_or(self, track: _Track, stamp: float, raw: str | None) -> str | None:
        """This frame's class, or "wave": an open palm whose wrist swings side to side starts a wave; a wave goes on
        while the wrist keeps swinging, whatever the blurred hand shows on a frame (issue #40: a fast wave seen as
        a palm, nothing, a palm again made short waves and stops, never a wave long enough to call)."""
        if raw == "open_palm" or (track.active == "wave" and raw != "point"):
            return "wave" if self._waving(track, stamp) else raw
        return raw

    def _body_wave(self, track: _Track, cue: Cue, raw: str | None) -> str | None:
        """This frame's class, or "wave" when the cue's lifted arm swings (`_arm_waving`); the wave then dates from
        the swing's start (`track.wave_since`), so that its hold counts the whole swing."""
        track.wave_since = self._arm_waving(cue)
        return "wave" if track.wave_since is not None else raw

    def _arm_waving(self, cue: Cue) -> float | None:
        """Since when this cue's arm, lifted, has been swinging side to side (deliberate.py `ArmSwing`): a wave the
        skeleton sees when the hand stage barely does (issue #40); None: not swinging, or a point."""
        if cue.arm is None or (cue.raw == "point" and cue.source == "hand"):
            return None  # a point the hand shows is a point; an arm's point that sweeps is a wave
        return self._swings[cue.arm.side].waving()

    def _measure(
        self, track: _Track, stamp: float, cue: Cue, observations: list[Observation], body: np.ndarray | None
    ) -> None:
        """The marks of a deliberate gesture (deliberate.py) on this frame: the palm's hold, the arm raised."""
        if cue.observation is not None:
            landmarks = observations[cue.observation].landmarks
            centre, shaped = palm_centre(landmarks), cue.raw == "open_palm" and palm_shaped(landmarks)
        else:  # an arm seen by pose alone: raised above the shoulder, forearm up (`raised_hand`)
            centre, shaped = cue.wrist, cue.raw == "open_palm"
        track.hold.add(stamp, centre, cue.size, shaped)
        track.raised = arm_raised(body, cue.arm.side if cue.arm is not None else cue.hand, cue.wrist)

    def _marked(self, track: _Track, stamp: float, events: list[Event]) -> list[Event]:
        """The marks of a deliberate gesture on this track's stop and wave events."""
        for ev in events:
            if ev.gesture in ("open_palm", "wave"):  # an ended gesture is not held now
                ev.still = 0.0 if ev.phase == "end" else round(track.hold.still_for(stamp), 3)
                ev.raised = track.raised
        return events

    def _waving_arms(self, arms: list[Arm], cues: list[Cue]) -> list[Cue]:
        """An arm whose hand the hand stage lost, at the wrist of a hand that is waving: the arm goes on with the
        wave (a fast wave at room distance blurs the hand on most frames; issue #40), its wrist in the hand's place."""
        used = {id(c.arm) for c in cues if c.arm is not None}
        out = []
        for a in arms:
            if id(a) in used or a.visibility < MIN_VISIBILITY:
                continue
            wrist = np.array(a.wrist, dtype=float)
            near = [
                t
                for t in self.tracks
                if t.active == "wave" and float(np.linalg.norm(t.wrist - wrist)) <= self.match_palms * 2 * t.palm
            ]
            if near or self._swings[a.side].waving() is not None:  # the body sees a wave
                size = near[0].palm if near else max(0.5 * a.forearm, 1.0)
                out.append(Cue(a.side, a.visibility, wrist, size, None, None, "body", 1.0, None, a))
        return out

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
                    events.append(
                        Event(track.active, "end", track.active_start, track.active_last, score, track.hand, None)
                    )
                    track.active = None
        if track.active is None and raw is not None and (self._held(track, stamp) or raw == "wave"):
            start = track.run_start
            if raw == "wave" and track.wave_since is not None:  # a body wave dates from its swing's start
                start = min(start, track.wave_since)
            track.active, track.active_start, track.active_last = raw, start, stamp
            track.misses, track.last_emit = 0, stamp
            events.append(Event(raw, "start", start, stamp, score, track.hand, ray))
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
        events = [
            Event(
                t.active,
                "end",
                t.active_start,
                t.active_last,
                round(float(np.mean(t.scores)) if t.scores else 0.0, 4),
                t.hand,
                None,
                still=0.0 if t.active in ("open_palm", "wave") else None,
            )
            for t in self.tracks
            if t.active is not None
        ]
        self.tracks, self.last_arms, self._arm_pointing = [], [], {}
        self._swings = {"left": ArmSwing(), "right": ArmSwing()}
        return events


def angle_between(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Degrees between two unit vectors (for tests and diagnostics)."""
    return math.degrees(math.acos(max(-1.0, min(1.0, a[0] * b[0] + a[1] * b[1]))))
