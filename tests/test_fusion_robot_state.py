"""Issue #43, the robot's state in fusion (services/fusion/robot.py, docs/robot.md), in process: "put it down" acts on
what the robot holds, a command while it is busy is asked about or queued as the profile says (stop passes), a
failure is announced once, and without any state fusion acts as it always did."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from common.robot import DEFAULT, Profile, load_profile
from common.schema import Clarification, FusedCommand, HeldObject, RobotState, RobotStatus
from services.fusion import robot
from services.fusion.core import Config, FusionCore
from testkit.scenarios import BASE_STAMP, KEYS, Obj, Step, deliver, say, see

TABLETOP = load_profile(Path(__file__).resolve().parent.parent / "profiles" / "tabletop_arm.toml")
TABLE = [Obj("cup_1", "cup", "red", (150, 300)), Obj("bowl_1", "bowl", "blue", (450, 300))]
RED_CUP = HeldObject(label="cup", id="cup_1", color="red")


def state(t: float, status: RobotStatus, **fields: Any) -> Step:
    def build(base: float) -> tuple[str, RobotState]:
        return KEYS.robot_state(), RobotState(stamp=base + t, source="robot/test", status=status, **fields)

    return Step(t, build)


class Fusion:
    """FusionCore fed step by step, as the service's worker feeds it (the same core, no Zenoh)."""

    def __init__(self, profile: Profile = DEFAULT):
        self.core = FusionCore(Config(), "fusion/test", profile=profile)
        for modality in ("vision", "gesture"):
            self.core.on_liveliness(modality, "test", True)
        self.wall = 1000.0

    def feed(self, *steps: Step) -> list[Any]:
        out: list[Any] = []
        for s in sorted(steps, key=lambda s: s.t):
            out.extend(o.sample for o in deliver(self.core, *s.build(BASE_STAMP), self.wall))
            out.extend(o.sample for o in self.core.tick(self.wall))
            self.wall += 0.002
        self.wall += 100.0
        out.extend(o.sample for o in self.core.tick(self.wall))
        return out

    def command(self, start: float, text: str, *extra: Step) -> list[Any]:
        """`text` said at `start` with the table in view around it."""
        scene = [see(start + t / 10, TABLE) for t in range(-10, 16, 2)]
        return self.feed(*scene, say(start, start + 0.9, text), *extra)


def only(out: list[Any]) -> Any:
    assert len(out) == 1, out
    return out[0]


def test_without_a_state_fusion_acts_as_before():
    cmd = only(Fusion().command(0.0, "put it down"))
    assert isinstance(cmd, FusedCommand) and cmd.intent == "put_down" and cmd.target is None
    assert "Robot" not in cmd.prompt


def test_put_it_down_acts_on_what_the_robot_holds():
    cmd = only(Fusion().command(0.0, "put it down", state(-0.5, "idle", holding=RED_CUP)))
    assert isinstance(cmd, FusedCommand) and cmd.intent == "put_down"
    assert cmd.target is not None and cmd.target.id == "cup_1"  # the object it holds, in view
    assert "it is the red cup (cup_1), which I hold" in cmd.explanation
    assert "Robot state: idle; holding the red cup (cup_1)" in cmd.prompt


def test_put_it_down_holding_nothing_or_something_else_is_refused():
    no = only(Fusion().command(0.0, "put it down", state(-0.5, "idle")))
    assert isinstance(no, Clarification) and no.reason == "not_found" and no.candidates == []
    assert no.question == "I'm not holding anything to put down."
    other = only(Fusion().command(0.0, "put down the bowl", state(-0.5, "idle", holding=RED_CUP)))
    assert isinstance(other, Clarification) and other.question == "I'm holding the red cup (cup_1), not a bowl."


