"""Issue #43 over real processes: fusion started with a robot profile (or refused at start with a malformed one, exit
code 2, nothing started), the profile answered on `robot/profile`, and the robot's state published on `robot/state`
changing what fusion does with the next command: asked about while busy, a failure announced, "put it down" on what it
holds. The objects are published as vision would (a table with a red cup and a blue bowl), the words as `hri say`."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from common.codec import decode
from common.schema import (
    Clarification,
    DetectedObject,
    Detections,
    FusedCommand,
    HeldObject,
    ImageQuality,
    RobotProfile,
    RobotState,
    RobotStatus,
)
from testkit.harness import Client, ProcessGroup, requires_services, type_command

ROOT = Path(__file__).resolve().parent.parent


def encode_map(data: dict[str, Any]) -> bytes:
    import msgpack

    return msgpack.packb(data)


TABLETOP = ROOT / "profiles" / "tabletop_arm.toml"
OBJECTS = [
    DetectedObject(id="cup_1", label="cup", color="red", score=0.9, bbox=[120, 260, 60, 80], center=[150, 300]),
    DetectedObject(id="bowl_1", label="bowl", color="blue", score=0.9, bbox=[420, 270, 60, 60], center=[450, 300]),
]


def test_a_malformed_profile_is_refused_at_start_saying_what_and_where(tmp_path: Path):
    bad = tmp_path / "arm.toml"
    bad.write_text('name = "arm"\n[grasp]\nmax_weight_kg = "two"\n')
    res = subprocess.run(
        [sys.executable, "-m", "services.fusion", "--profile", str(bad), "--connect", "tcp/127.0.0.1:9"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 2, res.stderr[-2000:]
    assert f"robot profile {bad}: [grasp] max_weight_kg: expected a number, got 'two'" in res.stderr


class Table:
    """Detections of the table, published at 5 Hz with the current time, as the vision service would."""

    def __init__(self, client: Client):
        self.client = client
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        seq = 0
        while not self.stop.wait(0.2):
            seq += 1
            self.client.publish(
                "hri/vision/cam0/objects",
                Detections(
                    stamp=time.time(),
                    source="vision/test",
                    seq=seq,
                    cam="cam0",
                    width=640,
                    height=480,
                    objects=OBJECTS,
                    quality=ImageQuality(brightness=0.55, contrast=0.5, sharpness=0.6),
                ),
            )

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2.0)


def said(client: Client, results: Any, text: str, timeout: float = 20.0) -> Any:
    """Say `text` and return what fusion publishes about it."""
    n = len([1 for _, s in results.drain() if isinstance(s, (FusedCommand, Clarification))])
    type_command(client, text)
    return results.wait(n + 1, timeout=timeout, where=lambda k, s: isinstance(s, (FusedCommand, Clarification)))[-1][1]


def robot_state(client: Client, status: RobotStatus, **fields: Any) -> None:
    """Publish a state and return once fusion has taken it (its `robot_states` count went up): the next words are
    decided with it."""
    taken = client.stats("fusion")["other"].get("robot_states", 0)
    client.publish("hri/robot/state", RobotState(stamp=time.time(), source="robot/test", status=status, **fields))
    client.wait_stats("fusion", lambda s: s["other"].get("robot_states", 0) > taken, f"the robot state {status!r}")


@pytest.mark.integration
@requires_services("fusion")
def test_the_robots_state_changes_what_fusion_does():
    group = ProcessGroup()
    client = table = None
    try:
        group.router()
        group.service("fusion", "--dialogue-timeout", "2")
        client = Client(group.endpoint)
        client.wait_alive("fusion", timeout=60)
        client.wait_matched(["hri/robot/state", "hri/speech/kbd/transcript", "hri/vision/cam0/objects"])
        profile = [decode(r.ok.payload.to_bytes(), RobotProfile) for r in client.session.get("hri/robot/profile")]
        assert [p.name for p in profile] == ["default"] and profile[0].while_busy == "ask"
        results = client.collect("hri/fusion/**")
        table = Table(client)
        client.put_raw("hri/robot/state", b"\xff not a state")  # bad input: counted and dropped
        client.put_raw(
            "hri/robot/state", encode_map({"v": 1, "stamp": time.time(), "source": "r/1", "status": "failed"})
        )
        # both bad states counted, and the table seen (two detections besides them): the words will meet the table
        ready = client.wait_stats("fusion", lambda s: len(s["rejected"]) >= 2 and s["received"] >= 4, "the table")
        rejected = ready["rejected"]
        assert rejected.get("not_msgpack") == 1 and rejected.get("bad_value") == 1, rejected  # a failure says why
        first = said(client, results, "bring me the bowl")
        assert isinstance(first, FusedCommand) and first.target is not None and first.target.id == "bowl_1", first
        robot_state(client, "busy", command=first.id, intent="bring")
        asked = said(client, results, "pick up the cup")
        assert isinstance(asked, Clarification) and asked.reason == "low_confidence", asked
        assert asked.question == "I'm still bringing the blue bowl. Shall I pick up the red cup now?"
        time.sleep(2.5)  # the question expires
        robot_state(client, "failed", command=first.id, intent="bring", reason="couldn't reach it")
        told = results.wait(
            1, timeout=10, where=lambda k, s: isinstance(s, Clarification) and s.question.startswith("I couldn't")
        )[0][1]
        assert told.question == "I couldn't bring the blue bowl: couldn't reach it." and told.reason == "not_found"
        robot_state(client, "idle")
        nothing = said(client, results, "put it down")
        assert isinstance(nothing, Clarification) and nothing.question == "I'm not holding anything to put down."
        robot_state(client, "idle", holding=HeldObject(label="cup", id="cup_1", color="red"))
        put = said(client, results, "put it down")
        assert isinstance(put, FusedCommand) and put.target is not None and put.target.id == "cup_1", put
        assert "Robot state: idle; holding the red cup (cup_1)" in put.prompt
        stats = client.stats("fusion")["other"]
        assert stats.get("asked_while_busy") == 1 and stats.get("robot_failure_announced") == 1, stats
    finally:
        if table is not None:
            table.close()
        if client is not None:
            client.close()
        group.close()


@pytest.mark.integration
@requires_services("fusion")
def test_a_profile_given_to_fusion_is_on_the_wire_and_decides():
    group = ProcessGroup()
    client = table = None
    try:
        group.router()
        group.service("fusion", "--profile", str(TABLETOP))
        client = Client(group.endpoint)
        client.wait_alive("fusion", timeout=60)
        client.wait_matched(["hri/robot/state", "hri/speech/kbd/transcript", "hri/vision/cam0/objects"])
        replies = [decode(r.ok.payload.to_bytes(), RobotProfile) for r in client.session.get("hri/robot/profile")]
        assert len(replies) == 1 and replies[0].name == "tabletop-arm" and replies[0].max_weight_kg == 1.0
        assert replies[0].camera is not None and replies[0].camera.frame_id == "cam0_optical"
        results = client.collect("hri/fusion/**")
        table = Table(client)
        client.wait_stats("fusion", lambda s: s["received"] >= 2, "the table")  # the words will meet it
        no = said(client, results, "go to the kitchen")
        assert isinstance(no, Clarification) and no.question == "I can't do that: I can't move from where I stand."
        first = said(client, results, "pick up the bowl")
        assert isinstance(first, FusedCommand) and "Robot: tabletop-arm" in first.prompt
        robot_state(client, "busy", command=first.id, intent="pick_up")
        before = len(results.drain())
        type_command(client, "pick up the cup")  # queued (the profile's while_busy), published once done
        client.wait_stats("fusion", lambda s: s["other"].get("queued_while_busy") == 1, "the command queued")
        assert len(results.drain()) == before  # nothing published while busy
        robot_state(client, "done", command=first.id)
        released = results.wait(before + 1, timeout=10)[-1][1]
        assert isinstance(released, FusedCommand), released
        assert released.intent == "pick_up" and released.target is not None and released.target.id == "cup_1"
    finally:
        if table is not None:
            table.close()
        if client is not None:
            client.close()
        group.close()


@pytest.mark.integration
@requires_services("fusion", "ros2")
def test_the_ros2_node_brings_the_robots_state_in_and_publishes_its_profile():
    """The ros2 node (bridge layout: the topic name as the key, raw CDR, as zenoh-bridge-ros2dds carries it): the
    robot's state as JSON on a std_msgs/String becomes RobotState on robot/state, a malformed one is counted and
    dropped, and fusion's profile is relayed to ROS as latched JSON with its camera mount on /tf_static."""
    from services.ros2 import core
    from services.ros2.types import deserialize, serialize

    group = ProcessGroup()
    client = None
    try:
        group.router()
        group.service("fusion", "--profile", str(ROOT / "profiles" / "mobile_manipulator.toml"))
        client = Client(group.endpoint)
        client.wait_alive("fusion", timeout=60)
        profiles: list[Any] = []
        got = threading.Event()

        def on_profile(sample: Any) -> None:
            profiles.append(deserialize(sample.payload.to_bytes(), core.STRING).data)
            got.set()

        sub = client.session.declare_subscriber("hri_fusion/robot_profile", on_profile)
        transforms: list[Any] = []
        tf_sub = client.session.declare_subscriber(
            "tf_static", lambda s: transforms.append(deserialize(s.payload.to_bytes(), core.TF_MESSAGE))
        )
        states = client.collect("hri/robot/state")
        ros2 = ["--key-layout", "bridge", "--state-topic", "robot_state", "--image-topic", "", "--depth-topic", ""]
        group.service("ros2", *ros2)
        client.wait_alive("ros2", timeout=60)
        assert got.wait(20), "no profile on hri_fusion/robot_profile"
        assert '"name": "mobile-manipulator"' in profiles[0] and '"max_weight_kg": 8.0' in profiles[0]
        deadline = time.monotonic() + 10
        while not transforms and time.monotonic() < deadline:
            time.sleep(0.1)
        (mount,) = transforms[0].transforms  # the head camera, 1.2 m up on base_link
        assert (mount.header.frame_id, mount.child_frame_id, mount.transform.translation.z) == (
            "base_link",
            "cam0_optical",
            1.2,
        )
        client.wait_matched(["hri_fusion/robot_state"])
        bad = core.msg(core.STRING, data='{"status": "failed"}')  # a failure without a reason
        client.session.put("hri_fusion/robot_state", serialize(bad, core.STRING))
        text = '{"status": "busy", "command": "cmd-1", "intent": "bring", "holding": {"label": "cup", "id": "cup_1"}}'
        client.session.put("hri_fusion/robot_state", serialize(core.msg(core.STRING, data=text), core.STRING))
        _, state = states.wait(1, timeout=20)[0]
        assert isinstance(state, RobotState) and state.status == "busy" and state.command == "cmd-1"
        assert state.holding is not None and state.holding.label == "cup" and state.source.startswith("ros2/")
        assert client.stats("ros2")["rejected"].get("bad_value") == 1
        sub.undeclare()
        tf_sub.undeclare()
    finally:
        if client is not None:
            client.close()
        group.close()


def test_hri_up_passes_the_profile_to_fusion_and_refuses_a_malformed_one_before_starting_anything(tmp_path: Path):
    import argparse

    from hri.launcher import add_up_arguments, services_from_args

    p = argparse.ArgumentParser()
    add_up_arguments(p)
    args = p.parse_args(["--profile", "profiles/tabletop_arm.toml", "--camera", "none"])
    (fusion,) = [s for s in services_from_args(args) if s.name == "fusion"]
    assert fusion.argv == ["services.fusion", "--profile", "profiles/tabletop_arm.toml"]
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[abilities]\nflies = true\n')
    port = "tcp/127.0.0.1:9"  # nothing may start: no router is reached, no service is spawned
    res = subprocess.run(
        [sys.executable, "-m", "hri.cli", "up", "--profile", str(bad), "--listen", port],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 2 and f"robot profile {bad}: [abilities]: unknown key(s) flies" in res.stderr
    assert "[hri up ]" not in res.stdout  # refused before the launcher said anything
