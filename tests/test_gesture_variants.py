"""Pointing as people do it, and the signs that are not a point, on real landmark arrays (pure numpy); and the
hand + body combination that must never overrule a clear hand (issue #23).

Every hand here is a real MediaPipe hand (tests/data/landmarks/real_hands.json) reshaped the way a hand moves:
a finger bent at its joints, the thumb raised, the hand turned to show its edge, the index aimed at the camera
(foreshortened). MediaPipe never detects drawn hands, so the landmark path is tested on real photos elsewhere
(tests/test_gesture.py, tests/test_gesture_photos.py)."""

import math

import numpy as np
import pytest

from services.gesture.body import arm, raised_hand
from services.gesture.rules import classify, finger_states, palm_size
from services.gesture.temporal import GestureTracker, body_scale, close_up, fuse_arms
from testkit.hands import RIGHT_OUT, H, W, fold_index, hand_at, person, real, rotate, run, starts

INDEX, MIDDLE, RING, LITTLE = 5, 9, 13, 17


def bend(p: np.ndarray, mcp: int, degrees: float) -> np.ndarray:
    """Bend one finger by `degrees` at each of its three joints (MCP, PIP, DIP), towards the thumb side's normal."""
    q = p.copy()
    a = math.radians(degrees)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    for joint in (mcp, mcp + 1, mcp + 2):
        q[joint + 1 : mcp + 4] = (q[joint + 1 : mcp + 4] - q[joint]) @ rot.T + q[joint]
    return q


def raise_thumb(p: np.ndarray) -> np.ndarray:
    """The thumb straightened out from its base, away from the index knuckle (the 'pistol' hand)."""
    q = p.copy()
    out = q[2] - q[INDEX]
    out /= np.linalg.norm(out)
    for j in (3, 4):
        q[j] = q[j - 1] + out * np.linalg.norm(p[j] - p[j - 1]) * 1.3
    return q


def edge_on(p: np.ndarray, squeeze: float = 0.35) -> np.ndarray:
    """The hand turned about its long axis (wrist -> middle knuckle) to show its edge: widths shrink."""
    axis = p[MIDDLE] - p[0]
    axis /= np.linalg.norm(axis)
    normal = np.array([-axis[1], axis[0]])
    q = p - p[0]
    along, across = q @ axis, q @ normal
    return np.outer(along, axis) + np.outer(across * squeeze, normal) + p[0]


def aim_index_at_camera(p: np.ndarray, shrink: float = 0.3) -> np.ndarray:
    """The index finger aimed toward the camera: its image shrinks toward its knuckle along its own line."""
    q = p.copy()
    q[INDEX + 1 : INDEX + 4] = p[INDEX] + (p[INDEX + 1 : INDEX + 4] - p[INDEX]) * shrink
    return q


POINT = real("point_right")
PALM = real("open_palm_up")


# -- pointing variants ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "variant",
    [
        "plain",
        "thumb raised",
        "edge on",
        "edge on, thumb raised",
        "back (mirrored)",
        "index at the camera",
        "index at the camera, thumb raised",
    ],
)
@pytest.mark.parametrize("degrees", [0, 90, 200, 300])
def test_pointing_variants_point_in_any_direction(variant, degrees):
    p = {
        "plain": POINT,
        "thumb raised": raise_thumb(POINT),
        "edge on": edge_on(POINT),
        "edge on, thumb raised": edge_on(raise_thumb(POINT)),
        "back (mirrored)": rotate(POINT, 0, flip=True),
        "index at the camera": aim_index_at_camera(POINT),
        "index at the camera, thumb raised": aim_index_at_camera(raise_thumb(POINT)),
    }[variant]
    assert classify(rotate(p, degrees)) == "point", variant


def test_an_index_aimed_at_the_camera_too_short_to_see_is_no_point():
    assert classify(aim_index_at_camera(POINT, 0.1)) != "point"


# -- the signs that are not a point --------------------------------------------------------------------------
def copy_finger_shape(p: np.ndarray, donor: np.ndarray, source: int, target: int) -> np.ndarray:
    """Finger `target` of `p` takes the shape of finger `source` of `donor` (relative to its own knuckle)."""
    q = p.copy()
    for j in (1, 2, 3):
        q[target + j] = p[target] + (donor[source + j] - donor[source])
    return q


SIGNS = {
    "call me": lambda: raise_thumb(copy_finger_shape(fold_index(POINT), POINT, INDEX, LITTLE)),
    "peace / V": lambda: copy_finger_shape(POINT, POINT, INDEX, MIDDLE),
    "rock": lambda: copy_finger_shape(POINT, POINT, INDEX, LITTLE),
    "relaxed hand": lambda: bend(bend(bend(bend(PALM, INDEX, 22), MIDDLE, 28), RING, 30), LITTLE, 30),
    "index out, others relaxed": lambda: bend(bend(bend(PALM, MIDDLE, 28), RING, 30), LITTLE, 30),
}


@pytest.mark.parametrize("sign", sorted(SIGNS))
@pytest.mark.parametrize("degrees", [0, 135, 270])
@pytest.mark.parametrize("view", ["front", "edge on", "mirrored"])
def test_signs_that_are_not_a_point(sign, degrees, view):
    p = SIGNS[sign]()
    p = {"front": p, "edge on": edge_on(p, 0.5), "mirrored": rotate(p, 0, flip=True)}[view]
    assert classify(rotate(p, degrees)) not in ("point", "open_palm"), (sign, finger_states(p))


