"""3-D pointing rays (services/gesture/space.py): a known arm geometry rendered into a synthetic depth image gives
a known ray and a known point on the floor; the plane fit on real RGB-D frames (YCB-Video, RealSense) puts the hit
on the table measured by the depth itself."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from common.schema import CameraInfo, DepthFrame
from services.gesture.space import (
    DepthView,
    FrameRays,
    Lifted,
    arm_ray3d,
    depth_view,
    fit_plane,
    fit_planes,
    hand_ray3d,
    surface_hit,
    surface_meeting,
    to_wire,
    torso_point,
)
from testkit.images import read_image
from testkit.shared import shared_path

W, H, F, CX, CY = 640, 480, 600.0, 320.0, 240.0
CAMERA_HEIGHT = 0.7  # m above the floor, the camera level: the floor is the plane y = 0.7 (seen from 1.75 m)
WALL = 6.0


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def project(p):
    return np.array([p[0] * F / p[2] + CX, p[1] * F / p[2] + CY])


def floor_and_wall() -> np.ndarray:
    """Depth (m) of the floor below a level camera, and a wall 6 m away."""
    v = np.arange(H, dtype=float)[:, None].repeat(W, axis=1)
    with np.errstate(divide="ignore"):
        floor = np.where(v > CY, CAMERA_HEIGHT * F / (v - CY), np.inf)
    return np.minimum(floor, WALL).astype(np.float32)


def paint(depth: np.ndarray, p: np.ndarray, radius: int) -> None:
    u, v = project(p)
    cv2.circle(depth, (int(round(u)), int(round(v))), radius, float(p[2]), -1)


class Person:
    """A person 3 m away (eyes 1.65 m above the floor), right arm straight from the shoulder towards a point on
    the floor 2.2 m from the camera."""

    def __init__(self, target=(-0.6, CAMERA_HEIGHT, 2.2)):
        self.target = np.array(target)
        self.eyes = np.array([0.25, -0.95, 3.0])
        self.shoulder = np.array([0.1, -0.7, 3.0])  # the person's right shoulder (image left: they face us)
        u = unit(self.target - self.shoulder)
        self.elbow, self.wrist, self.tip = (self.shoulder + r * u for r in (0.3, 0.55, 0.7))
        self.hips = np.array([[0.45, -0.2, 3.0], [0.1, -0.2, 3.0]])

    def depth(self, eyes=True, tip=True, arm=True, torso=True) -> np.ndarray:
        d = floor_and_wall()
        if torso:
            a, b = project(np.array([0.05, -0.75, 3.0])), project(np.array([0.5, -0.1, 3.0]))
            cv2.rectangle(d, tuple(int(c) for c in a), tuple(int(c) for c in b), 3.0, -1)
        if eyes:
            paint(d, self.eyes, 12)
        if arm:
            for p in (self.elbow, self.wrist):
                paint(d, p, 6)
        if tip:
            paint(d, self.tip, 5)
        return d

    def pose(self) -> np.ndarray:
        """33 x [x px, y px, visibility]; unset points invisible."""
        p = np.zeros((33, 3))
        left_shoulder = self.shoulder + [0.35, 0, 0]
        points = {
            2: self.eyes + [0.03, 0, 0],
            5: self.eyes - [0.03, 0, 0],
            11: left_shoulder,
            12: self.shoulder,
            14: self.elbow,
            16: self.wrist,
            20: self.tip,
            23: self.hips[0],
            24: self.hips[1],
            13: left_shoulder + [0, 0.3, 0],
            15: left_shoulder + [0, 0.55, 0],
        }
        for i, q in points.items():
            p[i] = [*project(q), 0.99]
        return p

    def world(self) -> np.ndarray:
        """MediaPipe-style world landmarks: metres, origin between the hips."""
        w = np.zeros((33, 3))
        left_shoulder = self.shoulder + [0.35, 0, 0]
        for i, q in {
            2: self.eyes + [0.03, 0, 0],
            5: self.eyes - [0.03, 0, 0],
            11: left_shoulder,
            12: self.shoulder,
            16: self.wrist,
            20: self.tip,
            23: self.hips[0],
            24: self.hips[1],
        }.items():
            w[i] = q
        return w - self.hips.mean(axis=0)


def view(depth: np.ndarray) -> DepthView:
    return DepthView(depth, F, F, CX, CY, "cam_optical")


def floor_point(origin, direction) -> np.ndarray:
    t = (CAMERA_HEIGHT - origin[1]) / direction[1]
    return origin + t * direction


def angle_deg(a, b) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(unit(a) @ unit(b))))))


def test_eye_fingertip_ray_and_its_floor_hit():
    person = Person()
    v = view(person.depth())
    ray = arm_ray3d(v, person.pose(), "right")
    assert ray.method == "eye_fingertip"
    expected = unit(person.tip - person.eyes)
    assert angle_deg(ray.direction, expected) < 1.0
    assert np.linalg.norm(ray.origin - person.eyes) < 0.03
    hit = surface_hit(v, ray)
    truth = floor_point(person.eyes, expected)
    assert hit is not None and abs(hit[1] - CAMERA_HEIGHT) < 0.02  # on the floor
    assert np.linalg.norm(hit - truth) < 0.05, (hit, truth)


def test_forearm_when_the_eyes_have_no_depth_and_shoulder_wrist_without_the_elbow():
    person = Person()
    depth = person.depth(eyes=False)
    paint(depth, person.eyes, 12)
    cv2.circle(depth, tuple(int(c) for c in project(person.eyes)), 12, 0.0, -1)  # a hole where the face is
    ray = arm_ray3d(view(depth), person.pose(), "right")
    assert ray.method == "forearm"
    assert angle_deg(ray.direction, person.wrist - person.elbow) < 2.0
    pose = person.pose()
    pose[14, 2] = 0.1  # elbow unseen
    ray = arm_ray3d(view(depth), pose, "right")
    assert ray.method == "shoulder_wrist"
    assert angle_deg(ray.direction, person.wrist - person.shoulder) < 2.0
    hit = surface_hit(view(depth), ray)
    assert np.linalg.norm(hit - person.target) < 0.08  # the arm points at the target itself


def test_a_fingertip_whose_window_sees_the_wall_is_not_used():
    person = Person()
    ray = arm_ray3d(view(person.depth(tip=False)), person.pose(), "right")  # the tip reads the floor/wall behind
    assert ray.method == "forearm"


def test_world_landmarks_placed_at_the_torso_when_the_arm_has_no_depth():
    person = Person()
    depth = person.depth(tip=False, arm=False, eyes=False)
    v = view(depth)
    torso = torso_point(v, person.pose())
    assert torso is not None and abs(torso[2] - 3.0) < 0.01
    for p in (person.tip, person.wrist, person.elbow):  # holes at the arm: no depth there at all
        cv2.circle(depth, tuple(int(c) for c in project(p)), 8, 0.0, -1)
    cv2.circle(depth, tuple(int(c) for c in project(person.eyes)), 14, 0.0, -1)
    assert arm_ray3d(v, person.pose(), "right") is None
    ray = arm_ray3d(v, person.pose(), "right", world=person.world())
    assert ray.method == "world_landmarks"
    assert angle_deg(ray.direction, person.tip - person.eyes) < 1.0
    assert np.linalg.norm(ray.origin - person.eyes) < 0.1
    hit = surface_hit(v, ray)
    assert np.linalg.norm(hit - floor_point(person.eyes, unit(person.tip - person.eyes))) < 0.15


def test_index_finger_ray_of_a_hand_alone():
    depth = floor_and_wall()
    mcp, tip = np.array([0.0, 0.1, 0.8]), np.array([0.03, 0.13, 0.74])  # a finger pointing down-forward-left
    hand = np.zeros((21, 2))
    hand[5], hand[8], hand[7] = project(mcp), project(tip), project((mcp + 2 * tip) / 3)
    for a in np.linspace(0.0, 1.0, 30):  # the finger: a row of 8 px discs from knuckle to tip
        paint(depth, mcp + a * (tip - mcp), 4)
    ray = hand_ray3d(view(depth), hand)
    assert ray.method == "index_finger"
    assert angle_deg(ray.direction, tip - mcp) < 10.0  # a 7 cm finger: its direction is rough


def test_frame_rays_give_the_wire_ray_with_its_hit():
    person = Person()
    rays = FrameRays(view(person.depth()), person.pose(), None)
    wire = rays.arm("right")
    assert wire.method == "eye_fingertip" and wire.frame_id == "cam_optical" and wire.hit is not None
    assert abs(wire.hit[1] - CAMERA_HEIGHT) < 0.02 and wire.hit_in_view is True
    hanging = rays.arm("left")  # no fingertip in view: the forearm, straight down
    assert hanging.method == "forearm" and angle_deg(hanging.direction, [0, 1, 0]) < 2.0
    assert FrameRays(view(person.depth()), None, None).arm("right") is None


def test_a_floor_point_below_the_image_is_given_out_of_view():
    """Issue #31: the person points at the floor 1.2 m from the camera, nearer than the floor the camera sees (from
    1.75 m on): the ray meets the seen floor's plane there, outside the image, `hit_in_view` false. Up is the
    person's torso axis (the torso has depth)."""
    person = Person(target=(-0.3, CAMERA_HEIGHT, 1.2))
    assert project(person.target)[1] > H  # below the image
    wire = FrameRays(view(person.depth()), person.pose(), None).arm("right")
    assert wire is not None and wire.method == "eye_fingertip" and wire.hit is not None
    assert wire.hit_in_view is False
    assert abs(wire.hit[1] - CAMERA_HEIGHT) < 0.02
    expected = floor_point(np.array(wire.origin), np.array(wire.direction))
    assert np.linalg.norm(np.array(wire.hit) - expected) < 0.02
    assert wire.hit[2] < CAMERA_HEIGHT * F / (H - CY)  # nearer than any floor the camera sees


