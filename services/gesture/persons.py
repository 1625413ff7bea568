"""People in view — pure: where each person's body is looked for, a person track with a stable id, and which
person each hand belongs to (issue #33; REP-155's person <-> body <-> face <-> hands).

**Regions.** MediaPipe Pose's legacy API finds one pose per image, so the body of every person is found by running
pose on that person's *region*: the frame cut around them. Regions come from two places, each for a reason:
- a **face** (MediaPipe face detection, a few ms a frame): a new person is found from the first frame their face
  is seen, at any place in the image; the region is the face box widened to the shoulders and arms
  (`REGION_SIDE` face widths each side) and stretched down to the hips and below (`REGION_BELOW` face heights),
  and split half-way towards a neighbouring face so that the crop holds one person, not the neighbour;
- the person's **body of the previous frame**, widened by `BODY_MARGIN`: a person whose face is not seen (the
  back of the head, a head bowed, a face too small at 4 m) keeps their body from frame to frame once any body was
  found for them.
A skeleton found in a face's region is kept only when its nose falls near that face (`NOSE_IN_FACE`): pose on a
crop may find the neighbour's arm rather than the person meant.

**Tracks.** A person observed in a frame (a face, a body, or both) is matched to the tracks of the earlier frames
by overlap of their boxes — the face box where both have a face (a face stays put while an arm moves), else the
person box — best overlap first, at least `MIN_IOU`, and a face id from a face tracker always wins. A track not
seen is kept `keep_s` seconds of source time (a short occlusion, a turn of the head) — and always until the next
update after it was last seen, so that a slow machine processing a frame a second keeps everyone's id; an
observation that matches no track starts a new person with a new id (`person-<n>`, never reused).

**Hands.** A hand (the hand stage's 21 landmarks, its handedness the person's own side) belongs to the person whose
pose wrist of the same side is nearest its wrist, within `WRIST_MATCH` body scales; else to the one person whose
box holds its wrist; else it is nobody's (nil on the wire: unknown).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from common.boxes import iou, match_in_order
from services.gesture.body import MIN_VISIBILITY, WRISTS
from services.gesture.temporal import body_scale

Box = tuple[float, float, float, float]  # x, y, w, h px

REGION_SIDE = 2.5  # face widths each side of the face's centre: elbows out, an arm pointing sideways
REGION_ABOVE = 0.6  # face heights above the face: a raised hand
REGION_BELOW = 7.0  # face heights below the face: hips and thighs (a standing body is ~7.5 heads tall)
BODY_MARGIN = 0.25  # of the body box's size, each side: where last frame's body is looked for again
NOSE_IN_FACE = 0.75  # the skeleton's nose within this many face sizes of the face centre: the face's body
MIN_IOU = 0.2  # boxes overlapping less are different people
WRIST_MATCH = 0.6  # body scales: a hand's wrist this near the pose wrist of its side is that person's hand
NOSE = 0


@dataclass(frozen=True)
class PersonObs:
    """One person seen in one frame: a face, a body or both (px of the frame)."""

    box: Box  # the person's extent: the body's box, else the face's region
    face_box: Box | None = None
    face_id: str | None = None  # from a face tracker (`Face.id`), when there is one
    body: np.ndarray | None = None  # 33x3 [x px, y px, visibility]
    score: float = 1.0


@dataclass
class PersonTrack:
    id: str
    box: Box
    face_box: Box | None
    face_id: str | None
    body: np.ndarray | None
    score: float
    first_seen: float
    last_seen: float
    seen_now: bool = True  # observed in the latest frame (not just kept)


def _clip(x0: float, y0: float, x1: float, y1: float, width: int, height: int) -> Box | None:
    x0, y0 = max(0.0, x0), max(0.0, y0)
    x1, y1 = min(float(width), x1), min(float(height), y1)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return None
    return (x0, y0, x1 - x0, y1 - y0)


def face_region(face: Box, others: list[Box], width: int, height: int) -> Box | None:
    """Where the body of the person with this face is looked for: widened and stretched down from the face,
    split half-way towards any other face beside it."""
    fx, fy, fw, fh = face
    cx = fx + fw / 2
    x0, x1 = cx - REGION_SIDE * fw, cx + REGION_SIDE * fw
    for ox, _, ow, _ in others:
        ocx = ox + ow / 2
        if ocx > cx:
            x1 = min(x1, (cx + fw / 2 + ocx - ow / 2) / 2)  # half-way between the two faces' facing edges
        elif ocx < cx:
            x0 = max(x0, (ocx + ow / 2 + cx - fw / 2) / 2)
    return _clip(x0, fy - REGION_ABOVE * fh, x1, fy + fh + REGION_BELOW * fh, width, height)


def body_box(body: np.ndarray) -> Box | None:
    """The box of the landmarks seen (visibility >= 0.5); None when fewer than 3 are."""
    p = np.asarray(body, dtype=float).reshape(33, 3)
    seen = p[p[:, 2] >= MIN_VISIBILITY]
    if len(seen) < 3:
        return None
    x0, y0 = float(seen[:, 0].min()), float(seen[:, 1].min())
    return (x0, y0, float(seen[:, 0].max()) - x0, float(seen[:, 1].max()) - y0)


def body_region(box: Box, width: int, height: int) -> Box | None:
    """Where a body seen last frame is looked for in this one."""
    x, y, w, h = box
    mx, my = BODY_MARGIN * max(w, h), BODY_MARGIN * max(w, h)
    return _clip(x - mx, y - my, x + w + mx, y + h + my, width, height)


def crop_int(region: Box) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) integer pixel bounds of a region, for slicing an image."""
    x, y, w, h = region
    return int(x), int(y), int(round(x + w)), int(round(y + h))


