"""Words for people and planners: clarification questions, explanations, the planner prompt. Pure."""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Sequence

from common.language import ANY_OBJECT, OBJECT_CATEGORIES, label_matches, plural
from common.robot import in_base
from common.schema import GESTURE, SPEECH, CameraMount, Location, Motion
from services.fusion import space
from services.fusion.decision import Act
from services.fusion.evidence import Pointing
from services.fusion.ground import SceneObject, Scored
from services.fusion.parse import ObjectPhrase, Utterance
from services.fusion.relations import fit_matrix

PROMPT_MAX_OBJECTS = 25  # a scene with 1000 detections must not make a 1000-line prompt


def region(o: SceneObject) -> str:
    """Where an object is in its image, in words."""
    fx, fy = o.center[0] / max(o.width, 1), o.center[1] / max(o.height, 1)
    horiz = "left" if fx < 1 / 3 else "right" if fx > 2 / 3 else "middle"
    vert = "top" if fy < 1 / 3 else "bottom" if fy > 2 / 3 else ""
    if horiz == "middle":
        return f"at the {vert}" if vert else "in the middle"
    return f"at the {vert} {horiz}" if vert else f"on the {horiz}"


def relative_positions(objs: list[SceneObject]) -> list[str]:
    """Position words that tell the objects apart: relative for 2-3, image regions beyond."""
    if len(objs) == 2:
        a, b = objs
        dx, dy = b.center[0] - a.center[0], b.center[1] - a.center[1]
        if abs(dx) >= abs(dy):
            return ["on the left", "on the right"] if dx > 0 else ["on the right", "on the left"]
        return ["at the top", "at the bottom"] if dy > 0 else ["at the bottom", "at the top"]
    if len(objs) == 3:
        order = sorted(range(3), key=lambda i: objs[i].center[0])
        words = [""] * 3
        for rank, i in enumerate(order):
            words[i] = ("on the left", "in the middle", "on the right")[rank]
        return words
    return [region(o) for o in objs]


def positions_clear(objs: list[SceneObject], where: list[str]) -> bool:
    """Do the position words tell the objects apart at a glance? Not when two share a word, nor when two objects
    stand so close (centres less than half their size apart) that "left" and "right" are a guess."""
    if len(set(where)) < len(where):
        return False
    for i, a in enumerate(objs):
        for b in objs[i + 1 :]:
            dx, dy = abs(a.center[0] - b.center[0]), abs(a.center[1] - b.center[1])
            if dx < 0.5 * (a.bbox[2] + b.bbox[2]) / 2 and dy < 0.5 * (a.bbox[3] + b.bbox[3]) / 2:
                return False
    return True


def landmarks(objs: list[SceneObject], scene: list[SceneObject]) -> list[str] | None:
    """'next to the laptop', 'next to the sink' …: for each candidate the nearest other thing in view (not a
    candidate, not of the candidates' kinds, not a person), when those differ between all the candidates; else None.
    People answer such a question with the same words ("the one next to the laptop"), and grounding reads them."""
    kinds = {o.label for o in objs}
    keys = {o.key for o in objs}
    others = [o for o in scene if o.key not in keys and o.label not in kinds and o.label != "person"]
    if not others:
        return None
    fits = fit_matrix("next_to", [o.bbox for o in objs], [o.bbox for o in others])
    out = []
    for i, o in enumerate(objs):
        same_cam = [j for j, x in enumerate(others) if x.cam == o.cam]
        if not same_cam:
            return None
        j = max(same_cam, key=lambda j: (fits[i, j], -j))
        if fits[i, j] < 0.3:  # nothing close enough to be "next to" it
            return None
        out.append(f"next to the {others[j].label}")
    return out if len(set(out)) == len(out) else None


def candidate_phrases(objs: list[SceneObject], scene: list[SceneObject] | None = None) -> list[str]:
    """'the red one on the left', 'the blue cup on the right', 'the one next to the laptop' … enough words to tell
    them apart: colour when colours differ, the kind when kinds differ, and where each is — relative positions when
    they differ, else the thing each one stands next to, else the image region."""
    colors_differ = len({o.color for o in objs}) > 1
    labels_differ = len({o.label for o in objs}) > 1
    where = relative_positions(objs)
    if scene and not positions_clear(objs, where):
        where = landmarks(objs, scene) or where
    out = []
    for o, pos in zip(objs, where):
        words = ["the"]
        if colors_differ and o.color:
            words.append(o.color)
        words.append(o.label if labels_differ else "one")
        out.append(" ".join(words) + " " + pos)
    return out


