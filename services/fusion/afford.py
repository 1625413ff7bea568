"""Who and what a command may act on (issue #31). Pure.

Two rules, applied to the objects in view before any scoring, so that no rule (touch, under the fingertip, along the
ray, relation, colour, the words) can propose what they leave out, and no question lists it:

1. **The commanding person is never the object.** The person pointing — the person detection whose box holds the
   pointing fingertip or the ray's origin (a detector's person box holds the arm) — is left out of every command,
   and so is what is on them: a detection centred on the pointing hand, and what they wear (a tie, a backpack, a
   handbag) inside their box.
2. **Affordances** (`common.language.INTENT_AFFORDANCES`, declared beside the action words): pick up / bring / put
   need something graspable by this robot (its profile, common/robot.py: by class, by the class's typical weight, and
   with depth by its measured size); go to / look at take anything; give to / follow / look at someone take a person
   (other people are targets of person actions only).

`applicable` says what is left and why each other object was removed; `refusal` turns a command whose words name
only what the action cannot apply to ("pick up the couch") into a plain answer with the reason ("I can't pick up a
couch: I don't lift furniture.", "I can't bring a chair: it weighs about 5 kg, over my 2 kg.").
"""

from __future__ import annotations

from dataclasses import dataclass

from common.language import ANY_OBJECT, OBJECT_CATEGORIES, Affordance, affordance, label_matches
from common.robot import DEFAULT, Profile
from services.fusion import space
from services.fusion.evidence import Pointing
from services.fusion.ground import SceneObject, on_the_hand, ray_score
from services.fusion.parse import ObjectPhrase
from services.fusion.touch import fingertip

WORN = frozenset({"tie", "backpack", "handbag"})  # what a person carries on the body, boxed inside the person's box
VERBS = {
    "pick_up": "pick up",
    "bring": "bring",
    "put_down": "put down",
    "follow": "follow",
    "go_to": "go to",
    "look_at": "look at",
}


@dataclass(frozen=True)
class Removed:
    obj: SceneObject
    why: str  # "you are pointing", "a couch is not something I can pick up", "0.92 m across: too big to pick up"


@dataclass(frozen=True)
class Applicable:
    """The objects a command may act on, and the others with the reason each was removed."""

    kept: list[SceneObject]
    removed: list[Removed]
    kind: Affordance | None
    commander: SceneObject | None = None


def _inside(point: tuple[float, float], box: tuple[float, float, float, float]) -> bool:
    x, y, w, h = box
    return x <= point[0] <= x + w and y <= point[1] <= y + h


def _holds_3d(p: Pointing, o: SceneObject) -> bool:
    """In metres: the 3-D ray starts (at the eyes, the shoulder or the hand) inside this person's measured body."""
    if p.ray3d is None or o.position is None or o.extent is None or not space.same_frame(p.ray3d, o.frame_id):
        return False
    return space.holds(o.position, o.extent, p.ray3d.origin, margin=space.NEAR_TOLERANCE_M)


def commanding_person(p: Pointing | None, objects: list[SceneObject]) -> SceneObject | None:
    """The person pointing: the person detection in the pointing camera whose box holds the fingertip or the ray's
    origin, or, in metres, whose measured body holds the 3-D ray's origin (with depth, those first; then the smallest
    box: in a crowd, boxes overlap behind the pointer). None without pointing or person."""
    if p is None:
        return None
    tip = fingertip(p.origin, p.direction, p.hand_box)
    holders = [
        o
        for o in objects
        if o.cam == p.cam
        and o.label == "person"
        and (_inside(tip, o.bbox) or _inside(p.origin, o.bbox) or _holds_3d(p, o))
    ]
    if not holders:
        return None
    in_metres = [o for o in holders if _holds_3d(p, o)]  # depth tells the pointer from a person behind him
    return min(in_metres or holders, key=lambda o: (o.bbox[2] * o.bbox[3], o.id))


def _on_commander(p: Pointing | None, commander: SceneObject | None, o: SceneObject) -> str | None:
    """Why `o` is part of the commanding person (None: it is not)."""
    if commander is not None and o.key == commander.key:
        return "the person pointing (the commanding person is never the object)"
    if p is not None and o.cam == p.cam and on_the_hand(p, o):
        return "on the pointing hand"
    if commander is not None and o.label in WORN and o.cam == commander.cam and _inside(o.center, commander.bbox):
        return f"worn by the person pointing ({o.label})"
    return None


def size_m(o: SceneObject) -> float | None:
    """The object's largest visible size in metres (width or height; depth's spread is a surface's), None unmeasured."""
    if o.extent is None:
        return None
    return max(o.extent[0], o.extent[1])


