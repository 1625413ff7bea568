"""camera (real photos) -> gesture -> hri echo / events, as real processes."""

import math

import pytest

from testkit.harness import DATA, Client

pytestmark = pytest.mark.integration
RED_CANDY = (548.0, 132.0)  # centre of the red candy in data/demo/pointing.png (px)


@pytest.mark.parametrize("scene,gesture", [("pointing.png", "point"), ("stop.png", "open_palm")])
def test_camera_to_gesture_events(group, scene, gesture):
    group.router()
    group.service("gesture")
    client = Client(group.endpoint)
    try:
        client.wait_alive("gesture", timeout=60)
        events = client.collect("hri/gesture/*/event")
        group.service("camera", "--source", str(DATA / "demo" / scene), "--fps", "10", "--loop")
        ((_, start),) = events.wait(1, timeout=60, where=lambda k, e: e.phase == "start")
        assert start.gesture == gesture and start.start <= start.end and start.cam == "cam0"
        if gesture == "point":
            assert start.ray is not None and start.ray.direction[0] > 0.9 and 0 < start.ray.confidence <= 1
            to_candy = (RED_CANDY[0] - start.ray.origin[0], RED_CANDY[1] - start.ray.origin[1])
            cos = (to_candy[0] * start.ray.direction[0] + to_candy[1] * start.ray.direction[1]) / math.hypot(*to_candy)
            assert math.degrees(math.acos(min(1.0, cos))) < 8, (start.ray, "does not point at the red candy")
        hands = group.echo("hri/gesture/cam0/hands", count=2, timeout=30)
        assert all(len(h["hands"]) == 1 and len(h["hands"][0]["landmarks"]) == 21 for h in hands)
        assert hands[0]["hands"][0]["gesture"] == gesture
    finally:
        client.close()


def test_frames_without_hands_publish_an_empty_list(group):
    group.router()
    group.service("gesture")
    group.service("camera", "--source", str(DATA / "images" / "tabletop" / "smarties.png"), "--fps", "10", "--loop")
    hands = group.echo("hri/gesture/cam0/hands", count=3, timeout=60)
    assert [h["hands"] for h in hands] == [[], [], []]