def test_no_depth_no_ray_and_no_hit():
    person = Person()
    v = view(np.zeros((H, W), np.float32))
    assert arm_ray3d(v, person.pose(), "right") is None
    ray = arm_ray3d(view(person.depth()), person.pose(), "right")
    assert surface_hit(v, ray) is None
    up = type(ray)(ray.origin, unit([0.0, -1.0, 0.2]), ray.method, ray.reach)  # at the ceiling: nothing there
    assert surface_hit(view(person.depth()), up) is None


# ---------------------------------------------------------------------------
# Depth frames off the wire
# ---------------------------------------------------------------------------
def depth_frame(raw: np.ndarray, scale: float, png: bool) -> DepthFrame:
    h, w = raw.shape
    info = CameraInfo(width=w, height=h, k=[F, 0, CX, 0, F, CY, 0, 0, 1], frame_id="cam_optical")
    data = cv2.imencode(".png", raw)[1].tobytes() if png else raw.astype("<u2").tobytes()
    return DepthFrame(
        stamp=1.0,
        source="camera/test",
        seq=0,
        cam="cam",
        width=w,
        height=h,
        encoding="16UC1",
        compression="png" if png else "none",
        depth_scale=scale,
        camera_info=info,
        data=data,
    )


def test_depth_view_reads_raw_and_png_alike():
    raw = (np.arange(H * W, dtype=np.uint32).reshape(H, W) % 5000).astype(np.uint16)
    a = depth_view(depth_frame(raw, 0.001, png=False))
    b = depth_view(depth_frame(raw, 0.001, png=True))
    assert np.array_equal(a.metres, b.metres)
    assert a.metres[0, 1234 % W] == pytest.approx((1234 % W) * 0.001, abs=1e-6)
    assert a.frame_id == "cam_optical" and a.fx == F


