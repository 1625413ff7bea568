"""What fusion publishes, built in one place from the schema's types: FusedCommand (with its planner prompt) and
Clarification. Ids are derived from the input's source, stamp and mic (or gesture): a replay reproduces them."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from common.counters import GestureIntent
from common.schema import (
    GESTURE,
    SPEECH,
    VISION,
    Clarification,
    ClarificationReason,
    FusedCommand,
    GestureEvent,
    Intent,
    Location,
    Motion,
    Transcript,
    Weights,
)
from services.fusion import describe
from services.fusion.ground import MAX_CANDIDATES, SceneObject, Scored
from services.fusion.window import Context


@dataclass
class Output:
    sample: FusedCommand | Clarification
    realtime: bool = False  # a stop: published at REAL_TIME priority, express


def stable_id(prefix: str, *parts: object) -> str:
    """Same inputs, same id: replaying a session reproduces the ids."""
    digest = hashlib.sha1("|".join(repr(p) for p in parts).encode()).hexdigest()
    return f"{prefix}-{digest[:16]}"


def unit(x: float) -> float:
    return round(max(0.0, min(1.0, x)), 4)


class Outputs:
    def __init__(self, source: str):
        self.source = source

    def command(  # noqa: PLR0913 - its arguments become the typed decision (issue #32 item 2) after #31 lands
        self,
        t: Transcript,
        intent: Intent,
        ctx: Context | None,
        *,
        confidence: float,
        explanation: str,
        text: str | None = None,
        target: SceneObject | None = None,
        location: Location | None = None,
        gesture: str | None = None,
        place: str | None = None,
        motion: Motion | None = None,
        motion_said: str = "",
        realtime: bool = False,
    ) -> Output:
        """A command on an utterance, with the window's weights, inputs and scene (`ctx`); without a window
        (a spoken stop, decided on arrival) speech alone."""
        text = text if text is not None else t.text
        prompt = describe.planner_prompt(
            text=text,
            intent=intent,
            target=target,
            location=location,
            place=place,
            pointing=ctx.pointing if ctx else None,
            gesture=None,
            objects=ctx.objects if ctx else [],
            missing=ctx.missing if ctx else [],
            explanation=explanation,
            motion=motion,
            motion_said=motion_said,
        )
        cmd = FusedCommand(
            stamp=t.stamp,
            source=self.source,
            id=stable_id("cmd", t.source, t.stamp, t.mic),
            intent=intent,
            text=text,
            target=target.to_target() if target else None,
            location=location,
            place=place,
            gesture=gesture,
            confidence=unit(confidence),
            weights=ctx.weights if ctx else Weights(speech=1.0, vision=0.0, gesture=0.0),
            inputs=ctx.inputs if ctx else {SPEECH: t.stamp, VISION: None, GESTURE: None},
            explanation=explanation,
            prompt=prompt,
            motion=motion,
        )
        return Output(cmd, realtime=realtime)

    def target_command(
        self,
        t: Transcript,
        intent: Intent,
        target: Scored,
        location: Location | None,
        ctx: Context,
        explanation: str,
        place: str | None = None,
    ) -> Output:
        """A command on the object grounding chose; the explanation says what was missing from the window."""
        if ctx.missing:
            explanation += "; missing: " + ", ".join(ctx.missing) + f" (window closed by {ctx.how})"
        return self.command(
            t,
            intent,
            ctx,
            confidence=target.total,
            explanation=explanation,
            target=target.obj,
            location=location,
            gesture="point" if target.gesture is not None else None,
            place=place,
        )

    def gesture_command(self, ev: GestureEvent, intent: GestureIntent, why: str, realtime: bool) -> Output:
        """A command from a gesture alone (stop, come here)."""
        prompt = describe.planner_prompt(
            text=None,
            intent=intent,
            target=None,
            location=None,
            place=None,
            pointing=None,
            gesture=f"{ev.gesture} ({ev.hand} hand)",
            objects=[],
            missing=[],
            explanation=why,
        )
        cmd = FusedCommand(
            stamp=ev.stamp,
            source=self.source,
            id=stable_id("cmd", ev.source, ev.stamp, ev.gesture),
            intent=intent,
            text=None,
            target=None,
            location=None,
            gesture=ev.gesture,
            confidence=round(ev.score, 4),
            weights=Weights(speech=0.0, vision=0.0, gesture=1.0),
            inputs={SPEECH: None, VISION: None, GESTURE: ev.stamp},
            explanation=why,
            prompt=prompt,
        )
        return Output(cmd, realtime=realtime)

    def clarification(
        self, t: Transcript, reason: ClarificationReason, question: str, candidates: list[SceneObject]
    ) -> Output:
        return Output(
            Clarification(
                stamp=t.stamp,
                source=self.source,
                id=stable_id("clr", t.source, t.stamp, t.mic),
                text=t.text,
                reason=reason,
                question=question,
                candidates=[o.to_target() for o in candidates[:MAX_CANDIDATES]],
            )
        )
