"""The gesture process with depth: a real photo of a person pointing (shared/data/pointing, 4-5 m away in a room,
the right arm pointing down to the image left) with a documented synthetic depth image, through camera -> gesture
over Zenoh. The depth is a floor plane seen by a camera pitched 30° down (2 m above it) and the person, found by
MediaPipe Pose in the test, standing on it at the depth of their feet. The Bodies and the point event must carry a
3-D ray in the intrinsics' frame whose hit lies on that floor."""

from __future__ import annotations

import json
import math
import time

import cv2
import numpy as np
import pytest

from testkit.harness import Client, requires_services
from testkit.images import read_image
from testkit.shared import shared_path

pytestmark = pytest.mark.integration

F, PITCH, HEIGHT = 900.0, math.radians(30.0), 2.0
FLOOR = np.array([0.0, math.cos(PITCH), math.sin(PITCH)])  # floor points p: p @ FLOOR == HEIGHT
FRAME = "room_camera_optical_frame"


def synthetic_depth(bgr: np.ndarray) -> np.ndarray:
    """uint16 mm: the floor, and the person (the hull of their pose landmarks, widened) at the depth of their feet."""
    from services.gesture.landmarks import PoseLandmarker

    h, w = bgr.shape[:2]
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = np.stack([(u - w / 2) / F, (v - h / 2) / F, np.ones_like(u)], axis=-1)
    along = rays @ FLOOR
    z = np.where(along > 1e-3, HEIGHT / np.maximum(along, 1e-3), 8.0)
    z = np.minimum(z, 8.0)  # the far wall
    poser = PoseLandmarker(video=False)
    try:
        pose = poser.detect(bgr)
    finally:
        poser.close()
    assert pose is not None, "MediaPipe Pose found nobody in the photo"
    seen = pose[pose[:, 2] >= 0.3, :2]
    feet = pose[[27, 28, 29, 30, 31, 32]]
    foot = feet[np.argmax(feet[:, 1]), :2]
    person_z = float(z[int(min(foot[1], h - 1)), int(foot[0])])
    hull = cv2.convexHull(seen.astype(np.int32))
    hull_mask = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(hull_mask, hull, 1)
    mask = cv2.dilate(hull_mask, np.ones((31, 31), np.uint8))
    z[mask > 0] = person_z
    return np.round(z * 1000).astype(np.uint16)


@requires_services("gesture")
def test_a_pointing_person_gets_a_3d_ray_that_meets_the_floor(group, tmp_path):
    photo = shared_path("data/pointing/room_woman_0126_t3_right_arm_to_image_left.png")
    bgr = read_image(str(photo))
    h, w = bgr.shape[:2]
    folder = tmp_path / "rgbd"
    folder.mkdir()
    cv2.imwrite(str(folder / "room-color.png"), bgr)
    cv2.imwrite(str(folder / "room-depth.png"), synthetic_depth(bgr))
    (folder / "intrinsics.json").write_text(
        json.dumps(
            {
                "width": w,
                "height": h,
                "fx": F,
                "fy": F,
                "cx": w / 2,
                "cy": h / 2,
                "depth_scale": 0.001,
                "frame_id": FRAME,
            }
        )
    )
    group.router()
    group.service("gesture")
    client = Client(group.endpoint)
    try:
        client.wait_alive("gesture", timeout=90)
        events = client.collect("hri/gesture/*/event")
        bodies = client.collect("hri/gesture/*/bodies")
        group.service("camera", "--source", str(folder), "--fps", "5", "--loop")
        ((_, start),) = events.wait(
            1, timeout=90, where=lambda k, e: e.gesture == "point" and e.ray is not None and e.ray.ray3d is not None
        )
        ((_, body),) = bodies.wait(
            1,
            timeout=30,
            where=lambda k, b: (
                bool(b.bodies) and b.bodies[0].right_ray is not None and b.bodies[0].right_ray.ray3d is not None
            ),
        )
    finally:
        client.close()
    for ray in (start.ray, body.bodies[0].right_ray):
        r3 = ray.ray3d
        assert r3.frame_id == FRAME and r3.method in ("eye_fingertip", "forearm", "shoulder_wrist"), r3
        assert r3.hit is not None, r3
        assert abs(float(np.dot(r3.hit, FLOOR)) - HEIGHT) < 0.03, r3.hit  # on the floor
        # the 3-D ray seen from the camera goes the way the 2-D ray does (both: down to the image left)
        o, d = np.array(r3.origin), np.array(r3.direction)
        a, b = o + 0.3 * d, o + 0.6 * d
        seen = np.array([F * b[0] / b[2] - F * a[0] / a[2], F * b[1] / b[2] - F * a[1] / a[2]])
        seen /= np.linalg.norm(seen)
        assert math.degrees(math.acos(min(1.0, float(seen @ np.array(ray.direction))))) < 15.0, (seen, ray.direction)


@requires_services("gesture")
def test_a_broken_depth_frame_is_counted_and_the_2d_rays_still_go_out(group):
    from common.schema import CameraInfo, DepthFrame, Frame

    bgr = read_image(str(shared_path("data/pointing/room_woman_0126_t3_right_arm_to_image_left.png")))
    h, w = bgr.shape[:2]
    png = cv2.imencode(".png", bgr)[1].tobytes()
    info = CameraInfo(width=w, height=h, k=[F, 0, w / 2, 0, F, h / 2, 0, 0, 1], frame_id=FRAME)
    group.router()
    proc = group.service("gesture")
    client = Client(group.endpoint)
    try:
        client.wait_alive("gesture", timeout=90)
        bodies = client.collect("hri/gesture/cam0/bodies")
        for seq in range(4):
            stamp = time.time()
            client.publish(
                "hri/camera/cam0/depth",
                DepthFrame(
                    stamp=stamp,
                    source="test/cam",
                    seq=seq,
                    cam="cam0",
                    width=w,
                    height=h,
                    encoding="16UC1",
                    compression="png",
                    depth_scale=0.001,
                    camera_info=info,
                    data=b"not a png at all",
                ),
            )
            client.publish(
                "hri/camera/cam0/frame",
                Frame(stamp=stamp, source="test/cam", seq=seq, cam="cam0", width=w, height=h, encoding="png", data=png),
            )
            time.sleep(0.5)
        ((_, body),) = bodies.wait(
            1, timeout=60, where=lambda k, b: bool(b.bodies) and b.bodies[0].right_ray is not None
        )
        assert body.bodies[0].right_ray.ray3d is None  # no depth to lift it with: the 2-D ray alone
        deadline = time.monotonic() + 10
        while client.stats("gesture")["rejected"].get("bad_value", 0) < 1:
            assert time.monotonic() < deadline, client.stats("gesture")
            time.sleep(0.2)
    finally:
        client.close()
    assert proc.alive() and "no PNG signature" in proc.output(), proc.output()
