"""Engagement with the robot (issue #40), in the spirit of ROS4HRI `hri_engagement` (Webb & Lemaignan, "Measuring
Visual Social Engagement from Proxemics and Gaze"): a person is engaged when they and the robot face each other
within reach, judged over a window of frames, and reported as REP-155's levels. Pure: wire `Faces` (and `Persons`
for depth) in; used by the gesture service (`Person.engagement`) and by fusion (was an utterance said to the
robot?). One question for everyone: `engaged_over(faces, person, t0, t1)` (in the gesture service, from the frames
its tracker judged: `EngagementTracker.engaged_between(person, t0, t1)`, the same rule).

Each frame of a person's face (`frame_engaged`) counts as engaged when all three hold:
- **the person faces the robot**: the head's angle off the line to the camera, combining yaw and pitch
  (`acos(cos yaw cos pitch)`), is at most `engage_head_angle` (20 deg). Face Mesh's angles are relative to the
  camera's view of the face (it fits the face in a crop), so an off-centre person looking at the lens reads near 0;
  and they read short of the truth for turned heads (a head labelled turned ~40 deg reads 30, a three-quarter view
  39: ../shared/data/people_multi), so 20 read is about 27 real: beyond that the eyes alone would have to make up
  the rest to look at the robot.
- **the robot faces the person**: the face is within the robot's field of attention, half of `engage_field`
  (60 deg, hri_engagement's field) off the camera's axis, from the face centre's pixel offset and the focal length
  (the camera's intrinsics when known, else the `engage_camera_fov` assumed).
- **within reach**: the distance is at most `engage_max_distance` (4 m, hri_engagement's): the person's `position`
  (depth) when a `Persons` sample near in time has it, else from the face's size: `focal * engage_face_height /
  face height px` (a face outline, forehead to chin, of 0.19 m: an adult's, give or take 15 %; so the estimate is
  good to about a fifth, plus the error of an assumed field of view).
hri_engagement multiplies the two gaze terms and a log-distance factor against one threshold; that product drops
a frontal face below its threshold beyond ~2.6 m, and a robot should still hear a person facing it from 3 m: here
distance is a gate, not a factor, and each gaze term has its own bound.

Over a window (`engaged_over`): the share of the person's frames engaged, and the share in its last `engage_end`
seconds; engaged when both reach `engage_share`. Head orientation over the utterance *and at its end*: a speaker
who turns to the robot to finish a request is speaking to it; one who turned away from it as they spoke is not.

The REP-155 level (`EngagementTracker`, for `Person.engagement`) follows hri_engagement's state machine over the
last `window` seconds of frames, each +1 engaged / -1 not: from UNKNOWN to DISENGAGED once half a window is seen;
DISENGAGED -> ENGAGING above a mean of -0.4; ENGAGING -> ENGAGED above 0.5 (-> DISENGAGED below -0.6); ENGAGED ->
DISENGAGING below 0.4; DISENGAGING -> ENGAGED above 0.6, -> DISENGAGED below -0.5.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Iterable, Sequence

from common.schema import EngagementLevel, Face, Faces, Persons
from common.settings import setting


@dataclass(frozen=True)
class EngagementConfig:
    """Engagement's settings (docs/people.md "Engagement"); flags of `hri-fusion`."""

    engage_head_angle: float = setting(
        20.0,
        "a head turned at most this many degrees off the line to the camera (yaw and pitch together, as Face Mesh "
        "reads them) faces the robot",
        above=0,
        at_most=90,
        metavar="DEG",
    )
    engage_field: float = setting(
        60.0,
        "the robot's field of attention (degrees, full width): a face farther off the camera's axis than half of it "
        "is not engaged",
        above=0,
        at_most=180,
        metavar="DEG",
    )
    engage_max_distance: float = setting(
        4.0, "a person farther than this (metres) is not engaged", above=0, metavar="M"
    )
    engage_camera_fov: float = setting(
        60.0,
        "horizontal field of view assumed for a camera whose intrinsics are not known (degrees)",
        above=0,
        below=180,
        metavar="DEG",
    )
    engage_face_height: float = setting(
        0.19,
        "height of a face's outline, forehead to chin (metres), assumed to tell its distance without depth",
        above=0,
        metavar="M",
    )
    engage_share: float = setting(
        0.5,
        "share of a person's frames engaged, over the utterance and over its end, for them to be engaged in it",
        above=0,
        at_most=1,
        metavar="P",
    )
    engage_end: float = setting(
        0.5, "seconds at the end of an utterance judged on their own ('and at its end')", above=0, metavar="S"
    )


@dataclass(frozen=True)
class FrameEngagement:
    """One frame of one face: the three conditions and the verdict (None: the head's angles are not known)."""

    head_angle: float | None  # degrees off the line to the camera
    off_axis: float  # degrees of the face centre off the camera's axis
    distance: float  # metres
    from_depth: bool  # the distance is the person's position (depth), not the face's size
    engaged: bool | None


