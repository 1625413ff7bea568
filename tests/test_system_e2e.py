"""The whole system as a user runs it: `hri up`, the demo on real data, a modality dying and coming back."""

import os
import signal
import subprocess
import sys
import time

import pytest

from common.schema import Clarification, FusedCommand
from hri.cli import make_transcript
from testkit.harness import DATA, ROOT, Client, Proc, free_port, requires_services, wait_for_port

pytestmark = pytest.mark.integration

TABLE = DATA / "demo" / "table.png"


def say(client: Client, text: str) -> None:
    client.publish(
        "hri/speech/kbd/transcript",
        make_transcript(text, mic="kbd", end=time.time(), confidence=0.95, source="test/kbd"),
    )


def next_result(results, timeout: float = 30.0):
    """The next command or clarification after those already seen."""
    n = len(results.seen) + 1
    return results.wait(n, timeout=timeout)[-1][1]


def descendants(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-eo", "pid=,ppid="], capture_output=True, text=True).stdout.split()
    children: dict[int, list[int]] = {}
    for child, parent in zip(out[0::2], out[1::2]):
        children.setdefault(int(parent), []).append(int(child))
    found, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            found.append(c)
            todo.append(c)
    return found


@requires_services("vision", "fusion")
def test_hri_up_runs_the_pipeline_and_stops_the_whole_group_cleanly():
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    up = Proc(
        "hri-up",
        [
            sys.executable,
            "-m",
            "hri.cli",
            "up",
            "--listen",
            endpoint,
            "--camera",
            str(TABLE),
            "--fps",
            "10",
            "--loop",
            "--speech-input",
            "none",
            "--no-gesture",
        ],
    )
    try:
        wait_for_port(port, timeout=60)
        client = Client(endpoint)
        try:
            deadline = time.monotonic() + 120
            while "all up" not in up.output():
                assert up.alive() and time.monotonic() < deadline, up.output()
                time.sleep(0.2)
            assert {s for s, _ in client.alive()} >= {"camera", "vision", "fusion"}
            children = descendants(up.pid)
            assert len(children) >= 4  # router, camera, vision, fusion
            results = client.collect("hri/fusion/**")
            time.sleep(1.0)
            say(client, "pick up the red one")
            result = next_result(results)
            assert isinstance(result, FusedCommand), result
            assert result.intent == "pick_up" and result.target is not None and result.target.color == "red"
        finally:
            client.close()
        code, took = up.terminate(timeout=15)
        assert code == 0, up.output()
        assert all(not os.path.exists(f"/proc/{pid}") for pid in children), "orphans left behind"
        assert "[camera ]" in up.output() and "[vision ]" in up.output()  # prefixed logs
    finally:
        up.kill()


@requires_services("vision", "gesture", "speech", "fusion")
def test_demo_runs_every_scenario_on_real_data():
    res = subprocess.run(
        [sys.executable, "-m", "demo", "--timeout", "30"], cwd=ROOT, capture_output=True, text=True, timeout=600
    )
    assert res.returncode == 0, res.stdout[-6000:] + res.stderr[-3000:]
    out = res.stdout
    assert "demo: 5 passed, 0 failed" in out
    assert "CLARIFICATION (ambiguous)" in out
    assert out.count("✔ COMMAND") == 4
    assert "COMMAND stop" in out


@requires_services("vision", "fusion")
def test_a_killed_modality_is_reported_missing_and_rejoins_when_restarted(group):
    group.router()
    group.service("camera", "--source", str(TABLE), "--fps", "10", "--loop")
    vision = group.service("vision")
    group.service("fusion")
    client = Client(group.endpoint)
    try:
        for name in ("camera", "vision", "fusion"):
            client.wait_alive(name, timeout=90)
        results = client.collect("hri/fusion/**")
        detections = client.collect("hri/vision/*/objects")

        def sees_red(_key, sample) -> bool:
            return any(o.color == "red" for o in sample.objects)

        detections.wait(1, timeout=90, where=sees_red)  # a condition, not a sleep: vision may start slowly
        say(client, "pick up the red one")
        first = next_result(results)
        assert isinstance(first, FusedCommand) and first.target is not None and first.target.color == "red"
        assert first.inputs["vision"] is not None

        os.killpg(vision.pid, signal.SIGKILL)
        vision.popen.wait(10)
        time.sleep(5.0)  # past the utterance window and fusion's look-back: no recent detections remain
        say(client, "pick up the red one")
        blind = next_result(results)
        # fusion still answers and says it cannot see, instead of acting on the stale objects
        assert isinstance(blind, Clarification) and blind.reason == "not_found", blind
        assert "can't see" in blind.question and not blind.candidates

        seen_before = len([d for d in detections.drain() if sees_red(*d)])
        group.service("vision")
        client.wait_alive("vision", timeout=90)
        detections.wait(seen_before + 1, timeout=90, where=sees_red)  # the restarted vision sees the red cup
        say(client, "pick up the red one")
        again = next_result(results)
        assert isinstance(again, FusedCommand) and again.target is not None and again.target.color == "red"
        assert again.inputs["vision"] is not None
    finally:
        client.close()
