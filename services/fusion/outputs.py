"""What fusion publishes, built in one place from the schema's types: FusedCommand (with its planner prompt) and
Clarification. Ids are derived from the input's source, stamp and mic (or gesture): a replay reproduces them."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from common.counters import GestureIntent
from common.robot import with_base
from common.schema import (
    GESTURE,
    SPEECH,
    VISION,
    CameraMount,
    Clarification,
    ClarificationReason,
    FusedCommand,
    GestureEvent,
    RobotState,
    Transcript,
    Weights,
)
from services.fusion import describe
from services.fusion.decision import Act, ActOnTarget
from services.fusion.describe import PromptScene
from services.fusion.ground import MAX_CANDIDATES, SceneObject
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
        self.robot: list[str] = []  # what the planner prompt says of the robot (its profile, its state; docs/robot.md)
        # where the camera sits on the robot (the profile's mount): targets and locations also in its base frame
        self.mount: CameraMount | None = None

    def command(self, t: Transcript, act: Act, ctx: Context | None) -> Output:
        """A command on an utterance, with the window's weights, inputs and scene (`ctx`); without a window
        (a spoken stop, decided on arrival) speech alone."""
        text = act.text if act.text is not None else t.text
        scene = (
            PromptScene(ctx.pointing, None, ctx.objects, ctx.missing, self.robot, self.mount) if ctx else PromptScene()
        )
        cmd = FusedCommand(
            stamp=t.stamp,
            source=self.source,
            id=stable_id("cmd", t.source, t.stamp, t.mic),
            intent=act.intent,
            text=text,
            target=with_base(act.target.to_target(), self.mount) if act.target else None,
            location=with_base(act.location, self.mount) if act.location else None,
            place=act.place,
            gesture=act.gesture,
            confidence=unit(act.confidence),
            weights=ctx.weights if ctx else Weights(speech=1.0, vision=0.0, gesture=0.0),
            inputs=ctx.inputs if ctx else {SPEECH: t.stamp, VISION: None, GESTURE: None},
            explanation=act.explanation,
            prompt=describe.planner_prompt(act, text, scene),
            motion=act.motion,
        )
        return Output(cmd, realtime=act.realtime)

    def target_command(self, t: Transcript, act: ActOnTarget, ctx: Context, explanation: str) -> Output:
        """A command on the object grounding chose; the explanation says what was missing from the window."""
        target = act.grounded.target
        assert target is not None  # an ActOnTarget has one
        if ctx.missing:
            explanation += "; missing: " + ", ".join(ctx.missing) + f" (window closed by {ctx.how})"
        command = Act(
            act.intent,
            confidence=target.total,
            explanation=explanation,
            target=target.obj,
            location=act.location,
            gesture="point" if target.gesture is not None else None,
            place=act.place,
        )
        return self.command(t, command, ctx)

    def gesture_command(self, ev: GestureEvent, intent: GestureIntent, why: str, realtime: bool) -> Output:
        """A command from a gesture alone (stop, come here)."""
        act = Act(intent, confidence=ev.score, explanation=why)
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
            prompt=describe.planner_prompt(
                act, None, PromptScene(gesture=f"{ev.gesture} ({ev.hand} hand)", robot=self.robot)
            ),
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
                candidates=[with_base(o.to_target(), self.mount) for o in candidates[:MAX_CANDIDATES]],
            )
        )

    def announcement(self, state: RobotState, words: str, cmd: FusedCommand | None) -> Output:
        """What the robot says of its own state ("I couldn't bring the red cup: couldn't reach it."): a `not_found`
        Clarification without candidates (v1: no new reason value, docs/robot.md), about the command's words."""
        return Output(
            Clarification(
                stamp=state.stamp,
                source=self.source,
                id=stable_id("clr", state.source, state.stamp, state.command),
                text=cmd.text if cmd is not None else None,
                reason="not_found",
                question=words,
                candidates=[],
            )
        )