def a(noun: str) -> str:
    """'a cup', 'an orange'."""
    return ("an " if noun[:1] in "aeiou" else "a ") + noun


def and_list(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def or_list(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " or " + items[-1]


def ambiguous_question(phrase: ObjectPhrase, candidates: list[Scored], scene: list[SceneObject] | None = None) -> str:
    objs = [c.obj for c in candidates]
    labels = {o.label for o in objs}
    what = next(iter(labels)) if len(labels) == 1 else phrase.label if phrase.label in OBJECT_CATEGORIES else "one"
    if (
        len(objs) > 3
        and len({o.color for o in objs}) == 1
        and len(set(relative_positions(objs))) < len(objs)
        and not (scene and landmarks(objs, scene))
    ):
        return (
            f"I see {len(objs)} {(objs[0].color + ' ') if objs[0].color else ''}{plural(what)} that fit. "
            f"Which one? Point at it, or say where it is (left, right, top, bottom)."
        )
    unchecked = f"I can't tell {' '.join(phrase.unmatched)} by sight. " if phrase.unmatched else ""
    return f"{unchecked}Which {what}: {or_list(candidate_phrases(objs, scene))}?"


def conflict_question(phrase: ObjectPhrase, said: Scored, pointed: Scored) -> str:
    a, b = candidate_phrases([said.obj, pointed.obj])
    return (
        f"You said the {phrase.describe()} but pointed at the {pointed.obj.name()}. Which one do you mean: {a} or {b}?"
    )


def not_found_question(
    phrase: ObjectPhrase, visible: list[SceneObject], vision_missing: bool, nothing_to: str | None = None
) -> str:
    """What I could not find, what I can see instead, and the question. An unknown noun is said as such:
    "I don't know what a pitcher is. I can see a blue cup and a bowl. Which one do you mean?". `nothing_to`: the
    verb of an action none of the objects in view can take ("pick up": only people and a couch are in view)."""
    unknown = phrase.unknown_nouns
    if unknown:
        lead = " ".join(f"I don't know what {a(n)} is." for n in unknown)
        what = f"the {phrase.describe()}"
    else:
        what = f"the {phrase.describe()}" if phrase.specific else "what you mean"
        lead = f"I can't see {what}."
    if vision_missing:
        return (
            f"{lead} I can't see anything right now (no camera input). Can you show me?"
            if phrase.noun
            else f"I can't see anything right now (no camera input), so I can't find {what}. Can you show me?"
        )
    if not visible and nothing_to:  # things in view, none the action applies to (people, furniture …)
        return f"{lead} I see nothing here I can {nothing_to}. Can you show me?"
    if not visible:
        return f"{lead} I don't see any objects. Can you show me?"
    if phrase.relations and not unknown and phrase.label:
        kind = [o for o in visible if label_matches(phrase.label, o.label)]
        if kind:  # the thing is there, the relation is not: say which part did not fit
            where = " and ".join(r.describe() for r in phrase.relations)
            noun = phrase.label if phrase.label != ANY_OBJECT else "one"
            return (
                f"I can see {and_list([a(o.name()) for o in kind[:3]])}, but no {noun} {where}. Which one do you mean?"
            )
    shown = sorted(visible[:4], key=lambda o: (o.cam, o.center[0], o.id))  # read left to right, like the scene
    names = [o.name() for o in shown]
    if len(set(names)) < len(names):  # two of a kind: say where each is
        names = [f"{o.name()} {region(o)}" for o in shown]
    return f"{lead} I can see {and_list([a(n) for n in names])}. Which one do you mean?"


def confirm_question(text: str, candidate: Scored | None) -> str:
    if candidate is not None:
        return f"I'm not sure. Do you mean the {candidate.obj.name()} {region(candidate.obj)}?"
    return f'I\'m not sure I heard you. Did you say: "{text}"?'


POINTED = 0.5  # the gesture evidence from which pointing is a reason for the choice (as `choose`'s "pointed")


def pointing_words(c: Scored) -> str:
    """How pointing scored `c`, by its rule and the figures that decided: 'under the fingertip', 'touched',
    '0.12 m from the 3-D ray (4 deg)', '5 deg off the image ray' ("" without pointing)."""
    if c.gesture is None:
        return ""
    if c.rule in ("touch", "under the fingertip"):
        return "touched by the fingertip" if c.rule == "touch" else "under the fingertip"
    if c.angle is None:
        return "not on the pointing ray"
    if c.off_m is not None:
        return f"{c.off_m:.2f} m from the 3-D pointing ray ({c.angle:.0f} deg)"
    return f"{c.angle:.0f} deg off the image pointing ray"


def decided_by(c: Scored, phrase: ObjectPhrase) -> str:
    """The rule that chose `c`: the words, pointing (and how), or both."""
    words = phrase.specific and c.match >= 0.5
    pointed = c.gesture is not None and c.gesture >= POINTED
    how = f"pointing ({c.rule})" if pointed and c.rule else "pointing"
    if words and pointed:
        return f"the words and {how}"
    if pointed:
        return how
    return "the words" if words else "the only candidate"


def explain_target(
    choice_winner: Scored,
    runner_up: Scored | None,
    weights: dict[str, float],
    phrase: ObjectPhrase,
    overruled: str | None,
) -> str:
    """Why the target won: the rule that decided and its figures (the fit to the words; how the pointing ray met it,
    when pointing counted for it; the runner-up). A figure that argues against the choice — the angle to a target
    that pointing did not single out — is never given as a reason."""
    o = choice_winner.obj
    reasons = []
    if phrase.specific:
        said = phrase.describe()
        fit = "fits" if choice_winner.match >= 0.5 else "does not fit"
        reasons.append(f"it {fit} '{said}' (speech {choice_winner.speech:.2f}, vision trust {choice_winner.trust:.2f})")
    if choice_winner.gesture is not None and choice_winner.gesture >= POINTED:
        reasons.append(f"{pointing_words(choice_winner)} (gesture {choice_winner.gesture:.2f})")
    if not reasons:
        reasons.append("it is the only object in view")
    text = (
        f"{o.id} ({o.name()}, {region(o)}) won with {choice_winner.total:.2f} by {decided_by(choice_winner, phrase)}: "
        + "; ".join(reasons)
    )
    if runner_up is not None:
        where = pointing_words(runner_up) if choice_winner.gesture is not None and runner_up.gesture else ""
        text += f"; runner-up {runner_up.obj.id} ({runner_up.obj.name()}) {runner_up.total:.2f}"
        text += f", {where}" if where else ""
    if overruled == SPEECH:
        text += (
            f". Speech and pointing disagreed; pointing won (gesture weight {weights[GESTURE]:.2f} vs "
            f"speech {weights[SPEECH]:.2f}, and vision trusts its labels for the said object only "
            f"{choice_winner.trust:.2f})"
        )
    elif overruled == GESTURE:
        text += (
            f". Speech and pointing disagreed; speech won (speech weight {weights[SPEECH]:.2f} vs "
            f"gesture {weights[GESTURE]:.2f})"
        )
    elif choice_winner.gesture is not None and choice_winner.gesture < POINTED:
        text += "; pointing did not choose it (it is not near the ray)"
    return text


def explain_command(text: str, intent: str, u: Utterance, location: Location | None) -> str:
    """Why a command without a target: what was heard, where it goes and how it moves."""
    return (
        f"'{text}' -> {intent}"
        + (f" to the {u.place}" if u.place else "")
        + (f"; location from the pointing ray at ({location.x:.0f}, {location.y:.0f})" if location else "")
        + (f": {motion_words(u.motion)}" if u.motion else "")
    )


def motion_words(m: Motion) -> str:
    """'move forward 10 m', 'turn left 90 degrees', 'move back (distance not said)'."""
    if m.angle is not None:  # a turn has an angle, a move a distance (or none said)
        return f"turn {m.direction or '(direction not said)'} {m.angle:g} degrees"
    amount = f"{m.distance:g} m" if m.distance is not None else "(distance not said: a short move)"
    return f"move {m.direction} {amount}"


@dataclass(frozen=True)
class PromptScene:
    """What the planner is told was perceived: the pointing, a gesture alone (its words), the objects in view
    and the inputs that were missing."""

    pointing: Pointing | None = None
    gesture: str | None = None
    objects: Sequence[SceneObject] = ()
    missing: Sequence[str] = ()
    robot: Sequence[str] = ()  # what the robot can do and is doing (none: the default profile, no state heard)
    mount: CameraMount | None = None  # where the camera sits on the robot (the profile's): positions in its base frame


def base_words(mount: CameraMount | None, frame_id: str | None, position: Sequence[float] | None) -> str:
    """ "; (x, y, z) m in base_link (x forward, y left, z up)" when the profile's mount places the camera frame."""
    base = in_base(mount, frame_id, None if position is None else list(position))
    if base is None or mount is None:
        return ""
    return f"; ({base[0]:.2f}, {base[1]:.2f}, {base[2]:.2f}) m in {mount.parent} (x forward, y left, z up)"


def most_confident(objects: Sequence[SceneObject], n: int) -> list[SceneObject]:
    """The n most confident objects (ties by camera and id), as sorting all would list them; only those scoring at
    least the n-th best score are sorted (a thousand objects in view: issue #34)."""
    if len(objects) <= n:
        cut = -math.inf
    else:
        cut = heapq.nlargest(n, [o.score for o in objects])[-1]
    return sorted([o for o in objects if o.score >= cut], key=lambda o: (-o.score, o.cam, o.id))[:n]


def planner_prompt(act: Act, text: str | None, scene: PromptScene) -> str:
    """Everything a planner needs, in plain text, from the same data the decision used."""
    intent, target, location, place, motion = act.intent, act.target, act.location, act.place, act.motion
    pointing, gesture, objects, missing = scene.pointing, scene.gesture, scene.objects, scene.missing
    lines = [f"Command: {intent}" + (f' (heard: "{text}")' if text else "")]
    if motion is not None:
        said = f', said as "{act.motion_said}"' if act.motion_said else ""
        lines.append(
            f"Motion: {motion_words(motion)} (robot frame: forward = the way it faces, "
            f"left/right = its own left/right{said})"
        )
    if target is not None:
        lines.append(
            f"Target: {target.id}, a {target.name()} at pixel ({target.center[0]:.0f}, "
            f"{target.center[1]:.0f}) in camera {target.cam}, {region(target)}"
            + space.metres_words(target.position, target.frame_id, target.extent)
            + base_words(scene.mount, target.frame_id, target.position)
        )
    if location is not None:
        lines.append(
            f"Location: pixel ({location.x:.0f}, {location.y:.0f}) in camera {location.cam}"
            + space.metres_words(location.position, location.frame_id)
            + base_words(scene.mount, location.frame_id, location.position)
        )
    if place:
        lines.append(f"Place: {place}")
    if pointing is not None:
        lines.append(
            f"Gesture: {pointing.hand} hand pointing from ({pointing.origin[0]:.0f}, "
            f"{pointing.origin[1]:.0f}) towards ({pointing.direction[0]:.2f}, {pointing.direction[1]:.2f}) "
            f"in camera {pointing.cam}" + space.ray_words(pointing.ray3d)
        )
    elif gesture:
        lines.append(f"Gesture: {gesture}")
    if objects:
        shown = most_confident(objects, PROMPT_MAX_OBJECTS)
        if target is not None and target not in shown:
            shown[-1] = target
        lines.append(
            f"Objects in view ({len(objects)}"
            + (f", {len(shown)} most confident listed" if len(shown) < len(objects) else "")
            + "):"
        )
        for o in sorted(shown, key=lambda o: (o.cam, o.center[0], o.id)):
            lines.append(
                f"- {o.id}: {o.name()} at ({o.center[0]:.0f}, {o.center[1]:.0f}) size "
                f"{o.bbox[2]:.0f}x{o.bbox[3]:.0f} in camera {o.cam} ({o.width}x{o.height}), {region(o)}, "
                f"score {o.score:.2f}" + space.metres_words(o.position, o.frame_id)
            )
    else:
        lines.append("Objects in view: none reported")
    if missing:
        lines.append("Missing inputs: " + ", ".join(missing))
    lines.extend(scene.robot)
    lines.append(f"Why: {act.explanation}")
    return "\n".join(lines)