def test_the_relaxed_fingers_are_bent_but_not_folded_over():
    """What makes the relaxed hands above not a point: the other fingertips stay beyond their middle joints."""
    p = SIGNS["index out, others relaxed"]()
    states = finger_states(p)
    assert states[0] == "extended" and states[1:] != ["extended"] * 3
    for mcp in (MIDDLE, RING, LITTLE):
        assert np.linalg.norm(p[mcp + 3] - p[0]) > np.linalg.norm(p[mcp + 1] - p[0])


# -- hand + body: a clear hand is never overruled ------------------------------------------------------------
def test_a_close_up_upright_palm_on_a_pointing_arm_stays_a_stop():
    """The regression of issue #23: a palm close to the camera, a skeleton whose arm 'points' and whose torso says
    the palm is low (not raised). Before: the resting rule cleared the palm and the arm made it a point."""
    body = person(right_arm=RIGHT_OUT)
    palm = hand_at(PALM, (140, 300), 160)  # wrist below the torso's middle: 'not raised' for that skeleton
    assert close_up(palm_size(palm.landmarks), body)
    assert starts(run(GestureTracker(), [([palm], body)] * 6)) == [("open_palm", "right", None)]


def test_an_open_palm_never_becomes_a_point():
    """A resting palm (not a close-up) on a pointing arm is no stop; it is not a point either."""
    body = person(right_arm=RIGHT_OUT)
    palm = hand_at(rotate(PALM, 180), (140, 190), 25)  # fingers down: not raised
    assert not close_up(25, body)
    assert starts(run(GestureTracker(), [([palm], body)] * 6)) == []


@pytest.mark.parametrize("sign", ["call me", "peace / V", "rock"])
@pytest.mark.parametrize("palm_px", [20, 60])
def test_a_sign_on_a_pointing_arm_is_not_a_point(sign, palm_px):
    body = person(right_arm=RIGHT_OUT)
    hand = hand_at(SIGNS[sign](), (140, 190), palm_px)
    assert arm(body, "right", W, H).pointing
    assert [s for s in starts(run(GestureTracker(), [([hand], body)] * 6)) if s[0] == "point"] == []


def test_a_small_unreadable_hand_on_a_pointing_arm_still_points_with_the_arm():
    """What the body stage is for: at room distance the hand is a few pixels of folded fingers (no class)."""
    body = person(right_arm=RIGHT_OUT)
    blob = aim_index_at_camera(fold_index(POINT), 0.5)  # everything folded, thumb tucked: unreadable at 20 px
    blob[4] = blob[3]
    hand = hand_at(blob, (140, 190), 20)
    assert classify(hand.landmarks) in (None, "fist")
    if classify(hand.landmarks) is None:
        assert starts(run(GestureTracker(), [([hand], body)] * 6)) == [("point", "right", "body")]
    assert starts(run(GestureTracker(), [([], body)] * 6)) == [("point", "right", "body")]


def test_a_close_up_hand_turns_pose_only_points_off():
    """MediaPipe Pose guesses a skeleton around a hand held close to the camera (the nico_table photos: shoulders
    11-37 px wide for a 120 px palm): its 'pointing' arms are not a second, phantom point."""
    body = person(right_arm=RIGHT_OUT)
    pointing_hand = hand_at(rotate(POINT, 90), (450, 300), 160)
    cues = fuse_arms([pointing_hand], [arm(body, s, W, H) for s in ("left", "right")], body)
    assert [(c.raw, c.source) for c in cues] == [("point", "hand")]
    assert starts(run(GestureTracker(), [([pointing_hand], body)] * 6)) == [("point", "left", "hand")]


# -- a raised hand the hand stage cannot see (room distance) -------------------------------------------------
RAISED = ((250, 150), (245, 80), (244, 65))  # the person's right forearm up, the wrist 100 px above the shoulder
AT_THE_EAR = ((240, 230), (290, 160), (295, 150))  # "call me" / a phone: the hand at head height, beside the ear


def test_an_arm_raised_above_the_shoulder_with_no_hand_seen_is_a_stop():
    body = person(right_arm=RAISED)
    assert raised_hand(body, "right", body_scale(body)) and not arm(body, "right", W, H).pointing
    assert starts(run(GestureTracker(), [([], body)] * 6)) == [("open_palm", "right", None)]


def test_a_hand_at_the_ear_or_hanging_is_no_raised_hand():
    for right_arm in (AT_THE_EAR, None):
        body = person(right_arm=right_arm)
        assert not raised_hand(body, "right", body_scale(body))
        assert starts(run(GestureTracker(), [([], body)] * 6)) == []


def test_a_seen_hand_on_a_raised_arm_decides_and_an_occluded_arm_is_not_judged():
    body = person(right_arm=RAISED)
    rock = hand_at(SIGNS["rock"](), RAISED[1], 30)
    assert starts(run(GestureTracker(), [([rock], body)] * 6)) == []  # a sign, not a stop
    hidden = person(right_arm=RAISED)
    hidden[[12, 14, 16], 2] = 0.2
    assert not raised_hand(hidden, "right", body_scale(hidden))
