"""Warm start (issue #41): the gesture process builds a camera's MediaPipe graphs before its first frame — at start for
the first camera, in the background (or ahead, --spare-graphs) for a new one — so that a camera's first frame is
answered and no frame waits for a graph to be built. Real process over Zenoh, a real hand photo."""

from __future__ import annotations

import time
from typing import Any

import cv2
import pytest

from common.schema import Frame, Hands
from testkit.harness import DATA, Client, ProcessGroup
from testkit.images import read_image

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]
STOP = DATA / "demo" / "stop.png"  # one open palm


def jpeg_frame(cam: str, seq: int) -> Frame:
    img = read_image(str(STOP))
    ok, data = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])
    assert ok
    h, w = img.shape[:2]
    return Frame(
        stamp=time.time(), source="camera/test", seq=seq, cam=cam, width=w, height=h, encoding="jpeg",
        data=data.tobytes(),
    )  # fmt: skip


def gauges(client: Client, timeout: float = 60.0) -> dict[str, Any]:
    """The gesture service's counters and gauges, once its worker has set the graph gauges (its first tick)."""
    deadline = time.monotonic() + timeout
    while True:
        other = client.stats("gesture")["other"]
        if "graph_sets_built" in other or time.monotonic() > deadline:
            return other
        time.sleep(0.2)


def first_hands(hands: Any, cam: str, timeout: float = 120.0) -> Hands:
    ((_, answer),) = hands.wait(1, timeout=timeout, where=lambda k, h: h.cam == cam)
    assert isinstance(answer, Hands)
    return answer


def start(group: ProcessGroup, *args: str) -> Client:
    group.router()
    group.service("gesture", *args)
    client = Client(group.endpoint)
    client.wait_alive("gesture", timeout=120)
    return client


def test_the_first_frame_of_the_first_camera_is_answered_by_graphs_built_at_start(group: ProcessGroup) -> None:
    client = start(group)
    try:
        before = gauges(client)
        assert before.get("graph_sets_built") == 1, f"one set of graphs built before the service was live: {before}"
        hands = client.collect("hri/gesture/*/hands")
        client.wait_matched(["hri/camera/first/frame"])
        client.publish("hri/camera/first/frame", jpeg_frame("first", 0))
        answer = first_hands(hands, "first")
        assert answer.seq == 0, "the camera's very first frame is answered"
        assert len(answer.hands) == 1 and len(answer.hands[0].landmarks) == 21, answer.hands
        after = gauges(client)
        assert after.get("graph_sets_built") == 1, f"no graph built on the frame path: {after}"
        assert "skipped_building_graphs" not in after, after
    finally:
        client.close()


def test_a_new_camera_is_served_once_its_graphs_are_built_and_others_go_on(group: ProcessGroup) -> None:
    """With no spare set, a second camera's graphs are built in the background: its frames are skipped (counted)
    until they exist, then answered; the first camera is answered all along."""
    client = start(group)
    try:
        hands = client.collect("hri/gesture/*/hands")
        client.wait_matched(["hri/camera/one/frame", "hri/camera/two/frame"])
        client.publish("hri/camera/one/frame", jpeg_frame("one", 0))
        first_hands(hands, "one")
        seq = 1
        while not [h for _, h in hands.drain() if h.cam == "two"]:
            assert seq < 600, "the new camera was never answered"
            client.publish("hri/camera/two/frame", jpeg_frame("two", seq))
            client.publish("hri/camera/one/frame", jpeg_frame("one", seq))
            seq += 1
            time.sleep(0.2)
        two = [h.seq for _, h in hands.seen if h.cam == "two"]
        one_while_building = [h.seq for _, h in hands.seen if h.cam == "one" and 0 < h.seq <= two[0]]
        other = gauges(client)
        assert other.get("skipped_building_graphs", 0) >= 1, f"the new camera's first frame waited for nothing: {other}"
        assert two[0] > 1 and other.get("graph_sets_built") == 2, (two, other)  # its first (seq 1) skipped
        assert one_while_building, f"camera one was not answered while two's graphs were built: {hands.seen}"
    finally:
        client.close()


def test_a_spare_set_serves_a_new_camera_from_its_first_frame(group: ProcessGroup) -> None:
    client = start(group, "--spare-graphs", "1")
    try:
        hands = client.collect("hri/gesture/*/hands")
        client.wait_matched(["hri/camera/one/frame", "hri/camera/two/frame"])
        client.publish("hri/camera/one/frame", jpeg_frame("one", 0))
        first_hands(hands, "one")
        deadline = time.monotonic() + 120
        while gauges(client).get("graph_sets_ready", 0) < 1:  # the spare taken by camera one is built again
            assert time.monotonic() < deadline, "no spare set was built again"
            time.sleep(0.2)
        client.publish("hri/camera/two/frame", jpeg_frame("two", 0))
        assert first_hands(hands, "two").seq == 0
        assert "skipped_building_graphs" not in gauges(client)
    finally:
        client.close()
