"""RGB-D end to end over Zenoh: camera (a colour/depth folder) -> vision (the real YOLOX-Nano) -> fusion, with a spoken
command published by the test.

The scene is built at test time from a real YCB-Video RGB-D frame (shared/data/rgbd/ycb_video/000002: a Soft Scrub
bottle on a table, 0.1 mm depth, PoseCNN's intrinsics): no real frame there has two bottles, so the bottle's own
pixels (colour and depth, where its depth is under 1.05 m) are copied up and to the right, and their depth made
0.35 m smaller: a second bottle held up in front of the table, higher in the image than the first but nearer the
camera. In the image the lowest bottle is the first; by depth the nearest is the copy.

"Go there": nobody is in these frames, so the pointing hand is published by the test: a person's eyes beside the
camera, the ray towards a spot on the table, lifted and met with the table by the gesture service's own functions
(services/gesture/space.py) on the frame's real depth. Fusion must answer with that point, on the table.
"""

from __future__ import annotations

import json
import time
from typing import Any

import cv2
import numpy as np
import pytest

from common.schema import Detections, FusedCommand, Hand, Hands, Ray, Ray3D, Transcript
from hri.cli import make_transcript
from services.gesture.space import DepthView, Lifted, surface_hit
from testkit.harness import Client
from testkit.images import read_image
from testkit.rgbd import start, words_end_over
from testkit.shared import shared_path

pytestmark = pytest.mark.integration

K: dict[str, Any] = {
    "width": 640,
    "height": 480,
    "fx": 1066.778,
    "fy": 1067.487,
    "cx": 312.9869,
    "cy": 241.3109,
    "depth_scale": 0.0001,
    "frame_id": "ycb_camera_optical_frame",
}
BOTTLE = (210, 31, 97, 257)  # the Soft Scrub bottle in 000002 (YOLOX-Nano: bottle 0.76)
COPY_AT = (420, 5)  # top-left of its copy
NEARER = 0.35  # m


def two_bottles(folder) -> tuple[np.ndarray, np.ndarray]:
    src = shared_path("data/rgbd/ycb_video")
    colour = read_image(src / "000002-color.png")
    depth = read_image(src / "000002-depth.png", cv2.IMREAD_UNCHANGED)
    x, y, w, h = BOTTLE
    dx, dy = COPY_AT
    z = depth[y : y + h, x : x + w].astype(float) * K["depth_scale"]
    own = (z > 0) & (z < 1.05)  # the bottle (and the table right at its foot), not the room behind
    colour[dy : dy + h, dx : dx + w][own] = colour[y : y + h, x : x + w][own]
    depth[dy : dy + h, dx : dx + w][own] = depth[y : y + h, x : x + w][own] - int(NEARER / K["depth_scale"])
    folder.mkdir()
    cv2.imwrite(str(folder / "000001-color.png"), colour)
    cv2.imwrite(str(folder / "000001-depth.png"), depth)
    (folder / "intrinsics.json").write_text(json.dumps(K))
    return colour, depth


def say(client: Client, text: str, end: float | None = None) -> None:
    client.publish("hri/speech/kbd/transcript", said(text, time.time() if end is None else end))


def said(text: str, end: float) -> Transcript:
    return make_transcript(text, mic="kbd", end=end, confidence=0.95, source="test/kbd")


def two_positions(det: Detections) -> list:
    return [o for o in det.objects if o.label == "bottle" and o.position is not None]


def wait_for_bottles(client: Client, text: str) -> tuple[list, float]:
    """The two bottles with positions, and a moment for the words `text` to end at so that fusion's whole window for
    them holds only samples with both positions (testkit.rgbd.words_end_over)."""
    det = words_end_over(client, text, lambda d: len(two_positions(d)) == 2, "two bottles with positions")
    return two_positions(det), det.stamp


# a level head camera 1.2 m above the base origin, 0.1 m ahead of it, placing the scene's optical frame (docs/robot.md)
HEAD_CAMERA = f"""name = "head-camera"
[camera]
frame_id = "{K["frame_id"]}"
xyz = [0.1, 0.0, 1.2]
rpy = [-1.5707963267948966, 0.0, -1.5707963267948966]
"""


