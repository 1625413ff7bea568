"""camera -> gesture -> Persons, as real processes (issue #33): a real clip of two people side by side and a real
photo of a person pointing."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import pytest

from common.schema import Hands, Persons
from testkit.harness import DATA, Client, ProcessGroup
from testkit.shared import shared_path
from tests.test_gesture_3d_integration import FRAME, F, synthetic_depth

pytestmark = pytest.mark.integration


def test_two_people_get_stable_ids_and_a_body_each(group: ProcessGroup) -> None:
    clip = shared_path("data/talking/comp_turns_lbax4n_sbwe5n.mp4")
    group.router()
    group.service("gesture", "--persons-every", "1")
    client = Client(group.endpoint)
    try:
        client.wait_alive("gesture", timeout=60)
        persons = client.collect("hri/gesture/*/persons")
        bodies = client.collect("hri/gesture/*/bodies")
        group.service("camera", "--source", str(clip), "--fps", "10", "--loop")
        got = persons.wait(8, timeout=120)
        samples = [p for _, p in got if isinstance(p, Persons)]
        assert all(len(s.persons) == 2 for s in samples)
        left = {min(s.persons, key=lambda p: p.bbox[0]).id for s in samples}
        right = {max(s.persons, key=lambda p: p.bbox[0]).id for s in samples}
        assert len(left) == 1 and len(right) == 1 and left != right, (left, right)
        assert all(p.has_body for s in samples for p in s.persons)
        _, last = bodies.wait(1, timeout=30, where=lambda k, b: len(b.bodies) == 2)[0]
        assert {b.person for b in last.bodies} == left | right
    finally:
        client.close()


def test_a_hand_carries_its_persons_id_and_a_close_up_hand_is_nobodys(group: ProcessGroup) -> None:
    """A real photo of a person with both hands up (HaGRID, ../shared/data/people): each hand names the one person;
    the demo's close-up pointing hand has no person in view: nil, never a guess."""
    photo = shared_path("data/people/call_0e022ee9-74fd-44fe-adad-60c11835e44f.jpg")
    group.router()
    group.service("gesture", "--persons-every", "1")
    client = Client(group.endpoint)
    try:
        client.wait_alive("gesture", timeout=60)
        hands = client.collect("hri/gesture/*/hands")
        persons = client.collect("hri/gesture/*/persons")
        group.service("camera", "--source", str(photo), "--fps", "5", "--loop")
        ((_, seen),) = persons.wait(1, timeout=60, where=lambda k, p: len(p.persons) == 1)
        ((_, frame),) = hands.wait(1, timeout=30, where=lambda k, h: h.seq == seen.seq)
        assert len(frame.hands) == 2 and {h.person for h in frame.hands} == {seen.persons[0].id}
        assert sorted(seen.persons[0].hands) == sorted(h.hand for h in frame.hands)
        group.service(
            "camera", "--source", str(DATA / "demo" / "pointing.png"), "--fps", "5", "--loop", "--cam", "cam1"
        )
        ((_, close_up),) = hands.wait(1, timeout=60, where=lambda k, h: h.cam == "cam1" and len(h.hands) == 1)
        assert isinstance(close_up, Hands) and close_up.hands[0].person is None
    finally:
        client.close()


def test_with_depth_a_person_has_a_position_in_metres_at_their_torso(group: ProcessGroup, tmp_path: Path) -> None:
    """A real photo of a person 4-5 m away (shared/data/pointing) with the documented synthetic depth of
    tests/test_gesture_3d_integration.py (a floor, the person standing on it): the person's `position` is a point
    of the depth image inside their box, in the intrinsics' frame."""
    photo = shared_path("data/pointing/room_woman_0126_t3_right_arm_to_image_left.png")
    bgr = cv2.imread(str(photo))
    assert bgr is not None
    h, w = bgr.shape[:2]
    depth = synthetic_depth(bgr)
    folder = tmp_path / "rgbd"
    folder.mkdir()
    cv2.imwrite(str(folder / "room-color.png"), bgr)
    cv2.imwrite(str(folder / "room-depth.png"), depth)
    intrinsics = {"width": w, "height": h, "fx": F, "fy": F, "cx": w / 2, "cy": h / 2}
    (folder / "intrinsics.json").write_text(json.dumps({**intrinsics, "depth_scale": 0.001, "frame_id": FRAME}))
    group.router()
    group.service("gesture", "--persons-every", "1")
    client = Client(group.endpoint)
    try:
        client.wait_alive("gesture", timeout=90)
        persons = client.collect("hri/gesture/*/persons")
        group.service("camera", "--source", str(folder), "--fps", "5", "--loop")
        ((_, seen),) = persons.wait(1, timeout=90, where=lambda k, p: any(q.position for q in p.persons))
    finally:
        client.close()
    (person,) = [p for p in seen.persons if p.position]
    x, y, z = person.position or [0.0, 0.0, 0.0]
    u, v = F * x / z + w / 2, F * y / z + h / 2
    bx, by, bw, bh = person.bbox
    assert person.frame_id == FRAME and bx <= u <= bx + bw and by <= v <= by + bh, (u, v, person.bbox)
    assert abs(depth[int(v), int(u)] / 1000.0 - z) < 0.05, (depth[int(v), int(u)], z)