def _not_afforded(kind: Affordance | None, verb: str, o: SceneObject, profile: Profile) -> str | None:
    """Why `intent`'s affordance excludes `o` (None: it does not)."""
    if kind == "person" and o.label != "person":
        return f"not a person (one can only {verb} a person)"
    if kind != "graspable":
        return None
    if profile.never_kind(o.label) is not None:
        return f"{article(o.label)} is not something I can {verb}"
    heavy = profile.class_reason(o.label)
    if heavy is not None:
        return f"too heavy to {verb}: {heavy}"
    size = size_m(o)
    if profile.size_reason(size) is not None:
        return f"{size:.2f} m across: too big to {verb} (at most {profile.max_size_m:.1f} m)"
    return None


def article(noun: str) -> str:
    return ("an " if noun[:1] in "aeiou" else "a ") + noun


def applicable(
    intent: str | None,
    phrase: ObjectPhrase,
    objects: list[SceneObject],
    pointing: Pointing | None,
    profile: Profile = DEFAULT,
) -> Applicable:
    """The objects `intent` (with the words `phrase`) may act on: never the commanding person or what is on them;
    only what the intent's affordance allows this robot (`profile`)."""
    kind = affordance(intent, phrase.label)
    verb = VERBS.get(intent or "", "act on")
    commander = commanding_person(pointing, objects)
    kept: list[SceneObject] = []
    removed: list[Removed] = []
    # the affordance's verdict depends on the label and the size alone: once per kind of object, not once per object
    # (a thousand objects in view are a few labels: issue #34)
    not_afforded: dict[tuple[str, tuple[float, float, float] | None], str | None] = {}
    for o in objects:
        why = _on_commander(pointing, commander, o)
        if why is None:
            kind_of = (o.label, o.extent)
            if kind_of not in not_afforded:
                not_afforded[kind_of] = _not_afforded(kind, verb, o, profile)
            why = not_afforded[kind_of]
        if why is None:
            kept.append(o)
        else:
            removed.append(Removed(o, why))
    return Applicable(kept, removed, kind, commander)


def _said_labels(phrase: ObjectPhrase) -> tuple[str, ...]:
    """The detector labels the words name (empty: no kind said, or "thing")."""
    if phrase.label is None or phrase.label == ANY_OBJECT:
        return ()
    return OBJECT_CATEGORIES.get(phrase.label, (phrase.label,))


def refusal(intent: str | None, phrase: ObjectPhrase, found: Applicable, profile: Profile = DEFAULT) -> str | None:
    """A plain answer when the words name only what `intent` cannot apply to: "I can't pick up a couch: I don't lift
    furniture." (by class or its typical weight, whether one is in view or not; the reason from `profile`), "I can't
    pick up the chair: 0.92 m across …" (every one in view that fits the words is too big), "I can only follow a
    person." None: the words leave something to act on."""
    verb = VERBS.get(intent or "", "do that to")
    labels = _said_labels(phrase)
    reasons = [profile.class_reason(label) for label in labels] if found.kind == "graspable" else []
    if labels and reasons and all(reasons):
        return f"I can't {verb} {article(phrase.label or labels[0])}: {reasons[0]}."
    if found.kind == "person" and labels and "person" not in labels:
        return f"I can only {verb} a person."
    if not labels or any(label_matches(phrase.label, o.label) for o in found.kept):
        return None
    fitting = [
        r for r in found.removed if label_matches(phrase.label, r.obj.label) and r.obj.key != _key(found.commander)
    ]
    if not fitting:
        return None
    return f"I can't {verb} the {fitting[0].obj.name()}: {fitting[0].why}."


def _key(o: SceneObject | None) -> tuple[str, str] | None:
    return None if o is None else o.key


def unable(intent: str | None, profile: Profile = DEFAULT) -> str | None:
    """A plain answer when this robot cannot do `intent` at all ("go to the kitchen" without a base: "I can't do that:
    I can't move from where I stand."); None: it can."""
    why = profile.missing_ability(intent)
    return None if why is None else f"I can't do that: {why}."


def relevant_removals(found: Applicable, phrase: ObjectPhrase, pointing: Pointing | None) -> list[Removed]:
    """The removed objects that would have been in the running: the words name their kind, or the ray points at
    them (G >= 0.5 by the ray alone)."""
    labels = _said_labels(phrase)
    out = []
    for r in found.removed:
        named = bool(labels) and label_matches(phrase.label, r.obj.label)
        pointed = pointing is not None and ray_score(pointing, r.obj).gesture >= 0.5
        if named or pointed:
            out.append(r)
    return out


def removed_words(found: Applicable, phrase: ObjectPhrase, pointing: Pointing | None, limit: int = 3) -> str:
    """ "; left out: p1 (person: the person pointing …), c2 (couch: a couch is not something I can pick up)" for an
    explanation: the candidates in the running that the commander rule or an affordance removed ("" when none)."""
    shown = relevant_removals(found, phrase, pointing)
    if not shown:
        return ""
    words = [f"{r.obj.id} ({r.obj.label}: {r.why})" for r in shown[:limit]]
    more = f" and {len(shown) - limit} more" if len(shown) > limit else ""
    return "; left out: " + ", ".join(words) + more