def test_a_command_while_busy_is_asked_about_and_a_yes_does_it():
    f = Fusion()
    first = only(f.command(0.0, "bring me the bowl"))
    assert isinstance(first, FusedCommand) and first.target is not None and first.target.id == "bowl_1"
    busy = state(2.0, "busy", command=first.id, intent="bring")
    asked = only(f.command(3.0, "pick up the cup", busy))
    assert isinstance(asked, Clarification) and asked.reason == "low_confidence"
    assert asked.question == "I'm still bringing the blue bowl. Shall I pick up the red cup now?"
    assert [c.id for c in asked.candidates] == ["cup_1"]
    done = only(f.command(5.0, "yes"))
    assert isinstance(done, FusedCommand) and done.intent == "pick_up" and done.target is not None
    assert done.target.id == "cup_1"


def test_stop_is_never_held_while_busy():
    f = Fusion(TABLETOP)  # queues while busy
    stop = only(f.command(3.0, "stop", state(2.0, "busy", command="cmd-x", intent="pick_up")))
    assert isinstance(stop, FusedCommand) and stop.intent == "stop"


def test_a_command_while_busy_is_queued_by_a_queueing_profile_and_goes_out_when_done():
    f = Fusion(TABLETOP)
    first = only(f.command(0.0, "pick up the bowl"))
    assert isinstance(first, FusedCommand)
    assert f.command(3.0, "pick up the cup", state(2.0, "busy", command=first.id, intent="pick_up")) == []
    assert f.core.robot.queued and f.core.robot.queued[0].target is not None
    released = only(f.feed(state(6.0, "done", command=first.id, holding=HeldObject(label="bowl"))))
    assert isinstance(released, FusedCommand) and released.intent == "pick_up"
    assert released.target is not None and released.target.id == "cup_1"
    assert f.feed(state(7.0, "idle")) == []  # released once


def test_a_stop_drops_what_was_queued_while_busy():
    f = Fusion(TABLETOP)
    assert f.command(3.0, "pick up the cup", state(2.0, "busy", command="cmd-x", intent="pick_up")) == []
    stop = only(f.command(6.0, "stop"))
    assert isinstance(stop, FusedCommand) and stop.intent == "stop"
    assert f.feed(state(8.0, "idle")) == []  # nothing left to release


def test_a_failure_is_announced_once_with_the_reason():
    f = Fusion()
    first = only(f.command(0.0, "bring me the bowl"))
    failed = state(3.0, "failed", command=first.id, intent="bring", reason="couldn't reach it")
    told = only(f.feed(failed))
    assert isinstance(told, Clarification) and told.reason == "not_found" and told.candidates == []
    assert told.question == "I couldn't bring the blue bowl: couldn't reach it."
    assert told.text == "bring me the bowl"
    assert f.feed(state(3.5, "failed", command=first.id, reason="couldn't reach it")) == []  # said once
    unknown = only(f.feed(state(4.0, "failed", reason="the gripper jammed.")))  # a failure of no known command
    assert isinstance(unknown, Clarification) and unknown.question == "I couldn't finish that: the gripper jammed."


def test_an_older_state_does_not_replace_a_newer_one():
    now = robot.RobotNow()
    assert now.update(RobotState(stamp=BASE_STAMP + 2, source="r/1", status="busy", command="c"))
    assert not now.update(RobotState(stamp=BASE_STAMP + 1, source="r/1", status="idle"))
    assert now.state is not None and now.state.status == "busy"


def test_while_busy_follows_the_profile():
    busy = RobotState(stamp=BASE_STAMP, source="r/1", status="busy", command="c")
    assert robot.while_busy(None, DEFAULT, "pick_up") == "act"
    assert robot.while_busy(busy, DEFAULT, "pick_up") == "ask"
    assert robot.while_busy(busy, TABLETOP, "pick_up") == "queue"
    assert robot.while_busy(busy, TABLETOP, "stop") == "act"
    idle = RobotState(stamp=BASE_STAMP, source="r/1", status="idle")
    assert robot.while_busy(idle, TABLETOP, "pick_up") == "act"