def to_frame(body_in_crop: np.ndarray, region: Box) -> np.ndarray:
    """A skeleton found in a crop, moved into the frame's pixels."""
    x0, y0, _, _ = crop_int(region)
    out = np.array(body_in_crop, dtype=float, copy=True)
    out[:, 0] += x0
    out[:, 1] += y0
    return out


def body_fits_face(body: np.ndarray, face: Box) -> bool:
    """Is this skeleton the face's person? Its nose (seen or guessed) near the face centre."""
    fx, fy, fw, fh = face
    nose = np.asarray(body, dtype=float).reshape(33, 3)[NOSE, :2]
    size = max(fw, fh)
    return bool(np.hypot(nose[0] - (fx + fw / 2), nose[1] - (fy + fh / 2)) <= NOSE_IN_FACE * size)


def union_box(a: Box, b: Box) -> Box:
    x0, y0 = min(a[0], b[0]), min(a[1], b[1])
    x1, y1 = max(a[0] + a[2], b[0] + b[2]), max(a[1] + a[3], b[1] + b[3])
    return (x0, y0, x1 - x0, y1 - y0)


def observe(face: Box | None, body: np.ndarray | None, face_id: str | None = None, score: float = 1.0) -> PersonObs:
    """One person's observation from a face and/or a body: the box is the body's (with the face), else the face's."""
    bbox = body_box(body) if body is not None else None
    if bbox is not None and face is not None:
        bbox = union_box(bbox, face)
    if bbox is None and face is not None:
        fx, fy, fw, fh = face
        bbox = (fx, fy, fw, fh)
    if bbox is None:
        raise ValueError("a person observation needs a face or a body with landmarks seen")
    return PersonObs(bbox, face, face_id, body if body is not None and body_box(body) is not None else None, score)


def _affinity(track: PersonTrack, obs: PersonObs) -> float:
    """How well an observation continues a track: 2 for the same face id, else the overlap of the faces when both
    have one, else of the person boxes."""
    if obs.face_id is not None and obs.face_id == track.face_id:
        return 2.0
    if obs.face_box is not None and track.face_box is not None:
        return max(iou(obs.face_box, track.face_box), 0.5 * iou(obs.box, track.box))
    return iou(obs.box, track.box)


@dataclass
class PersonTracker:
    """Stable person ids over the frames of one camera. Feed `update(stamp, observations)` in stamp order."""

    keep_s: float = 1.0  # a track unseen this long (source time) is dropped: a short occlusion keeps its id
    tracks: list[PersonTrack] = field(default_factory=list)
    next_id: int = 1

    def update(self, stamp: float, observations: list[PersonObs]) -> list[PersonTrack]:
        """The tracks seen in this frame, in the order of `observations` (one per observation)."""
        # a track seen in the last update is always matched again, however long ago that was in source time (a
        # slow machine processes few frames); one missed since is kept `keep_s`; a stream gone back: all new
        self.tracks = [
            t for t in self.tracks if t.last_seen <= stamp and (t.seen_now or stamp - t.last_seen <= self.keep_s)
        ]
        pairs = [(_affinity(t, o), ti, oi) for ti, t in enumerate(self.tracks) for oi, o in enumerate(observations)]
        best_first = sorted((p for p in pairs if p[0] >= MIN_IOU), key=lambda p: (-p[0], p[1], p[2]))
        assigned = {oi: self.tracks[ti] for oi, ti in match_in_order(best_first).items()}
        for t in self.tracks:
            t.seen_now = False
        out = []
        for oi, o in enumerate(observations):
            track = assigned.get(oi) or self._new(stamp, o)
            track.box, track.body, track.score, track.last_seen, track.seen_now = o.box, o.body, o.score, stamp, True
            track.face_box = o.face_box or track.face_box
            track.face_id = o.face_id or track.face_id
            out.append(track)
        return out

    def _new(self, stamp: float, o: PersonObs) -> PersonTrack:
        track = PersonTrack(f"person-{self.next_id}", o.box, o.face_box, o.face_id, o.body, o.score, stamp, stamp)
        self.next_id += 1
        self.tracks.append(track)
        return track

    def bodies(self) -> list[tuple[str, Box]]:
        """(id, body box) of the tracks whose body was seen last: where to look for them again."""
        return [(t.id, b) for t in self.tracks if t.body is not None and (b := body_box(t.body)) is not None]


