"""Fusion's decision as a value: what to do with one utterance, made in one place (FusionCore.decide and
decide_command, services/fusion/core.py) and rendered in one place (FusionCore.render: the dialogue asks,
services/fusion/outputs.py builds the wire messages, services/fusion/describe.py the words and the planner prompt).

- `Act`: publish a command, on a target, a location, a place, a motion or none of them;
- `Ask`: publish a clarification with the command drafted so far: which object (the choice's candidates and
  reason), where (`where`), or whether it was heard right (`heard`);
- `Refuse`: say why the command cannot be done ("I can't pick up a couch.", services/fusion/afford.py);
- `Ignore`: publish nothing, and count why.
"""

from __future__ import annotations

from dataclasses import dataclass

from common.counters import FusionCounter
from common.schema import Intent, Location, Motion
from services.fusion.ground import Choice, SceneObject, Scored


@dataclass
class Draft:
    """A command that is ready except for the person's answer."""

    intent: Intent
    text: str
    target: SceneObject | None = None
    location: Location | None = None
    place: str | None = None
    motion: Motion | None = None
    motion_said: str = ""


@dataclass(frozen=True)
class Act:
    """A command to publish. `text` is what the command says was heard (None: the transcript's own); `gesture`
    names the gesture that took part ("point"); `realtime` sends it at once (a stop)."""

    intent: Intent
    confidence: float
    explanation: str
    text: str | None = None
    target: SceneObject | None = None
    location: Location | None = None
    gesture: str | None = None
    place: str | None = None
    motion: Motion | None = None
    motion_said: str = ""
    realtime: bool = False


@dataclass(frozen=True)
class Grounded:
    """What grounding chose for the command's object: the winner, the runner-up and the side that lost a
    disagreement between speech and pointing (for the explanation)."""

    target: Scored | None = None
    runner_up: Scored | None = None
    overruled: str | None = None


@dataclass(frozen=True)
class ActOnTarget:
    """Act on the object grounding chose; the explanation is written when rendered (`explanation` given: the
    fallback's own). `remember`: "no, the other one" may correct it."""

    intent: Intent
    grounded: Grounded
    location: Location | None = None
    place: str | None = None
    explanation: str | None = None
    remember: bool = True


@dataclass(frozen=True)
class Ask:
    """Ask before acting: `choice` gives the reason and the candidates; `where` asks for the place instead;
    `heard` asks whether the words were heard right."""

    draft: Draft
    choice: Choice | None = None
    where: bool = False
    heard: bool = False


@dataclass(frozen=True)
class Refuse:
    """The words name only what the action cannot apply to: `answer` says so (on the wire a `not_found`
    Clarification without candidates, open like a question)."""

    answer: str
    draft: Draft


@dataclass(frozen=True)
class Ignore:
    """Publish nothing: `reason` is counted, `why` logged."""

    reason: FusionCounter
    why: str = ""


Decision = Act | ActOnTarget | Ask | Refuse | Ignore
