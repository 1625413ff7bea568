"""A camera whose clock jumps back 10 minutes: vision, gesture and fusion follow its new timeline after the
documented run of frames (common/stamps.py), and fusion grounds a command in it."""

from __future__ import annotations

import time

import cv2
import pytest

from common.schema import Frame
from common.stamps import DEFAULT_RESET_RUN
from hri.cli import make_transcript
from testkit.harness import DATA, Client

pytestmark = pytest.mark.integration

TABLE = DATA / "demo" / "table.png"
JUMP_S = 600.0
PERIOD_S = 0.2  # the camera timeline: 5 fps


def test_services_follow_a_camera_clock_that_jumps_back_ten_minutes(group):
    group.router()
    procs = {
        "vision": group.service("vision", "--labels", str(DATA / "demo" / "labels.json")),
        "gesture": group.service("gesture"),
        "fusion": group.service("fusion"),
    }
    client = Client(group.endpoint)
    try:
        for name in procs:
            client.wait_alive(name, timeout=120)
        detections, hands = client.collect("hri/vision/cam0/objects"), client.collect("hri/gesture/cam0/hands")
        commands = client.collect("hri/fusion/command")
        img = cv2.imread(str(TABLE))
        data = cv2.imencode(".jpg", img)[1].tobytes()

        def frame(seq: int, stamp: float) -> Frame:
            return Frame(
                stamp=stamp,
                source="test/cam",
                seq=seq,
                cam="cam0",
                width=img.shape[1],
                height=img.shape[0],
                encoding="jpeg",
                data=data,
            )

        def publish_and_wait(seq: int, stamp: float, served: bool) -> None:
            """Lockstep (no frame is skipped for a newer one however slow the machine): publish, and if the
            frame should be served, wait for vision's and gesture's output for it."""
            client.publish("hri/camera/cam0/frame", frame(seq, stamp))
            if served:
                detections.wait(1, timeout=60, where=lambda k, s: s.seq == seq)
                hands.wait(1, timeout=60, where=lambda k, s: s.seq == seq)
            else:
                time.sleep(PERIOD_S)

        t0 = time.time()
        for i in range(5):  # the normal timeline
            publish_and_wait(i, t0 + i * PERIOD_S, served=True)
        back = time.time() - JUMP_S  # the camera's clock steps back 10 minutes
        jumped = 2 * DEFAULT_RESET_RUN
        for i in range(jumped):
            publish_and_wait(100 + i, back + i * PERIOD_S, served=i >= DEFAULT_RESET_RUN - 1)
        time.sleep(0.5)
        for name, col in (("vision", detections), ("gesture", hands)):
            new = [s for _, s in col.drain() if s.seq >= 100]
            # the first frame served on the new timeline is the last of the run, and every one after it
            assert [s.seq - 100 for s in new] == list(range(DEFAULT_RESET_RUN - 1, jumped)), (name, new)
            assert all(s.stamp < back + JUMP_S / 2 for s in new)
            stats = client.stats(name)
            assert stats["other"].get("timeline_reset") == 1, stats
            assert stats["rejected"].get("out_of_order") == DEFAULT_RESET_RUN - 1, stats
        # fusion follows too: a command spoken on the new timeline is grounded on the new timeline's detections
        said = make_transcript(
            "pick up the red candy", mic="kbd", end=back + jumped * PERIOD_S, confidence=1.0, source="test/kbd"
        )
        client.publish("hri/speech/kbd/transcript", said)
        ((_, cmd),) = commands.wait(1, timeout=30, where=lambda k, c: c.inputs.get("speech") == said.stamp)
        assert cmd.intent == "pick_up" and cmd.target is not None and cmd.target.color == "red", cmd
        assert back <= cmd.inputs["vision"] <= back + jumped * PERIOD_S, cmd.inputs
        assert client.stats("fusion")["other"].get("timeline_reset", 0) >= 1
        for proc in procs.values():
            assert proc.alive()
    finally:
        client.close()