def focal_px(width: int, cfg: EngagementConfig, fx: float | None = None) -> float:
    """The focal length in pixels: the camera's when known, else from the assumed horizontal field of view."""
    return fx if fx is not None and fx > 0 else (width / 2.0) / math.tan(math.radians(cfg.engage_camera_fov / 2.0))


def head_angle(yaw: float | None, pitch: float | None) -> float | None:
    """The head's angle off the line to the camera, yaw and pitch together (degrees)."""
    if yaw is None or pitch is None:
        return None
    c = math.cos(math.radians(yaw)) * math.cos(math.radians(pitch))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def frame_engaged(
    face: Face,
    width: int,
    height: int,
    cfg: EngagementConfig,
    distance: float | None = None,
    fx: float | None = None,
) -> FrameEngagement:
    """Whether this face, in a frame of `width` x `height` px, is engaged with the robot; `distance`: the person's
    distance from depth (metres) when known."""
    f = focal_px(width, cfg, fx)
    x, y, w, h = face.bbox
    dx, dy = x + w / 2.0 - width / 2.0, y + h / 2.0 - height / 2.0
    off_axis = math.degrees(math.atan(math.hypot(dx, dy) / f))
    from_depth = distance is not None
    if distance is None:
        distance = f * cfg.engage_face_height / max(h, 1.0)
    angle = head_angle(face.yaw, face.pitch)
    verdict = None
    if angle is not None:
        verdict = (
            angle <= cfg.engage_head_angle
            and off_axis <= cfg.engage_field / 2.0
            and distance <= cfg.engage_max_distance
        )
    return FrameEngagement(angle, off_axis, distance, from_depth, verdict)


@dataclass(frozen=True)
class Engagement:
    """A person's engagement over a window: engaged (None: not known), and the figures it rests on."""

    engaged: bool | None
    share: float | None  # share of the window's frames engaged
    share_at_end: float | None  # share of the frames in its last `engage_end` s engaged
    frames: int  # frames of the person's face with known head angles
    distance: float | None  # median distance, metres
    reason: str


def _is_person(face: Face, person: str) -> bool:
    return face.person == person or face.id == person


def _depth_distance(persons: Sequence[Persons], person: str, stamp: float, cam: str) -> float | None:
    """The person's distance from depth in the `Persons` sample of the camera nearest in time (within 0.5 s)."""
    near = [s for s in persons if s.cam == cam and abs(s.stamp - stamp) <= 0.5]
    if not near:
        return None
    sample = min(near, key=lambda s: abs(s.stamp - stamp))
    for p in sample.persons:
        if p.id == person and p.position is not None:
            return math.sqrt(sum(v * v for v in p.position))
    return None


def person_frames(
    faces: Iterable[Faces],
    person: str,
    t0: float,
    t1: float,
    cfg: EngagementConfig,
    persons: Sequence[Persons] = (),
) -> list[tuple[float, FrameEngagement]]:
    """(stamp, judgement) of each frame in [t0, t1] showing the person's face (`Face.person`, or the face id)."""
    out = []
    for sample in sorted(faces, key=lambda s: s.stamp):
        if not t0 <= sample.stamp <= t1:
            continue
        for face in sample.faces:
            if _is_person(face, person):
                depth = _depth_distance(persons, person, sample.stamp, sample.cam) if persons else None
                out.append((sample.stamp, frame_engaged(face, sample.width, sample.height, cfg, depth)))
                break
    return out


def window_verdict(marks: Sequence[tuple[float, bool]], t1: float, cfg: EngagementConfig) -> tuple[bool, float, float]:
    """The window rule on (stamp, engaged) frames ending at `t1`: (engaged, share, share in the last `engage_end` s).
    The end falls back on the last frame when none is that recent. `marks` must not be empty."""
    share = sum(e for _, e in marks) / len(marks)
    end = [e for s, e in marks if s >= t1 - cfg.engage_end] or [marks[-1][1]]
    at_end = sum(end) / len(end)
    return share >= cfg.engage_share and at_end >= cfg.engage_share, share, at_end


