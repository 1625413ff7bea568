"""A secured stack (hri secure init / --secure): only the right process may command the robot."""

from __future__ import annotations

import time

import cv2
import pytest
import zenoh

from common.schema import FusedCommand, Weights
from common.security import init_secrets, make_tls, read_passwords
from hri.cli import make_transcript
from testkit.harness import DATA, Client, ProcessGroup, wait_for_port

pytestmark = pytest.mark.integration

TABLE = DATA / "demo" / "table.png"


def secured_router(group: ProcessGroup, secrets: str):
    proc = group.start("router", "hri.cli", "router", "--listen", group.endpoint, "--secure", secrets, connect=False)
    wait_for_port(group.port)
    return proc


def test_only_authorised_services_command_the_robot(group, tmp_path):
    from common.schema import Frame

    secrets = str(init_secrets(tmp_path / "secrets", {"operator": ["reader", "keyboard"]}).folder)
    secured_router(group, secrets)
    vision = group.service("vision", "--labels", str(DATA / "demo" / "labels.json"), "--secure", secrets)
    fusion = group.service("fusion", "--secure", secrets)
    reader = Client(group.endpoint, secure=secrets)  # user cli: read-only
    camera = Client(group.endpoint, secure=secrets, user="camera")
    speech = Client(group.endpoint, secure=secrets, user="speech")
    intruder = Client(group.endpoint, secure=secrets, user="vision")  # a compromised vision process
    try:
        reader.wait_alive("vision", timeout=120)
        reader.wait_alive("fusion", timeout=120)
        commands = reader.collect("hri/fusion/command")
        objects = reader.collect("hri/vision/*/objects")
        img = cv2.imread(str(TABLE))
        frame = Frame(
            stamp=time.time(),
            source="camera/test",
            seq=0,
            cam="cam0",
            width=img.shape[1],
            height=img.shape[0],
            encoding="jpeg",
            data=cv2.imencode(".jpg", img)[1].tobytes(),
        )
        camera.publish("hri/camera/cam0/frame", frame)
        objects.wait(1, timeout=60)
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
        intruder.publish("hri/fusion/command", forged)
        # a fresh session sends its first put before it learns there is no subscriber it may reach: the router
        # itself must refuse it
        from common.codec import encode

        hasty = Client(group.endpoint, secure=secrets, user="gesture")
        hasty.put_raw("hri/fusion/command", encode(forged))
        hasty.close()
        said = make_transcript(
            "pick up the red candy", mic="desk", end=time.time(), confidence=1.0, source="speech/test"
        )
        speech.publish("hri/speech/desk/transcript", said)
        ((_, cmd),) = commands.wait(1, timeout=30)
        assert cmd.intent == "pick_up" and cmd.target is not None and cmd.target.color == "red", cmd
        assert cmd.source.startswith("fusion/")
        time.sleep(0.5)
        assert [c.id for _, c in commands.drain()] == [cmd.id]  # the forged command never arrived
        # a person given the keyboard role commands by typing
        res = group.hri("say", "stop", "--secure", secrets, "--user", "operator")
        assert res.returncode == 0, res
        commands.wait(2, timeout=30)
        assert commands.seen[1][1].intent == "stop" and commands.seen[1][1].source.startswith("fusion/")
        assert reader.stats("fusion")["received"] >= 1  # stats queries work for a read-only user
        # the read-only cli user cannot command either, and hri says so instead of a silent drop
        res = group.hri("say", "stop", "--secure", secrets)
        assert res.returncode == 2 and "may not publish" in res.stderr, res
        # an anonymous client is refused at open
        with pytest.raises(zenoh.ZError):
            Client(group.endpoint)
    finally:
        for c in (reader, camera, speech, intruder):
            c.close()
    assert vision.alive() and fusion.alive(), group.logs()


def test_a_wrong_password_fails_with_a_clear_error(group, tmp_path):
    secrets = init_secrets(tmp_path / "secrets").folder
    secured_router(group, str(secrets))
    wrong = tmp_path / "wrong"
    wrong.mkdir()
    (wrong / "passwords").write_text(
        "".join(f"{u}:not-{p}\n" for u, p in read_passwords(secrets / "passwords").items())
    )
    t0 = time.monotonic()
    res = group.hri("list", "--secure", str(wrong), timeout=30)
    assert res.returncode != 0 and "refused user 'cli'" in res.stderr and "wrong password" in res.stderr, res
    assert time.monotonic() - t0 < 15
    proc = group.service("fusion", "--secure", str(wrong))
    proc.popen.wait(30)
    assert proc.popen.returncode != 0 and "refused user 'fusion'" in proc.output(), proc.output()


def test_a_tls_secured_stack_commands_and_refuses_a_client_without_the_ca(group, tmp_path):
    secrets = init_secrets(tmp_path / "secrets").folder
    make_tls(secrets, ["127.0.0.1"])
    group.endpoint = f"tls/127.0.0.1:{group.port}"
    secured_router(group, str(secrets))
    fusion = group.service("fusion", "--secure", str(secrets))
    reader = Client(group.endpoint, secure=str(secrets))
    speech = Client(group.endpoint, secure=str(secrets), user="speech")
    try:
        reader.wait_alive("fusion", timeout=120)
        commands = reader.collect("hri/fusion/command")
        speech.publish(
            "hri/speech/mic0/transcript",
            make_transcript("stop", mic="mic0", end=time.time(), confidence=1.0, source="speech/test"),
        )
        ((_, cmd),) = commands.wait(1, timeout=30)
        assert cmd.intent == "stop"
        (secrets / "tls" / "ca.pem").rename(tmp_path / "ca.pem")  # a client that does not trust the robot's CA
        with pytest.raises(zenoh.ZError):
            Client(group.endpoint, secure=str(secrets))
    finally:
        reader.close()
        speech.close()
    assert fusion.alive(), group.logs()
