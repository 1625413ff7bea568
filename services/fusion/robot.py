"""What the robot is doing, as fusion uses it (issue #43, docs/robot.md). Pure.

The robot (or the ROS 2 bridge) publishes `RobotState` when its state changes; fusion keeps the latest (`RobotNow`).
Until one arrives fusion behaves as it always has. With one:
- "put it down (there)" acts on what the robot holds, and is refused when it holds nothing (`put_down_check`);
- a command while the robot is busy is asked about or queued, as the profile says (`while_busy`); stop always passes;
- a failure ("couldn't reach it") is announced to the person (`failure_words`), once per failed command;
- a command queued while busy goes out when the robot is idle or done (`RobotNow.release`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from common.robot import Profile
from common.schema import FusedCommand, HeldObject, RobotState
from services.fusion.ground import SceneObject

BusyAction = Literal["act", "ask", "queue"]
# -ing forms of the intents, for "I'm still bringing the red cup"
DOING = {
    "pick_up": "picking up",
    "bring": "bringing",
    "put_down": "putting down",
    "go_to": "going to",
    "come_here": "coming to you",
    "look_at": "looking at",
    "follow": "following",
    "greet": "greeting",
    "move": "moving",
    "turn": "turning",
}
DO = {"pick_up": "pick up", "bring": "bring", "put_down": "put down", "go_to": "go to", "look_at": "look at"}
REMEMBERED_COMMANDS = 100  # the recent commands a state's `command` id is looked up in (for words)
QUEUE_MAX = 10  # commands held while busy; more are dropped oldest first


def held_words(held: HeldObject) -> str:
    """ "the red cup" (with its id when known: "the red cup (cup_3)")."""
    name = f"the {held.color + ' ' if held.color else ''}{held.label}"
    return f"{name} ({held.id})" if held.id else name


def command_words(cmd: FusedCommand | None, intent: str | None, doing: bool) -> str:
    """ "bringing the red cup" / "bring the red cup" from the command (else its intent alone)."""
    verbs = DOING if doing else DO
    name = cmd.intent if cmd is not None else intent
    verb = verbs.get(name or "", "doing something" if doing else "do that")
    if cmd is not None and cmd.target is not None:
        t = cmd.target
        return f"{verb} the {t.color + ' ' if t.color else ''}{t.label}"
    if cmd is not None and cmd.place:
        return f"{verb} the {cmd.place}"
    return verb


def while_busy(state: RobotState | None, profile: Profile, intent: str) -> BusyAction:
    """What to do with a new command `intent` now: act (idle, unknown state, or a stop), or ask / queue while busy."""
    if state is None or state.status != "busy" or intent == "stop":
        return "act"
    return profile.while_busy


def busy_question(state: RobotState, doing: FusedCommand | None, cmd: FusedCommand) -> str:
    """ "I'm still bringing the red cup. Shall I pick up the blue cup now?" """
    return (
        f"I'm still {command_words(doing, state.intent, doing=True)}. "
        f"Shall I {command_words(cmd, cmd.intent, doing=False)} now?"
    )


def failure_words(state: RobotState, cmd: FusedCommand | None) -> str:
    """ "I couldn't bring the red cup: couldn't reach it." """
    what = command_words(cmd, state.intent, doing=False) if cmd is not None or state.intent else "finish that"
    return f"I couldn't {what}: {(state.reason or 'it failed').strip().rstrip('.')}."


@dataclass(frozen=True)
class PutDown:
    """What "put it down" means with the robot's state known: `refuse` (words), or the held object (`held`, and the
    object in view that is it, by id)."""

    refuse: str | None = None
    held: HeldObject | None = None
    in_view: SceneObject | None = None


def put_down_check(state: RobotState | None, said_label: str | None, objects: list[SceneObject]) -> PutDown | None:
    """ "Put it down there" with the robot's state: it holds nothing (refused), holds something else than the words
    name (refused), or holds it (that object). None: the state is unknown (act as before)."""
    if state is None:
        return None
    held = state.holding
    if held is None:
        return PutDown(refuse="I'm not holding anything to put down.")
    if said_label not in (None, "object", held.label):
        return PutDown(refuse=f"I'm holding {held_words(held)}, not a {said_label}.")
    in_view = next((o for o in objects if held.id is not None and o.id == held.id), None)
    return PutDown(held=held, in_view=in_view)


@dataclass
class RobotNow:
    """The robot's latest state, the recent commands (to say what a state's command was) and the commands held
    while it is busy (profile `while_busy = "queue"`)."""

    state: RobotState | None = None
    sent: dict[str, FusedCommand] = field(default_factory=dict)
    queued: list[FusedCommand] = field(default_factory=list)
    announced: set[tuple[str | None, float]] = field(default_factory=set)

    def remember(self, cmd: FusedCommand) -> None:
        self.sent[cmd.id] = cmd
        while len(self.sent) > REMEMBERED_COMMANDS:
            del self.sent[next(iter(self.sent))]

    def command(self, state: RobotState | None) -> FusedCommand | None:
        return None if state is None or state.command is None else self.sent.get(state.command)

    def update(self, state: RobotState) -> bool:
        """Take `state` unless older than the one held; True when taken."""
        if self.state is not None and state.stamp < self.state.stamp:
            return False
        self.state = state
        return True

    def failure(self) -> str | None:
        """The words announcing the current state's failure, once per failed command (None: nothing to say)."""
        state = self.state
        if state is None or state.status != "failed":
            return None
        key = (state.command, state.stamp if state.command is None else 0.0)
        if key in self.announced:
            return None
        self.announced.add(key)
        return failure_words(state, self.command(state))

    def queue(self, cmd: FusedCommand) -> None:
        self.queued = (self.queued + [cmd])[-QUEUE_MAX:]

    def drop_queued(self) -> int:
        """Forget every queued command (a stop); how many there were."""
        dropped, self.queued = len(self.queued), []
        return dropped

    def release(self) -> FusedCommand | None:
        """The next queued command once the robot is idle or done (then it is busy with it: one at a time)."""
        if self.state is None or self.state.status not in ("idle", "done") or not self.queued:
            return None
        return self.queued.pop(0)

    def words(self) -> str:
        """The state for a planner: "busy with cmd-… (bring the red cup); holding the red cup (cup_3)"."""
        state = self.state
        if state is None:
            return ""
        cmd = self.command(state)
        doing = f" with {state.command}" if state.command else ""
        if cmd is not None or state.intent:
            doing += f" ({command_words(cmd, state.intent, doing=False)})"
        why = f": {state.reason}" if state.status == "failed" and state.reason else ""
        held = f"; holding {held_words(state.holding)}" if state.holding else "; holding nothing"
        return f"{state.status}{doing}{why}{held}"