def engaged_over(
    faces: Iterable[Faces],
    person: str,
    t0: float,
    t1: float,
    cfg: EngagementConfig | None = None,
    persons: Sequence[Persons] = (),
) -> Engagement:
    """Was `person` (a person id, or a face id without a person tracker) engaged with the robot over [t0, t1]: their
    face's frames engaged for at least `engage_share` of the window and of its last `engage_end` seconds. `persons`:
    `Persons` samples whose `position` (depth) gives the distance."""
    cfg = cfg or EngagementConfig()
    near = [s for s in persons if t0 - 0.5 <= s.stamp <= t1 + 0.5]  # the ones a frame of the window may use
    frames = [(s, j) for s, j in person_frames(faces, person, t0, t1, cfg, near) if j.engaged is not None]
    if not frames:
        return Engagement(None, None, None, 0, None, f"no frame shows {person}'s head orientation")
    engaged, share, at_end = window_verdict([(s, bool(j.engaged)) for s, j in frames], t1, cfg)
    judged = [j for _, j in frames]
    distance = sorted(j.distance for j in judged)[len(judged) // 2]
    angles = sorted(j.head_angle for j in judged if j.head_angle is not None)
    how = "depth" if any(j.from_depth for j in judged) else "face size"
    reason = (
        f"engaged in {share:.0%} of {len(judged)} frames, {at_end:.0%} at the end; head {angles[len(angles) // 2]:.0f}"
        f" deg off the camera (median), {distance:.1f} m ({how})"
    )
    return Engagement(engaged, round(share, 3), round(at_end, 3), len(judged), round(distance, 2), reason)


_Step = tuple[float, EngagementLevel] | None
# hri_engagement's transitions: level -> ((below, to), (above, to)) on the mean of the +1/-1 history
_TRANSITIONS: dict[EngagementLevel, tuple[_Step, _Step]] = {
    "disengaged": (None, (-0.4, "engaging")),
    "engaging": ((-0.6, "disengaged"), (0.5, "engaged")),
    "engaged": ((0.4, "disengaging"), None),
    "disengaging": ((-0.5, "disengaged"), (0.6, "engaged")),
}


def next_level(level: EngagementLevel, mean: float) -> EngagementLevel:
    """REP-155's level after `level` given the mean of the engagement history (+1 engaged, -1 not)."""
    if level == "unknown":
        return "disengaged"
    down, up = _TRANSITIONS[level]
    if down is not None and mean < down[0]:
        return down[1]
    if up is not None and mean > up[0]:
        return up[1]
    return level


@dataclass
class _History:
    level: EngagementLevel = "unknown"
    marks: deque[tuple[float, int]] = field(default_factory=deque)  # (stamp, +1 / -1)
    first: float | None = None


@dataclass
class EngagementTracker:
    """REP-155 engagement levels of the persons of one camera, from the frames of their faces (hri_engagement's
    history and state machine over `window` seconds). Feed `update(faces)` in stamp order; `level(person)`."""

    cfg: EngagementConfig = field(default_factory=EngagementConfig)
    window: float = 2.0
    forget: float = 2.0  # a person not seen this long starts over (unknown)
    people: dict[str, _History] = field(default_factory=dict)

    def update(self, sample: Faces, persons: Persons | None = None) -> None:
        for face in sample.faces:
            who = face.person or face.id
            depth = _depth_distance([persons], who, sample.stamp, sample.cam) if persons is not None else None
            verdict = frame_engaged(face, sample.width, sample.height, self.cfg, depth).engaged
            if verdict is None:
                continue
            hist = self.people.setdefault(who, _History())
            if hist.marks and sample.stamp < hist.marks[-1][0]:  # the stream went back: start over
                hist = self.people[who] = _History()
            if hist.marks and sample.stamp - hist.marks[-1][0] > self.forget:
                hist = self.people[who] = _History()
            hist.first = sample.stamp if hist.first is None else hist.first
            hist.marks.append((sample.stamp, 1 if verdict else -1))
            while hist.marks and hist.marks[0][0] < sample.stamp - self.window:
                hist.marks.popleft()
            if sample.stamp - hist.first >= self.window / 2:  # half a window seen: a level can be said
                hist.level = next_level(hist.level, sum(m for _, m in hist.marks) / len(hist.marks))
        for who in [w for w, h in self.people.items() if h.marks and sample.stamp - h.marks[-1][0] > self.forget]:
            del self.people[who]

    def level(self, person: str) -> EngagementLevel:
        hist = self.people.get(person)
        return hist.level if hist is not None else "unknown"

    def engaged_between(self, person: str, t0: float, t1: float) -> bool | None:
        """`engaged_over`'s answer from the frames this tracker judged (the last `window` s): for a gesture service
        rule asking about a span that just ended (a palm held, a wave). None: no frame of the person in the span."""
        hist = self.people.get(person)
        marks = [(s, m > 0) for s, m in hist.marks if t0 <= s <= t1] if hist is not None else []
        return window_verdict(marks, t1, self.cfg)[0] if marks else None


def engaged_flag(level: EngagementLevel) -> bool | None:
    """`Person.engaged` from the level: true while engaged (and still when only starting to look away)."""
    if level == "unknown":
        return None
    return level in ("engaged", "disengaging")


def mark_engagement(persons: Persons, tracker: EngagementTracker) -> None:
    """Each person's REP-155 level (`Person.engagement`, and `engaged` from it) from the camera's tracker; a person
    whose face has not been judged stays unknown (nil)."""
    for p in persons.persons:
        level = tracker.level(p.id)
        if level == "unknown" and p.face is not None:
            level = tracker.level(p.face)  # no person tracker had named the face yet
        if level != "unknown":
            p.engagement, p.engaged = level, engaged_flag(level)