# ---------------------------------------------------------------------------
# Real frames: the table plane
# ---------------------------------------------------------------------------
YCB_K = (1066.778, 1067.487, 312.9869, 241.3109)


def ycb_view(name: str) -> DepthView:
    depth = read_image(str(shared_path(f"data/rgbd/ycb_video/{name}-depth.png")), cv2.IMREAD_UNCHANGED)
    return DepthView(depth.astype(np.float32) * 1e-4, *YCB_K, "ycb_optical")


def realsense_view() -> DepthView:
    data = np.load(shared_path("data/rgbd/realsense_tabletop/realsense_frame.npz"))
    fx, fy, cx, cy = (float(v) for v in data["intrinsics"])
    return DepthView(data["depth"].reshape(720, 1280).astype(np.float32) * 1e-3, fx, fy, cx, cy, "rs_optical")


class _Ray:
    def __init__(self, origin, direction, reach=0.3):
        self.origin, self.direction, self.reach, self.method = np.asarray(origin, float), unit(direction), reach, "t"


@pytest.mark.parametrize(
    "frame,pixels",
    [
        ("ycb", [(600, 440), (60, 420), (560, 330), (120, 300), (400, 400)]),
        ("realsense", [(1000, 400), (200, 500), (900, 600), (150, 150)]),
    ],
)
def test_pointing_at_the_table_hits_the_table_where_the_depth_says(frame, pixels):
    """A ray from a virtual eye above the camera towards a table pixel meets the fitted plane within 2 cm of that
    pixel's own measured 3-D point (an independent back-projection of the raw depth)."""
    v = ycb_view("000002") if frame == "ycb" else realsense_view()
    eye = np.array([0.1, -0.4, 0.1])
    for px in pixels:
        z = v.depth_at(*px)
        assert z is not None, px
        measured = v.back_project(*px, z)
        hit = surface_hit(v, _Ray(eye, measured - eye))
        assert hit is not None, px
        assert np.linalg.norm(hit - measured) < 0.02, (px, hit, measured)


