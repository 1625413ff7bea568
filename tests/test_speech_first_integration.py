"""Speech first (issue #42) across real processes: vision eases while a SpeechDecoding notice says speech decodes,
and goes back to every frame when the decode ends (the speech side: tests/test_speech_integration.py counts the
notices a real decode publishes)."""

from __future__ import annotations

import time

import cv2
import pytest

from common.schema import Frame, SpeechDecoding
from testkit.harness import DATA, Client
from testkit.images import read_image

pytestmark = pytest.mark.integration
PERIOD = 2.0


def frame(jpeg: bytes, seq: int, width: int, height: int) -> Frame:
    return Frame(
        stamp=time.time(),
        source="test/cam",
        seq=seq,
        cam="cam0",
        width=width,
        height=height,
        encoding="jpeg",
        data=jpeg,
    )


def send_frames(client: Client, jpeg: bytes, size: tuple[int, int], first: int, count: int) -> None:
    """`count` frames at 10 fps."""
    for k in range(count):
        client.publish("hri/camera/cam0/frame", frame(jpeg, first + k, *size))
        time.sleep(0.1)


def test_vision_takes_a_frame_a_period_while_speech_decodes_and_every_frame_after(group) -> None:
    img = read_image(str(DATA / "demo" / "table.png"))
    jpeg = cv2.imencode(".jpg", img)[1].tobytes()
    size = (img.shape[1], img.shape[0])
    group.router()
    # a period of 2 s: on a loaded machine vision may serve a frame a second at nice 10, so 0.25 s would ease nothing
    group.service("vision", "--labels", str(DATA / "demo" / "labels.json"), f"--speech-first-period={PERIOD}")
    client = Client(group.endpoint)
    try:
        client.wait_alive("vision", timeout=60)
        client.wait_matched(["hri/camera/cam0/frame", "hri/speech/desk/decoding"])
        out = client.collect("hri/vision/cam0/objects")
        send_frames(client, jpeg, size, 0, 5)  # warm
        out.wait(1, timeout=30)
        time.sleep(0.5)
        out.drain()
        # a decode in progress (its notice renewed every second: a loaded machine may serve few frames a second),
        # frames at 10 fps until vision has eased some of them
        began, eased_count, sent = time.monotonic(), 0, 5
        while eased_count < 5 and time.monotonic() - began < 60:
            notice = SpeechDecoding(stamp=time.time(), source="test/speech", mic="desk", decoding=True)
            client.publish("hri/speech/desk/decoding", notice, realtime=True)
            send_frames(client, jpeg, size, sent, 10)
            sent += 10
            eased_count = client.stats("vision")["other"].get("eased_for_speech", 0)
        served = len([d for _, d in out.drain() if d.seq >= 5])  # the frames sent while decoding (not the warm ones)
        seconds = time.monotonic() - began
        assert eased_count >= 5
        assert served <= seconds / PERIOD + 2, (served, seconds)  # one a period at most, while easing
        done = SpeechDecoding(stamp=time.time(), source="test/speech", mic="desk", decoding=False)
        client.publish("hri/speech/desk/decoding", done, realtime=True)
        time.sleep(0.3)
        send_frames(client, jpeg, size, sent, 5)
        assert out.wait(1, timeout=30)  # served again
        time.sleep(0.5)
        assert client.stats("vision")["other"].get("eased_for_speech", 0) == eased_count  # nothing eased since
    finally:
        client.close()
