"""The profile's camera mount used (issue #43): a target's or a location's position in the camera's optical frame
(REP-103 optical: x right, y down, z forward) also given in the robot's base frame (REP-103 body: x forward, y left,
z up), and never when the profile does not place that camera (common/robot.py `in_base`, `with_base`)."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from common.robot import DEFAULT, in_base, mount_rotation, parse_profile, with_base
from common.schema import CameraMount, Location, Target
from testkit.room3d import FRAME, detections, hands, pointing_hand, step, thing
from testkit.scenarios import Scenario, run_in_process, say

LEVEL = [-math.pi / 2, 0.0, -math.pi / 2]  # the optical frame of a camera looking straight ahead (docs/robot.md)


def mount(xyz: list[float], rpy: list[float], frame_id: str = "cam0_optical") -> CameraMount:
    return CameraMount(parent="base_link", frame_id=frame_id, xyz=xyz, rpy=rpy)


def test_a_camera_pitched_30_degrees_down_sees_a_point_2_m_along_its_axis_on_the_floor_ahead():
    """1.2 m above the base origin, pitched 30 deg down (roll -(90 + 30) deg in the optical frame's rpy): the point
    2 m along the optical axis is 2 cos 30 = 1.732 m ahead and 2 sin 30 = 1 m lower, 0.2 m above the base."""
    down30 = mount([0.0, 0.0, 1.2], [-math.radians(120), 0.0, -math.pi / 2])
    assert in_base(down30, "cam0_optical", [0.0, 0.0, 2.0]) == pytest.approx([1.732, 0.0, 0.2], abs=1e-3)
    # a point 1 m right of the axis and 0.5 m below it in the image: to the robot's right (-y), lower still
    base = in_base(down30, "cam0_optical", [1.0, 0.5, 2.0])
    assert base is not None
    assert base[1] == pytest.approx(-1.0, abs=1e-4)
    assert base[0] == pytest.approx(2 * math.cos(math.radians(30)) - 0.5 * math.sin(math.radians(30)), abs=1e-4)
    assert base[2] == pytest.approx(1.2 - 2 * math.sin(math.radians(30)) - 0.5 * math.cos(math.radians(30)), abs=1e-4)


def test_a_level_camera_offset_sideways_and_a_camera_yawed_to_the_left():
    # level, 0.15 m ahead of the base origin, 0.3 m to its right, 0.6 m up: right in the image is the base's -y
    side = mount([0.15, -0.3, 0.6], LEVEL)
    assert in_base(side, "cam0_optical", [0.5, 0.1, 1.0]) == pytest.approx([1.15, -0.8, 0.5])
    # the same camera turned 90 deg to the robot's left (yaw +90 deg): its forward is the base's +y, its right +x
    left = mount([0.0, 0.0, 1.0], [-math.pi / 2, 0.0, 0.0])
    assert in_base(left, "cam0_optical", [0.0, 0.0, 2.0]) == pytest.approx([0.0, 2.0, 1.0], abs=1e-6)
    assert in_base(left, "cam0_optical", [0.5, 0.0, 2.0]) == pytest.approx([0.5, 2.0, 1.0], abs=1e-6)
    # yawed 45 deg right: 2 m ahead of it is sqrt(2) ahead and sqrt(2) to the right of the base
    right45 = mount([0.0, 0.0, 1.0], [-math.pi / 2, 0.0, -math.pi / 2 - math.pi / 4])
    assert in_base(right45, "cam0_optical", [0.0, 0.0, 2.0]) == pytest.approx([2**0.5, -(2**0.5), 1.0], abs=1e-4)


def test_the_rotation_is_tf2s_roll_pitch_yaw():
    """The same rotation the ROS 2 node puts on /tf_static (services/ros2/core.py `quaternion`), for an arbitrary
    roll, pitch and yaw: fusion's base positions and the robot's tf tree agree."""
    from services.ros2.core import quaternion

    rpy = [-1.9, 0.3, -1.2]
    q = quaternion(rpy)
    w, x, y, z = q.w, q.x, q.y, q.z
    from_quaternion = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    assert np.allclose(mount_rotation(rpy), from_quaternion, atol=1e-9)


def test_no_mount_or_another_frame_claims_no_base_position():
    level = mount([0.1, 0.0, 1.2], LEVEL)
    assert in_base(None, "cam0_optical", [0.0, 0.0, 2.0]) is None  # no mount: nothing is claimed
    assert in_base(level, "camera_color_optical_frame", [0.0, 0.0, 2.0]) is None  # a camera it does not place
    assert in_base(level, None, [0.0, 0.0, 2.0]) is None
    assert in_base(level, "cam0_optical", None) is None  # no depth, no position
    target = Target(id="b", label="bottle", bbox=[0, 0, 1, 1], center=[0, 0], score=0.9, cam="cam0")
    assert with_base(target, level) is target
    seen = msgspec.structs.replace(target, position=[0.0, 0.0, 2.0], frame_id="cam0_optical")
    assert with_base(seen, None) is seen
    placed = with_base(seen, level)
    assert placed.base == pytest.approx([2.1, 0.0, 1.2]) and placed.base_frame_id == "base_link"
    assert placed.position == seen.position and placed.frame_id == "cam0_optical"  # the optical position stays
    there = Location(x=1.0, y=2.0, cam="cam0", position=[-1.0, 1.2, 3.0], frame_id="cam0_optical")
    assert with_base(there, level).base == pytest.approx([3.1, 1.0, 0.0])
    assert DEFAULT.camera is None  # the default profile places no camera


PROFILE = f"""name = "head-camera"
[camera]
parent = "base_footprint"
frame_id = "{FRAME}"
xyz = [0.1, 0.0, 1.2]
rpy = [{LEVEL[0]}, 0.0, {LEVEL[2]}]
"""


def pick_up_the_pointed_bottle(profile=None) -> list:
    places = [[-0.8, 0.5, 2.4], [0.6, 0.5, 1.2]]
    objects = [thing("b0", "bottle", places[0]), thing("b1", "bottle", places[1])]
    steps = [step(t / 10, lambda s: detections(objects, stamp=s)) for t in range(-10, 20, 2)]
    steps += [step(t / 10, lambda s: hands(pointing_hand(np.array(places[0])), stamp=s)) for t in range(-10, 20)]
    steps.append(say(0.0, 0.8, "pick up that bottle"))
    return run_in_process(Scenario("3-D", sorted(steps, key=lambda s: s.t), []), profile=profile)


def test_fusion_gives_the_target_in_the_base_frame_with_a_mount_and_only_then():
    (cmd,) = pick_up_the_pointed_bottle(parse_profile(PROFILE))
    target = cmd.target
    # (-0.8, 0.5, 2.4) optical from a level camera at (0.1, 0, 1.2): 2.5 m ahead, 0.8 m left, 0.7 m up
    assert target.position == pytest.approx([-0.8, 0.5, 2.4]) and target.frame_id == FRAME
    assert target.base == pytest.approx([2.5, 0.8, 0.7]) and target.base_frame_id == "base_footprint"
    assert "; (2.50, 0.80, 0.70) m in base_footprint (x forward, y left, z up)" in cmd.prompt
    (plain,) = pick_up_the_pointed_bottle()
    assert plain.target.id == target.id and plain.target.base is None and plain.target.base_frame_id is None
    assert "base_footprint" not in plain.prompt and " m in base" not in plain.prompt


def test_go_there_gives_the_place_in_the_base_frame_too():
    """ "Go there" pointing at the floor: the location where the 3-D ray meets it, also in the base frame."""
    spot = np.array([0.2, 1.0, 2.0])  # on the floor 1 m below the camera, 2 m ahead, a little to its right
    bottle = [thing("b0", "bottle", [-0.8, 0.5, 2.4])]
    steps = [step(t / 10, lambda s: detections(bottle, stamp=s)) for t in range(-10, 20, 2)]
    steps += [step(t / 10, lambda s: hands(pointing_hand(spot, hit=spot), stamp=s)) for t in range(-10, 20)]
    steps.append(say(0.0, 0.6, "go there"))
    (cmd,) = run_in_process(Scenario("go", sorted(steps, key=lambda s: s.t), []), profile=parse_profile(PROFILE))
    assert cmd.intent == "go_to" and cmd.location is not None, cmd
    assert cmd.location.position == pytest.approx(spot.tolist(), abs=1e-3)
    # a level camera at (0.1, 0, 1.2): 2.1 m ahead, 0.2 m right, 1 m below the camera (0.2 m above the base origin)
    assert cmd.location.base == pytest.approx([2.1, -0.2, 0.2], abs=1e-3)
    assert cmd.location.base_frame_id == "base_footprint"
    assert "(2.10, -0.20, 0.20) m in base_footprint" in cmd.prompt
