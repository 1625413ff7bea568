"""People in fusion (issue #33) — pure: whose gestures count for an utterance, competing pointing, and people as
referents ("bring it to me", "give it to her", "the man on the left", "the person who is talking").

- **Whose gesture counts.** With the utterance's speaker known (`Speaker.person`), a hand or gesture event of
  another person is not evidence for it; one whose person is not known (nil: an older sender, a hand no body
  reaches) still is — it cannot be told apart. A stop palm is not filtered here: anyone's stop stops the robot.
- **Competing pointing.** With the speaker unknown, every person's pointing during the utterance is evidence; when
  two people point, fusion grounds each and asks when they point at different things.
- **People as referents.** The recipient of "bring it to me" / "give it to her" / "hand it to the man on the left"
  is a person, not the object: the phrase is cut from the text before the object is parsed, and resolved against
  the `Persons` in view: "me" / "the person who is talking" = the speaker; "her" / "him" / "them" = the one other
  person in view (none or several: unknown); "the man on the left" = the leftmost (image left) person.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Iterable

import msgspec

from common.schema import GestureEvent, Hands, Location, Person, Persons
from services.fusion.evidence import Pointing, PointingObs, select_pointing
from services.fusion.ground import SceneObject

SPEAKER_WORDS = ("me", "myself", "us")
OTHER_WORDS = ("her", "him", "them")
PERSON_NOUNS = r"(?:person|man|woman|guy|lady|boy|girl|gentleman|one|kid|child)"
TALKING = r"(?:who is|who's|that is|that's)\s+(?:talking|speaking)"
SIDE = r"(?:on|to)\s+the\s+(left|right)"
# "to me", "to her", "to the man on the left", "to the person who is talking"; and "give me", "hand her" (the
# indirect object right after the verb)
RECIPIENT = re.compile(
    rf"\b(?:to|for)\s+(?P<to>me|myself|us|her|him|them|the\s+{PERSON_NOUNS}(?:\s+{SIDE}|\s+{TALKING})?)\b"
    rf"|\b(?P<verb>give|hand|bring|pass)\s+(?P<io>me|us|her|him|them)\b(?=\s+(?:the|a|an|that|this|it|those|these))",
    re.IGNORECASE,
)


@dataclass(frozen=True)
class PersonRef:
    """A person named in an utterance."""

    who: str  # "speaker", "other" (her/him/them), "side" (the man on the left), "any" (the person)
    side: str | None = None  # "left" / "right" for `who == "side"`
    said: str = ""


def _ref(phrase: str) -> PersonRef:
    words = phrase.lower().split()
    side = re.search(r"\b(left|right)\b", phrase.lower())
    if words[0] in SPEAKER_WORDS or re.search(TALKING, phrase.lower()):
        return PersonRef("speaker", said=phrase)
    if words[0] in OTHER_WORDS:
        return PersonRef("other", said=phrase)
    if side:
        return PersonRef("side", side.group(1), said=phrase)
    return PersonRef("any", said=phrase)


def split_recipient(text: str) -> tuple[str, PersonRef | None]:
    """The text without its recipient phrase, and the person it names (None when the text names no recipient)."""
    m = RECIPIENT.search(text)
    if m is None:
        return text, None
    if m.group("to"):
        return _join(text[: m.start()], text[m.end() :]), _ref(m.group("to"))
    return _join(text[: m.start("io")], text[m.end("io") :]), _ref(m.group("io"))


def _join(before: str, after: str) -> str:
    return " ".join((before + " " + after).split())


# "follow me", "look at him", "watch the person who is talking": a person as the object of a person action
PERSON_ACTION = re.compile(
    rf"\b(?:follow|look\s+at|watch|face|turn\s+to)\s+(?P<who>me|us|her|him|them|the\s+{PERSON_NOUNS}\s+{TALKING})\b",
    re.IGNORECASE,
)


def person_referent(text: str) -> PersonRef | None:
    """The person a person action names, when it names one by their part in the talk ("me", "him", "the person who
    is talking"); a description by looks or place ("the man on the left") is grounded like any object."""
    m = PERSON_ACTION.search(text)
    return _ref(m.group("who")) if m else None


def as_scene_object(person: Person, seen: Persons) -> SceneObject:
    """A person of `Persons` as a candidate a command can target (label `person`, the person's id)."""
    x, y, w, h = person.bbox
    return SceneObject(
        id=person.id,
        label="person",
        raw_label="person",
        color=None,
        bbox=(x, y, w, h),
        center=(x + w / 2, y + h / 2),
        score=person.score,
        cam=seen.cam,
        width=seen.width,
        height=seen.height,
        stamp=seen.stamp,
        quality=1.0,
        position=(person.position[0], person.position[1], person.position[2]) if person.position else None,
        frame_id=person.frame_id,
    )


def resolve(ref: PersonRef, persons: list[Person], speaker: str | None) -> Person | None:
    """The person `ref` names among those in view; None when it cannot be told."""
    if ref.who == "speaker":
        return next((p for p in persons if p.id == speaker), None)
    others = [p for p in persons if p.id != speaker]
    if ref.who == "side" and others:
        ordered = sorted(others, key=lambda p: p.bbox[0] + p.bbox[2] / 2)
        return ordered[0] if ref.side == "left" else ordered[-1]
    return others[0] if len(others) == 1 else None


def location_of(person: Person, cam: str) -> Location:
    """Where a person is, as a command's `location`: the centre of their box, and their torso in metres."""
    x, y, w, h = person.bbox
    return Location(x=x + w / 2, y=y + h / 2, cam=cam, position=person.position, frame_id=person.frame_id)


def latest_persons(samples: Iterable[Persons], ref: float, within: float = 2.0) -> Persons | None:
    """The Persons sample nearest `ref` (ties: the earlier), if one is within `within` seconds of it."""
    near = min(samples, key=lambda s: (abs(s.stamp - ref), s.stamp), default=None)
    return near if near is not None and abs(near.stamp - ref) <= within else None


# -- whose gesture counts ------------------------------------------------------------------------------------
def speakers_items(items: Iterable[tuple[str, Any]], speaker: str | None) -> list[tuple[str, Any]]:
    """The gesture samples of a window that are evidence for the speaker's utterance: every one when the speaker is
    unknown; else without the hands and events of another (known) person."""
    if speaker is None:
        return list(items)
    out: list[tuple[str, Any]] = []
    for key, item in items:
        if isinstance(item, Hands):
            kept = [h for h in item.hands if h.person in (None, speaker)]
            item = item if len(kept) == len(item.hands) else msgspec.structs.replace(item, hands=kept)
        elif isinstance(item, GestureEvent) and item.person not in (None, speaker):
            continue
        out.append((key, item))
    return out


def competing(observations: list[PointingObs], ref: float) -> tuple[Pointing, ...]:
    """Each known person's pointing when more than one person points in the window, else ()."""
    people = sorted({o.person for o in observations if o.person is not None})
    if len(people) < 2:
        return ()
    chosen = (select_pointing([o for o in observations if o.person == who], ref) for who in people)
    return tuple(p for p in chosen if p is not None)
