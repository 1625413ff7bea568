"""Is the person making a gesture engaged with the robot, and are they speaking, at a moment (issue #40) — pure.

`engaged` is the ONE place fusion's gesture rules ask whether a person faces the robot: REP-155 engagement on
`Persons` (`Person.engaged`, the gesture service's engagement tracker, common/engagement.py) when it is known, else
the same rule over the person's face frames of the last `LOOK_BACK_S` (`engaged_over`: facing the robot, in its
field, within reach); None when nothing tells. Not the
body's orientation (services/fusion/space.py `Facing`): around a hand close to the camera MediaPipe guesses a
skeleton turned away (intent/cat1_palm_closeup_phone: a stop held to a phone was taken for one turned away).
`speaking`: `Person.speaking` when filled, else the
person's mouth moving (the mean change of `mouth_open` per second over the last `LOOK_BACK_S`, the speaker
attribution's `speaker_still` threshold, services/fusion/speaker.py).

A face is the person's when `Face.person` says so; a gesture of no known person (or faces without person ids) is
taken for the one face in view (several faces: not known)."""

from __future__ import annotations

from collections.abc import Sequence

from common.engagement import EngagementConfig, engaged_over
from common.schema import Faces, Persons
from services.fusion.speaker import Track, tracks_of

LOOK_BACK_S = 1.0  # s of source time before the moment looked at
SPEAKING_AT = 0.5  # Person.speaking (a likelihood) at or above it: speaking


def _persons_field(persons: Sequence[Persons], person: str | None, stamp: float, name: str) -> object | None:
    """The latest non-nil value of `Person.<name>` for `person` in the Persons samples of the look-back."""
    if person is None:
        return None
    for sample in reversed(persons):
        if stamp - LOOK_BACK_S <= sample.stamp <= stamp + 1e-9:
            for p in sample.persons:
                value = getattr(p, name, None)
                if p.id == person and value is not None:
                    return value
    return None


def face_track(faces: Sequence[Faces], person: str | None, stamp: float) -> Track | None:
    """The face track of `person` in the look-back (the only face there when faces carry no person ids)."""
    tracks = tracks_of(s for s in faces if stamp - LOOK_BACK_S <= s.stamp <= stamp + 1e-9)
    if person is not None:
        mine = [t for t in tracks.values() if person in t.people]
        if mine:
            return max(mine, key=lambda t: len(t.stamps))
    only = next(iter(tracks.values())) if len(tracks) == 1 else None
    return only if only is not None and (person is None or not only.people) else None


def engaged(
    persons: Sequence[Persons],
    faces: Sequence[Faces],
    person: str | None,
    stamp: float,
    cfg: EngagementConfig | None = None,
) -> bool | None:
    """Does `person` face the robot at `stamp`? None when nothing tells."""
    said = _persons_field(persons, person, stamp, "engaged")
    if isinstance(said, bool):
        return said
    track = face_track(faces, person, stamp)
    if track is None:
        return None
    return engaged_over(faces, track.person, stamp - LOOK_BACK_S, stamp, cfg, persons).engaged


def speaking(
    persons: Sequence[Persons], faces: Sequence[Faces], person: str | None, stamp: float, still: float
) -> bool:
    """Is `person` speaking at `stamp`: their mouth moving faster than `still` (change of mouth_open per second)?"""
    said = _persons_field(persons, person, stamp, "speaking")
    if isinstance(said, float):
        return said >= SPEAKING_AT
    track = face_track(faces, person, stamp)
    if track is None:
        return False
    seen = [(t, m) for t, m in zip(track.stamps, track.mouth) if m is not None]
    moves = [abs(m1 - m0) / (t1 - t0) for (t0, m0), (t1, m1) in zip(seen, seen[1:]) if t1 > t0]
    return bool(moves) and sum(moves) / len(moves) >= still