def test_the_nearest_bottle_is_chosen_by_depth_not_by_the_lowest_box(group, tmp_path):
    two_bottles(tmp_path / "scene")
    (tmp_path / "head.toml").write_text(HEAD_CAMERA)
    client = start(group, tmp_path / "scene", "--profile", str(tmp_path / "head.toml"))
    try:
        bottles, seen_at = wait_for_bottles(client, "pick up the nearest bottle")
        results = client.collect("hri/fusion/command")
        # the words end as a frame with both positions was captured: fusion's window holds only frames with depth
        # however far vision lags the clock (seconds on a loaded machine: fusion then saw no camera input)
        say(client, "pick up the nearest bottle", end=seen_at)
        cmd = results.wait(1, timeout=30)[0][1]
    finally:
        client.close()
    lowest = max(bottles, key=lambda o: o.bbox[1] + o.bbox[3])
    nearest = min(bottles, key=lambda o: float(np.linalg.norm(o.position)))
    assert lowest.id != nearest.id  # the scene is what it should be: 2-D and depth disagree
    assert nearest.position[2] < lowest.position[2] - 0.25, bottles
    assert isinstance(cmd, FusedCommand) and cmd.intent == "pick_up", cmd
    assert cmd.target.id == nearest.id, cmd.explanation
    assert cmd.target.position == nearest.position and cmd.target.frame_id == K["frame_id"]
    assert cmd.target.extent == nearest.extent
    # the profile's mount places the camera: the same point in the robot's base frame (forward = optical z + 0.1 m,
    # left = -optical x, up = 1.2 m - optical y)
    x, y, z = nearest.position
    assert (
        cmd.target.base == pytest.approx([z + 0.1, -x, 1.2 - y], abs=1e-3) and cmd.target.base_frame_id == "base_link"
    )


def test_go_there_with_pointing_is_a_point_on_the_table(group, tmp_path):
    _, depth = two_bottles(tmp_path / "scene")
    view = DepthView(depth.astype(np.float32) * K["depth_scale"], K["fx"], K["fy"], K["cx"], K["cy"], K["frame_id"])
    spot_px = (560, 420)  # the table, bottom right
    spot = view.back_project(*spot_px, view.depth_at(*spot_px))
    eyes = np.array([0.35, -0.45, 0.2])  # a person standing just beside and in front of the camera
    direction = (spot - eyes) / np.linalg.norm(spot - eyes)
    tip = eyes + 0.6 * direction
    hit = surface_hit(view, Lifted(eyes, direction, "eye_fingertip", 0.6))
    assert hit is not None
    project = lambda p: (K["fx"] * p[0] / p[2] + K["cx"], K["fy"] * p[1] / p[2] + K["cy"])  # noqa: E731
    tip_px, spot_seen = np.array(project(tip)), np.array(project(hit))
    d2 = (spot_seen - tip_px) / np.linalg.norm(spot_seen - tip_px)
    ray3d = Ray3D(
        origin=eyes.tolist(),
        direction=direction.tolist(),
        method="eye_fingertip",
        frame_id=K["frame_id"],
        hit=[float(c) for c in hit],
    )
    client = start(group, tmp_path / "scene")
    client.declare_alive("gesture")  # the test sends the hands: fusion waits for them (not only their arrival)
    try:
        _, t0 = wait_for_bottles(client, "go there")  # the words end there: fusion's window holds frames with depth
        results = client.collect("hri/fusion/command")
        for i in range(12):  # pointing for the 1.1 s up to the end of the words
            tip_list = [float(c) for c in tip_px]
            client.publish(
                "hri/gesture/cam0/hands",
                Hands(
                    stamp=t0 - 1.1 + 0.1 * i,
                    source="test/gesture",
                    seq=i,
                    cam="cam0",
                    width=640,
                    height=480,
                    hands=[
                        Hand(
                            hand="right",
                            score=0.95,
                            landmarks=[tip_list] * 21,
                            gesture="point",
                            ray=Ray(origin=tip_list, direction=d2.tolist(), confidence=0.9, source="body", ray3d=ray3d),
                        )
                    ],
                ),
            )
        client.publish(
            "hri/speech/kbd/transcript",
            make_transcript("go there", mic="kbd", end=t0, confidence=0.95, source="test/kbd"),
        )
        cmd = results.wait(1, timeout=30)[0][1]
    finally:
        client.close()
    assert cmd.intent == "go_to" and cmd.location is not None, cmd
    loc = cmd.location
    assert loc.frame_id == K["frame_id"] and loc.position == pytest.approx(hit.tolist(), abs=1e-3)
    # on the table: the real depth where the point is seen says the same distance (an independent reading)
    u, v = project(loc.position)
    assert abs(view.depth_at(u, v) - loc.position[2]) < 0.02
    assert np.linalg.norm(np.array(loc.position) - spot) < 0.03
    # its pixel, from the pinhole fusion fits to the objects' centres and positions, lands near where it is seen
    assert abs(loc.x - u) < 30 and abs(loc.y - v) < 30, (loc, u, v)