def _by_wrist(side: str, wrist: np.ndarray, persons: list[PersonTrack]) -> str | None:
    best: tuple[float, str] | None = None
    for p in persons:
        if p.body is None:
            continue
        joint = p.body[WRISTS[side]]
        if joint[2] < MIN_VISIBILITY * 0.5:  # a wrist pose barely saw cannot claim a hand
            continue
        d = float(np.hypot(*(wrist - joint[:2]))) / body_scale(p.body)
        if d <= WRIST_MATCH and (best is None or d < best[0]):
            best = (d, p.id)
    return best[1] if best else None


def _by_box(wrist: np.ndarray, persons: list[PersonTrack]) -> str | None:
    holding = [
        p.id
        for p in persons
        if p.box[0] <= wrist[0] <= p.box[0] + p.box[2] and p.box[1] <= wrist[1] <= p.box[1] + p.box[3]
    ]
    return holding[0] if len(holding) == 1 else None


def assign_hands(hands: list[tuple[str, np.ndarray]], persons: list[PersonTrack]) -> list[str | None]:
    """Per hand ((handedness, 21x2 landmarks)), the id of the person it belongs to, or None. One person has at most
    one hand of each side: a second claim of the same side goes to nobody."""
    out: list[str | None] = []
    taken: set[tuple[str, str]] = set()
    for side, landmarks in hands:
        wrist = np.asarray(landmarks, dtype=float).reshape(-1, 2)[0]
        who = _by_wrist(side, wrist, persons) or _by_box(wrist, persons)
        if who is not None and (who, side) in taken:
            who = None
        if who is not None:
            taken.add((who, side))
        out.append(who)
    return out


PoseIn = Callable[[Box], "np.ndarray | None"]  # pose on one region of the frame -> 33x3 in the frame's px, or None


@dataclass(frozen=True)
class Seen:
    """What the frame's detectors give the person stage."""

    width: int
    height: int
    faces: list[tuple[Box, str | None]]  # face boxes with their face-track id (None without a face tracker)
    main_body: np.ndarray | None = None  # the full-frame pose (the most prominent person), when run
    previous: list[Box] = field(default_factory=list)  # body boxes of the last frame's persons


def _claimed(body: np.ndarray, bodies: list[np.ndarray]) -> bool:
    """The same skeleton found twice (two regions over one person): the noses within a tenth of its size."""
    nose = body[NOSE, :2]
    return any(float(np.hypot(*(nose - b[NOSE, :2]))) <= 0.1 * body_scale(b) for b in bodies)


def observe_people(seen: Seen, pose_in: PoseIn) -> list[PersonObs]:
    """Every person of the frame with their body where one is found: a face's person gets the full-frame skeleton
    when its nose is at that face, else pose on the face's region; a body of the last frame with no face now is
    looked for in its widened box. `pose_in` runs pose on one region (the shell's MediaPipe)."""
    boxes = [b for b, _ in seen.faces]
    bodies: list[np.ndarray] = []
    out: list[PersonObs] = []
    main = seen.main_body
    for k, (face, face_id) in enumerate(seen.faces):
        body = main if main is not None and body_fits_face(main, face) else None
        region = face_region(face, boxes[:k] + boxes[k + 1 :], seen.width, seen.height) if body is None else None
        if region is not None:
            found = pose_in(region)
            body = found if found is not None and body_fits_face(found, face) else None
        if body is not None and _claimed(body, bodies):
            body = None
        if body is not None:
            bodies.append(body)
        out.append(observe(face, body, face_id))
    for body in [main] if main is not None else []:
        if body_box(body) is not None and not _claimed(body, bodies) and not _in_a_face(body, boxes):
            bodies.append(body)
            out.append(observe(None, body))
    for previous in seen.previous:  # a person whose face is not seen now: their body where it was
        region = body_region(previous, seen.width, seen.height)
        if region is None or any(iou(previous, o.box) >= MIN_IOU for o in out):
            continue
        found = pose_in(region)
        if found is not None and body_box(found) is not None and not _claimed(found, bodies):
            bodies.append(found)
            out.append(observe(None, found))
    return out


def _in_a_face(body: np.ndarray, faces: list[Box]) -> bool:
    """A body whose nose is at a face already listed belongs to that face's person (its own pose missed)."""
    return any(body_fits_face(body, f) for f in faces)


def _centre_in(box: Box, other: Box) -> bool:
    x, y, w, h = box
    ox, oy, ow, oh = other
    return ox <= x + w / 2 <= ox + ow and oy <= y + h / 2 <= oy + oh


def merge_faces(tracked: Sequence[tuple[Box, str | None]], detected: Sequence[Box]) -> list[tuple[Box, str | None]]:
    """The person stage's faces of a frame (issue #40): the face stage's (Face Mesh: box and face id, but a
    short-range detector that misses faces beyond ~2 m) and every face the full-range detector finds that none of
    them is (neither box's centre inside the other's), left to right. A face both found keeps the face stage's box
    and id, so persons near the camera are as with the face stage alone; a face at room distance still seeds its
    person's region."""
    extra = [(d, None) for d in detected if not any(_centre_in(d, t) or _centre_in(t, d) for t, _ in tracked)]
    return sorted([*tracked, *extra], key=lambda f: f[0][0])
