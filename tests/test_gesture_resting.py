"""Issue #31, the gesture side: hands held at the body are neither a point nor a grasp; an arm aimed at the camera
points when depth shows it straight; a ray leaving the image still meets the floor or table, marked out of view.

Real landmark arrays (tests/data/landmarks/real_bodies.json, written by `python -m testkit.record_bodies` from real
photos of ../shared/: which photo, crop and person are recorded beside each array) are fed to the pure rules; the
photos themselves go through MediaPipe in the last tests (skipped when ../shared is absent)."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from services.gesture.body import arm, held_at_body
from services.gesture.rules import classify, palm_size
from services.gesture.space import DepthView, FrameRays, lift_pose
from services.gesture.temporal import Event, GestureTracker, Observation, fuse_arms
from testkit.hands import fold_index, hand_at, real
from testkit.harness import ROOT
from testkit.shared import shared_path

BODIES = json.loads((ROOT / "tests" / "data" / "landmarks" / "real_bodies.json").read_text())


def body(name: str) -> np.ndarray:
    return np.array(BODIES[name]["pose"], dtype=float)


def hands(name: str) -> list[Observation]:
    return [Observation(h["hand"], 0.9, np.array(h["landmarks"], dtype=float)) for h in BODIES[name]["hands"]]


def size(name: str) -> tuple[int, int]:
    return BODIES[name]["width"], BODIES[name]["height"]


def run(
    observations: list[Observation], pose: np.ndarray | None, dims: tuple[int, int], joints3d: np.ndarray | None = None
) -> list[Event]:
    tracker, events = GestureTracker(), []
    for i in range(6):
        events += tracker.update(100 + i / 30, observations, pose, dims, joints3d)[1]
    return events


def started(events: list[Event]) -> list[str]:
    return [e.gesture for e in events if e.phase == "start"]


# -- resting hands: real landmark arrays ----------------------------------------------------------------------
def test_a_fist_resting_on_the_knee_of_a_seated_man_is_no_grasp():
    """coco_val2014_000000000241 (people_multi), the man seated on the couch: the hand stage reads one of the hands
    between his knees as a fist; both arms rest on the legs, so nothing starts (before issue #31: a `fist`)."""
    pose, seen = body("seated_hands_on_knees"), hands("seated_hands_on_knees")
    assert "fist" in [classify(o.landmarks) for o in seen]
    assert held_at_body(pose, "left") == held_at_body(pose, "right") == "on_leg"
    assert started(run(seen, pose, size("seated_hands_on_knees"))) == []
    assert "fist" in started(run(seen, None, size("seated_hands_on_knees")))  # without the body: the hand alone


def test_a_fist_hanging_at_the_side_is_no_grasp():
    """The standing man of the same photo: his relaxed left hand reads as a fist; it hangs along his thigh."""
    pose, seen = body("standing_fist_hanging"), hands("standing_fist_hanging")
    assert [classify(o.landmarks) for o in seen] == ["fist"]
    assert started(run(seen, pose, size("standing_fist_hanging"))) == []


def test_a_pointing_hand_on_a_forearm_folded_across_the_body_is_no_point():
    """none_00c84257 (people): the woman's right forearm is held across her belly (elbow 57 deg). The real pointing
    hand (demo/pointing.png) put at that wrist, at her palm size, classifies as a point but is held at the body."""
    pose = body("forearm_across_belly")
    wrist = pose[16, :2]
    palm = palm_size(hands("forearm_across_belly")[0].landmarks)
    pointing = hand_at(real("point_right"), wrist, palm, hand="right")
    assert classify(pointing.landmarks) == "point"
    assert held_at_body(pose, "right") == "folded"
    assert started(run([pointing], pose, size("forearm_across_belly"))) == []
    fist = hand_at(fold_index(real("point_right")), wrist, palm, hand="right")
    assert started(run([fist], pose, size("forearm_across_belly"))) == []


def test_an_extended_arm_still_points_and_a_raised_fist_is_still_a_grasp():
    """The control: the same real hands on an arm held out (the person of testkit.hands) still point / grasp."""
    from testkit.hands import RIGHT_OUT, person

    pose = person(right_arm=RIGHT_OUT)
    pointing = hand_at(real("point_right"), (140, 190), 25)
    fist = hand_at(fold_index(real("point_right")), (140, 190), 25)
    assert held_at_body(pose, "right") is None
    assert started(run([pointing], pose, (640, 480))) == ["point"]
    assert started(run([fist], pose, (640, 480))) == ["fist"]


def test_two_hands_held_together_are_neither_point_nor_grasp():
    """The real pointing hand and a fist made from it, wrists one palm apart (hands clasped at the chest): no point,
    no grasp, with or without a body; four palms apart, each is its own gesture."""
    pointing = hand_at(real("point_right"), (300, 260), 30, hand="right")
    fist = hand_at(fold_index(real("point_right")), (330, 262), 30, hand="left")
    assert [classify(o.landmarks) for o in (pointing, fist)] == ["point", "fist"]
    cues = fuse_arms([pointing, fist], [], None)
    assert [c.raw for c in cues] == [None, None]
    apart = hand_at(fold_index(real("point_right")), (420, 262), 30, hand="left")
    assert [c.raw for c in fuse_arms([pointing, apart], [], None)] == ["point", "fist"]


# -- an arm aimed at the camera, with depth --------------------------------------------------------------------
# lowcam_man_image8 (pointing): the real 2-D skeleton of a man aiming his right arm at the camera. No RGB-D frame of
# a person exists in ../shared, so its depth is a documented model: a pinhole with f = 520 px (the shoulders, 154 px
# apart, are then 0.385 m at 1.3 m), the body (torso, head) a plane at 1.3 m before a wall at 3 m, and the arm's
# joints at the depths that give an adult's segments (upper arm 0.30 m, forearm 0.26 m, wrist -> index 0.08 m),
# each the root nearer the camera: an arm reaching towards it.
F, CX, CY, BODY_Z, WALL_Z = 520.0, 230.0, 229.5, 1.3, 3.0
ARM_CHAIN = ((12, None, 0.0), (14, 12, 0.30), (16, 14, 0.26), (20, 16, 0.08))  # (joint, from, length m)


def _back(u: float, v: float, z: float) -> np.ndarray:
    return np.array([(u - CX) * z / F, (v - CY) * z / F, z])


def _nearer_depth(previous: np.ndarray, u: float, v: float, length: float) -> float:
    d = np.array([(u - CX) / F, (v - CY) / F, 1.0])
    a, b, c = float(d @ d), float(-2 * d @ previous), float(previous @ previous - length * length)
    return (-b - math.sqrt(max(b * b - 4 * a * c, 0.0))) / (2 * a)


def arm_at_camera_depth(pose: np.ndarray, dims: tuple[int, int]) -> DepthView:
    depth = np.full((dims[1], dims[0]), WALL_Z, dtype=np.float32)
    torso = pose[[11, 12, 24, 23], :2].astype(np.int32)
    cv2.fillPoly(depth, [torso], BODY_Z)
    cv2.circle(depth, tuple(int(c) for c in pose[0, :2]), 40, BODY_Z, -1)  # the head
    joints = {12: _back(pose[12, 0], pose[12, 1], BODY_Z)}
    for joint, parent, length in ARM_CHAIN[1:]:
        z = _nearer_depth(joints[parent], pose[joint, 0], pose[joint, 1], length)
        joints[joint] = _back(pose[joint, 0], pose[joint, 1], z)
    for (a, _, _), (b, _, _) in zip(ARM_CHAIN, ARM_CHAIN[1:]):  # the arm, drawn near to far so that near wins
        for t in np.linspace(0, 1, 30):
            p = joints[a] * (1 - t) + joints[b] * t
            u, v = p[0] * F / p[2] + CX, p[1] * F / p[2] + CY
            disc = np.zeros_like(depth)
            cv2.circle(disc, (int(round(u)), int(round(v))), 8, 1.0, -1)
            depth[(disc > 0) & (depth > p[2])] = p[2]
    return DepthView(depth, F, F, CX, CY, "lowcam_optical")


def test_an_arm_aimed_at_the_camera_points_when_depth_shows_it_straight():
    pose, dims = body("arm_at_camera"), size("arm_at_camera")
    flat = arm(pose, "right", *dims)
    assert flat.elbow_deg is not None and flat.elbow_deg < 150 and not flat.pointing  # crooked in the image
    assert started(run([], pose, dims)) == []
    view = arm_at_camera_depth(pose, dims)
    joints = lift_pose(view, pose)
    deep = arm(pose, "right", *dims, joints3d=joints)
    assert (
        deep.pointing
        and deep.elbow_deg is not None
        and deep.elbow_deg >= 140
        and deep.away_deg is not None
        and deep.away_deg > 60
    )
    assert started(run([], pose, dims, joints)) == ["point"]
    ray = FrameRays(view, pose, None).arm("right")
    assert ray is not None and ray.method == "eye_fingertip"
    assert ray.direction[2] < -0.5  # towards the camera, which the README says he points at


def test_a_hand_on_the_knee_stays_at_rest_in_3d():
    """The seated man's skeleton lifted with a depth model of sitting: the body at 2 m, the knees and hands 0.45 m
    in front of the hips, the elbows 0.2 m (f = 1000 px for the 2x upscaled crop: his shoulders are then 0.31 m
    apart). 3-D says the arms reach forward, away from the torso; the wrist at the knee says rest."""
    pose, dims = body("seated_hands_on_knees"), size("seated_hands_on_knees")
    forward = {13: 0.2, 14: 0.2, **dict.fromkeys((15, 16, 17, 18, 19, 20, 21, 22, 25, 26), 0.45)}
    f, cx, cy, z = 1000.0, dims[0] / 2, dims[1] / 2, 2.0
    joints = np.array([_lifted(pose[k, :2], z - forward.get(k, 0.0), f, cx, cy) for k in range(33)])
    for side in ("left", "right"):
        elbow, away = (
            arm(pose, side, *dims, joints3d=joints).elbow_deg,
            arm(pose, side, *dims, joints3d=joints).away_deg,
        )
        assert held_at_body(pose, side, joints) == "on_leg", (side, elbow, away)
        assert not arm(pose, side, *dims, joints3d=joints).pointing
    assert started(run(hands("seated_hands_on_knees"), pose, dims, joints)) == []


def _lifted(pixel: np.ndarray, z: float, f: float, cx: float, cy: float) -> np.ndarray:
    return np.array([(pixel[0] - cx) * z / f, (pixel[1] - cy) * z / f, z])


# -- through MediaPipe, on the real photos -------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["seated_hands_on_knees", "standing_fist_hanging", "forearm_across_belly"])
def test_resting_hands_on_the_real_photos_start_no_point_and_no_grasp(name: str) -> None:
    from services.gesture.landmarks import HandLandmarker, PoseLandmarker

    entry = BODIES[name]
    img = cv2.imread(str(shared_path(entry["source"].removeprefix("../shared/"))))
    assert img is not None, entry["source"]
    if entry["crop"]:
        x0, y0, x1, y1 = entry["crop"]
        img = img[y0:y1, x0:x1]
    if entry["upscale"] != 1.0:
        img = cv2.resize(img, None, fx=entry["upscale"], fy=entry["upscale"], interpolation=cv2.INTER_CUBIC)
    hand_stage, pose_stage, tracker = HandLandmarker("lite"), PoseLandmarker(), GestureTracker()
    events: list[Event] = []
    try:
        for i in range(6):
            events += tracker.update(
                i / 10, hand_stage.detect(img), pose_stage.detect(img), (img.shape[1], img.shape[0])
            )[1]
    finally:
        hand_stage.close()
        pose_stage.close()
    assert not {"point", "fist"} & set(started(events)), started(events)


# -- a hand of another person than the full-frame skeleton's, and a fist at the head (issue #31 follow-up) ---------
def run_with_others(
    observations: list[Observation], pose: np.ndarray | None, others: list[np.ndarray], dims: tuple[int, int]
) -> list[Event]:
    tracker, events = GestureTracker(), []
    for i in range(6):
        events += tracker.update(100 + i / 30, observations, pose, dims, None, others)[1]
    return events


def test_a_fist_on_the_knee_of_another_person_than_the_full_frame_skeleton_is_no_grasp() -> None:
    """coco_241's seated man when MediaPipe Pose's full-frame skeleton is the standing man's (as on the full photo):
    his real hands match no arm of the standing man, so the hand stage alone read `fist`. Given the seated man's own
    skeleton (the person stage's), his fist rests on his leg: nothing starts. The standing man's skeleton is put far
    to the right of the seated man's, as in the photo."""
    seated, seen = body("seated_hands_on_knees"), hands("seated_hands_on_knees")
    standing = body("standing_fist_hanging").copy()
    standing[:, 0] += 600.0  # beside him: none of its wrists is near the seated man's hands
    dims = (1100, 760)
    assert "fist" in started(run_with_others(seen, standing, [], dims))  # without his skeleton: a grasp
    assert started(run_with_others(seen, standing, [seated], dims)) == []
    assert started(run_with_others(seen, None, [seated], dims)) == []  # no full-frame skeleton at all


def test_another_persons_arm_never_makes_a_point_but_their_raised_fist_stays_a_grasp() -> None:
    """The control: the real pointing hand and fist on the arm held out of another person (testkit.hands) keep
    their own classes: the other person's arm judges rest, it does not invent or remove signs held up."""
    from testkit.hands import RIGHT_OUT, person

    other = person(right_arm=RIGHT_OUT)
    pointing = hand_at(real("point_right"), (140, 190), 25)
    fist = hand_at(fold_index(real("point_right")), (140, 190), 25)
    assert started(run_with_others([pointing], None, [other], (640, 480))) == ["point"]
    assert started(run_with_others([fist], None, [other], (640, 480))) == ["fist"]


def test_a_fist_at_the_head_is_no_grasp_but_beside_it_is() -> None:
    """The real fist (the demo's pointing hand with its index folded) at the face of a real skeleton (none_00c84257,
    at her palm size): a hand at the head (a phone, a "call me" sign the lite model folds, a hand scratching) is
    not a grasp sign. Four palms to the side of the head, at the same height, it is."""
    pose = body("forearm_across_belly")
    palm = palm_size(hands("forearm_across_belly")[0].landmarks)
    face = pose[[0, 7, 8], :2].mean(axis=0)
    at_face = hand_at(fold_index(real("point_right")), face + (0.0, palm), palm, hand="right")
    beside = hand_at(fold_index(real("point_right")), face + (4 * palm, palm), palm, hand="right")
    assert classify(at_face.landmarks) == classify(beside.landmarks) == "fist"
    assert started(run([at_face], pose, size("forearm_across_belly"))) == []
    assert started(run([beside], pose, size("forearm_across_belly"))) == ["fist"]
    assert started(run_with_others([at_face], None, [pose], size("forearm_across_belly"))) == []  # anyone's head


@pytest.mark.parametrize(
    "photo",
    ["people_multi/coco_val2014_000000000241.jpg", "people/call_172ba7f6-c6ba-4398-89a2-25375dccfefa.jpg"],
)
def test_the_two_resting_hands_left_start_nothing_through_the_service_path(photo: str) -> None:
    """The whole photos through the service's path (hands, pose, the person stage, the tracker;
    testkit.gesture_photos): coco_241's seated man's hand on his knee (his skeleton is the person stage's) and the
    "call" sign held at the ear that the lite hand model folds into a fist. Before: a `fist` start on each."""
    from testkit.gesture_photos import starts_on_photo

    assert starts_on_photo(shared_path(f"data/{photo}")) == []