def test_the_table_plane_of_a_real_frame_fits_its_points():
    v = ycb_view("000004")
    cloud = v.cloud()
    near = cloud[cloud[:, 2] < 1.2]  # the table top and what stands on it (the room is farther)
    plane = fit_plane(near)
    assert plane is not None
    residual = plane.distance(plane.inliers)
    assert float(np.median(residual)) < 0.01
    assert len(plane.inliers) > 0.3 * len(near)


def test_a_ray_leaving_the_image_meets_the_table_out_of_view():
    """The real RealSense table-top frame (the camera looks down at the board: up is towards the camera, -z). A ray
    from above the table to a point of the table's plane 0.25 m beyond the image's bottom edge meets the table there,
    marked out of view; the same ray aimed inside the image meets it where the depth sees it, in view."""
    view = realsense_view()
    table = fit_planes(view.cloud())[0]
    normal = table.normal if table.normal[2] < 0 else -table.normal  # towards the camera
    up = np.array([0.0, 0.0, -1.0])
    edge = view.back_project(640, 719, float(view.depth_at(640, 700) or 0.0))
    edge = edge - (table.normal @ edge + table.offset) * table.normal  # onto the plane
    down_image = np.array([0.0, 1.0, 0.0]) - (np.array([0.0, 1.0, 0.0]) @ table.normal) * table.normal
    target = edge + 0.25 * down_image / np.linalg.norm(down_image)
    assert not (0 <= view.project(target)[1] < view.height)  # really outside the image
    origin = target + 0.6 * normal - 0.4 * down_image / np.linalg.norm(down_image)
    direction = (target - origin) / np.linalg.norm(target - origin)
    meeting = surface_meeting(view, Lifted(origin, direction, "eye_fingertip", 0.3), up=up)
    assert meeting is not None and not meeting.in_view
    assert np.linalg.norm(meeting.point - target) < 0.02
    wire = to_wire(Lifted(origin, direction, "eye_fingertip", 0.3), "rs_optical", meeting)
    assert wire.hit is not None and wire.hit_in_view is False
    seen = view.back_project(900, 600, float(view.depth_at(900, 600) or 0.0))  # the board
    inside = surface_meeting(view, Lifted(origin, (seen - origin) / np.linalg.norm(seen - origin), "forearm", 0.3))
    assert inside is not None and inside.in_view and np.linalg.norm(inside.point - seen) < 0.02
