"""Several robots on one network: one router, each robot its own secured users, nothing crosses over."""

from __future__ import annotations

import time

import pytest

from common.codec import encode
from common.schema import FusedCommand, Weights
from common.security import access_control, init_secrets, login_user, may_publish, read_passwords
from hri.cli import make_transcript
from testkit.harness import Client, wait_for_port


def site(tmp_path):
    init_secrets(tmp_path / "site", robot="robot1")
    return init_secrets(tmp_path / "site", robot="robot2")


def test_each_robot_has_its_own_users_bound_to_its_prefix(tmp_path):
    sec = site(tmp_path)
    assert {"robot1-fusion", "robot1-cli", "robot2-speech", "robot2-cli"} <= set(sec.users)
    assert "fusion" not in sec.users  # no user of the default prefix on a site made with --robot only
    assert set(read_passwords(sec.passwords_file)) == set(sec.users)
    assert may_publish(sec, "robot1-fusion", "robot1/fusion/command", "hri")
    assert not may_publish(sec, "robot2-fusion", "robot1/fusion/command", "hri")
    assert not may_publish(sec, "robot2-speech", "robot1/speech/kbd/transcript", "hri")
    acl = access_control(sec, "hri")
    rules = {r["id"]: r for r in acl["rules"]}
    assert rules["speech-publish@robot2"]["key_exprs"] == ["robot2/speech/*/transcript", "robot2/speech/*/decoding"]
    assert rules["learn-subscribers@robot1"]["key_exprs"] == ["robot1/**"]
    subjects = {s["id"]: s["usernames"] for s in acl["subjects"]}
    assert subjects["role-fusion@robot1"] == ["robot1-fusion"] and subjects["role-fusion@robot2"] == ["robot2-fusion"]
    # a process started with --prefix robot1 logs in as robot1's user of its name
    assert login_user(sec.folder, "vision", "robot1") == "robot1-vision"
    assert login_user(sec.folder, "vision", "hri") == "vision"


def transcript(text: str, source: str):
    return make_transcript(text, mic="kbd", end=time.time(), confidence=0.95, source=source)


@pytest.mark.integration
def test_two_robots_share_a_router_without_seeing_each_others_inputs(group, tmp_path):
    secrets = str(site(tmp_path).folder)
    group.start("router", "hri.cli", "router", "--listen", group.endpoint, "--secure", secrets, connect=False)
    wait_for_port(group.port)
    fusion1 = group.service("fusion", "--prefix", "robot1", "--secure", secrets)
    fusion2 = group.service("fusion", "--prefix", "robot2", "--secure", secrets)
    reader1 = Client(group.endpoint, prefix="robot1", secure=secrets, user="robot1-cli")
    reader2 = Client(group.endpoint, prefix="robot2", secure=secrets, user="robot2-cli")
    speech1 = Client(group.endpoint, prefix="robot1", secure=secrets, user="robot1-speech")
    speech2 = Client(group.endpoint, prefix="robot2", secure=secrets, user="robot2-speech")
    fusion2_forger = Client(group.endpoint, prefix="robot2", secure=secrets, user="robot2-fusion")
    try:
        reader1.wait_alive("fusion", timeout=90)
        reader2.wait_alive("fusion", timeout=90)
        out1 = reader1.collect("robot1/fusion/**")
        out2 = reader2.collect("robot2/fusion/**")
        time.sleep(1.0)
        # robot 2's operator speaks: robot 2 acts, robot 1 hears nothing
        speech2.publish("robot2/speech/kbd/transcript", transcript("turn left", "speech/robot2"))
        ((_, cmd2),) = out2.wait(1, timeout=20)
        assert isinstance(cmd2, FusedCommand) and cmd2.intent == "turn", cmd2
        # robot 2's processes try robot 1's keys: its words and a forged command
        speech2.put_raw("robot1/speech/kbd/transcript", encode(transcript("turn right", "speech/robot2")))
        speech2.publish("robot1/speech/kbd/transcript", transcript("turn right", "speech/robot2"))
        forged = FusedCommand(
            stamp=time.time(),
            source="fusion/forged",
            id="cmd-forged",
            intent="stop",
            confidence=1.0,
            weights=Weights(speech=1.0, vision=0.0, gesture=0.0),
            inputs={},
            explanation="forged",
            prompt="forged",
        )
        fusion2_forger.publish("robot1/fusion/command", forged)
        fusion2_forger.put_raw("robot1/fusion/command", encode(forged))
        # robot 1's own operator: the one command robot 1 sees
        time.sleep(1.0)
        speech1.publish("robot1/speech/kbd/transcript", transcript("turn left", "speech/robot1"))
        ((_, cmd1),) = out1.wait(1, timeout=20)
        assert isinstance(cmd1, FusedCommand) and cmd1.intent == "turn" and "left" in cmd1.prompt, cmd1
        out1.drain(1.5)
        assert [s.id for _, s in out1.seen] == [cmd1.id], [s for _, s in out1.seen]
        stats1 = reader1.stats("fusion")
        assert stats1["received"] == 1, stats1  # robot 1's fusion consumed robot 1's one transcript, nothing else
        assert fusion1.alive() and fusion2.alive()
    finally:
        for c in (reader1, reader2, speech1, speech2, fusion2_forger):
            c.close()
