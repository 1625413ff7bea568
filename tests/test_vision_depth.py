"""Object positions in metres from real RGB-D frames (services/vision/depth.py, common/depth.py), no Zenoh.

The YCB-Video frames (../shared/data/rgbd/ycb_video, depth in 0.1 mm, K from its README) are checked against an
independent computation written out here: region growing from the box's centre (on the object for these boxes)
over neighbours whose depth steps by less than 1 cm (an object's surface is smooth, its outline a depth jump),
then the median of those pixels back-projected with K by hand.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from common.depth import UndecodableDepth, depth_frame, depth_metres, depth_units, encode_depth, metres
from common.schema import CameraInfo, DetectedObject, InvalidSample
from services.camera.rgbd import mirror_camera_info
from services.vision.depth import DEPTH_MISSES, DepthImage, DepthMatcher, foreground, object_depth, with_depth
from testkit.images import read_image
from testkit.shared import shared_path

# YCB-Video (PoseCNN tools/demo.py): fx, fy, cx, cy; 1 depth unit = 0.1 mm
FX, FY, CX, CY = 1066.778, 1067.487, 312.9869, 241.3109
YCB_SCALE = 0.0001
YCB_INFO = CameraInfo(width=640, height=480, k=[FX, 0, CX, 0, FY, CY, 0, 0, 1], frame_id="ycb_optical")

# boxes drawn by hand around the objects of 000002-color.png ([x, y, w, h] px); each holds background too
# (the wall behind the bleach bottle's neck, the table around the cans)
BOXES = {
    "000002": {
        "master chef can": (303, 150, 108, 172),
        "soup can (lying)": (370, 255, 130, 103),
        "sugar box": (195, 288, 140, 160),
        "bleach bottle": (212, 32, 96, 258),
        "mug on the shelf": (497, 20, 91, 107),
        "ball on the shelf": (495, 172, 65, 65),
    },
    "000004": {
        "mustard bottle": (335, 240, 105, 207),
        "tuna can": (222, 328, 100, 95),  # half of its box is the desk it stands on
    },
}
BOXES_000002 = BOXES["000002"]


def ycb(name: str) -> tuple[np.ndarray, np.ndarray]:
    folder = shared_path("data/rgbd/ycb_video")
    colour = read_image(str(folder / f"{name}-color.png"), cv2.IMREAD_COLOR)
    depth = read_image(str(folder / f"{name}-depth.png"), cv2.IMREAD_UNCHANGED)
    assert depth.dtype == np.uint16 and depth.shape == colour.shape[:2]
    return colour, depth


def reference_position(depth_units16: np.ndarray, box) -> np.ndarray:
    """Independent of the module: region growing from the centre, hand-written pinhole back-projection."""
    x, y, w, h = box
    region = depth_units16[y : y + h, x : x + w].astype(np.float32) * YCB_SCALE
    patch = region[h * 2 // 5 : h * 3 // 5, w * 2 // 5 : w * 3 // 5]
    seed = np.median(patch[patch > 0])
    pv, pu = np.nonzero(np.abs(patch - seed) < 0.003)  # a centre pixel at the seed's depth
    seed_pixel = (int(pu[0] + w * 2 // 5), int(pv[0] + h * 2 // 5))
    grown = np.zeros((h + 2, w + 2), np.uint8)
    blocked = np.where(region > 0, region, 100.0).astype(np.float32)  # holes stop the growth
    cv2.floodFill(blocked, grown, seed_pixel, 0, 0.01, 0.01, flags=4 | cv2.FLOODFILL_MASK_ONLY | (255 << 8))
    vs, us = np.nonzero((grown[1:-1, 1:-1] > 0) & (region > 0))
    z = region[vs, us].astype(np.float64)
    u, v = us + x, vs + y
    return np.median(np.stack([(u - CX) * z / FX, (v - CY) * z / FY, z], 1), axis=0)


@pytest.mark.parametrize("frame", sorted(BOXES))
def test_positions_on_real_frames_agree_with_an_independent_computation_within_2cm(frame):
    _, depth = ycb(frame)
    m = metres(depth, YCB_SCALE)
    for name, box in BOXES[frame].items():
        got = object_depth(m, YCB_INFO, box)
        assert got is not None, name
        ref = reference_position(depth, box)
        assert 0.8 < ref[2] < 1.3, (name, ref)  # the README: objects at about 0.8–1 m (the shelf farther)
        assert abs(got.position[2] - ref[2]) < 0.02  # depth alone, too
        err = np.linalg.norm(np.array(got.position) - ref)
        assert err < 0.02, (name, got.position, ref.tolist())
        assert 0.5 < got.support <= 1.0, (name, got.support)
        assert all(0.01 < e < 0.35 for e in got.extent), (name, got.extent)  # object-sized, not the room


def test_the_object_not_the_wall_behind_it():
    """The sugar box's real depth, with the left 60 % of its box replaced by a wall 1.8 m away (a box whose object
    is small beside a far background): the plain box median jumps to the wall, the position stays."""
    _, depth = ycb("000002")
    box = BOXES_000002["sugar box"]
    x, y, w, h = box
    before = object_depth(metres(depth, YCB_SCALE), YCB_INFO, box)
    walled = depth.copy()
    walled[y : y + h, x : x + int(0.6 * w)] = 18000  # 1.8 m
    m = metres(walled, YCB_SCALE)
    assert np.nanmedian(m[y : y + h, x : x + w]) > 1.7
    after = object_depth(m, YCB_INFO, box)
    assert abs(after.position[2] - before.position[2]) < 0.02
    assert after.position[0] > before.position[0]  # the visible part is the right 40 %
    assert after.extent[2] < 0.3  # the wall is not part of the object


def test_holes_inside_a_box_lower_the_support_not_the_position():
    _, depth = ycb("000002")
    box = BOXES_000002["master chef can"]
    before = object_depth(metres(depth, YCB_SCALE), YCB_INFO, box)
    holed = depth.copy()
    x, y, w, h = box
    holed[y + h // 4 : y + 3 * h // 4, x + w // 4 : x + 3 * w // 4] = 0  # a quarter of the box: no measurement
    after = object_depth(metres(holed, YCB_SCALE), YCB_INFO, box)
    assert after is not None
    assert np.linalg.norm(np.subtract(after.position, before.position)) < 0.02
    assert after.support < before.support - 0.2
    # all holes: no position (absent, never zero)
    empty = depth.copy()
    empty[y : y + h, x : x + w] = 0
    assert object_depth(metres(empty, YCB_SCALE), YCB_INFO, box) is None
    obj = DetectedObject(id="o1", label="can", score=0.9, bbox=list(box), center=[x + w / 2, y + h / 2])
    assert with_depth(obj, DepthImage(empty, YCB_SCALE, YCB_INFO)).position is None
    # the service's path: 16-bit units scaled per sampled pixel, the same as metres converted up front
    measured = with_depth(obj, DepthImage(holed, YCB_SCALE, YCB_INFO))
    assert np.allclose(measured.position, after.position, atol=5e-3) and measured.depth_support < 1.0


def test_a_mirrored_camera_keeps_positions_right():
    """The source flips the image left-right: with cx' = width − 1 − cx every object's position is its
    mirror image (x negated, y and z unchanged), in the frame marked `_mirrored`."""
    _, depth = ycb("000002")
    m = metres(depth, YCB_SCALE)
    flipped = np.ascontiguousarray(m[:, ::-1])
    info = mirror_camera_info(YCB_INFO)
    assert info.cx == pytest.approx(640 - 1 - CX) and info.frame_id == "ycb_optical_mirrored"
    for name, (x, y, w, h) in BOXES_000002.items():
        straight = object_depth(m, YCB_INFO, (x, y, w, h))
        mirrored = object_depth(flipped, info, (640 - x - w, y, w, h))
        expected = (-straight.position[0], straight.position[1], straight.position[2])
        assert np.allclose(mirrored.position, expected, atol=0.005), (name, mirrored.position, expected)
    # the same flip with K left alone puts every object off by (2·cx − width + 1)·z/fx: about 1.3 cm here
    wrong = object_depth(flipped, YCB_INFO, (640 - 303 - 108, 150, 108, 172))
    right = object_depth(flipped, info, (640 - 303 - 108, 150, 108, 172))
    assert abs(wrong.position[0] - right.position[0]) > 0.01


def test_foreground_takes_the_nearest_substantial_mode():
    rng = np.random.default_rng(0)
    wall = rng.normal(2.0, 0.01, 600)
    cup = rng.normal(0.9, 0.005, 300)
    speck = np.full(5, 0.4)  # a few stray near pixels are not an object
    z = np.concatenate([wall, cup, speck])
    own = foreground(z)
    assert own[600:900].all() and not own[:600].any() and not own[900:].any()
    assert foreground(np.full(50, 1.0)).all()


def test_a_wrong_resolution_k_is_refused():
    with pytest.raises(InvalidSample, match="intrinsics are for 1280x720, the image is 640x480"):
        depth_frame(
            np.zeros((480, 640), np.uint16),
            stamp=1.0,
            source="t/x",
            seq=0,
            cam="c",
            depth_scale=0.001,
            camera_info=CameraInfo(
                width=1280, height=720, k=[905.6, 0, 648.8, 0, 904.5, 387.8, 0, 0, 1], frame_id="rs"
            ),
        )


@pytest.mark.parametrize("compression", ["none", "png"])
def test_depth_frames_round_trip_losslessly(compression):
    _, depth = ycb("000002")
    frame = depth_frame(
        depth,
        stamp=1.0,
        source="t/x",
        seq=3,
        cam="c",
        depth_scale=YCB_SCALE,
        camera_info=YCB_INFO,
        compression=compression,
    )
    assert np.array_equal(depth_units(frame), depth)
    m = depth_metres(frame)
    assert np.isnan(m[depth == 0]).all() and np.allclose(m[depth > 0], depth[depth > 0] * YCB_SCALE)
    if compression == "png":
        assert len(frame.data) < 0.6 * depth.nbytes  # the point of compressing


def test_float_depth_and_a_bad_png_payload():
    f = np.array([[0.0, np.nan], [1.5, np.inf]], np.float32)
    enc, data = encode_depth(f)
    assert enc == "32FC1"
    info = CameraInfo(width=2, height=2, k=[1, 0, 0.5, 0, 1, 0.5, 0, 0, 1], frame_id="f")
    frame = depth_frame(f, stamp=1.0, source="t/x", seq=0, cam="c", depth_scale=1.0, camera_info=info)
    m = depth_metres(frame)
    assert np.isnan(m[0, 0]) and np.isnan(m[0, 1]) and m[1, 0] == 1.5 and np.isnan(m[1, 1])
    with pytest.raises(ValueError, match="16UC1 only"):
        encode_depth(f, "png")
    bad = depth_frame(
        np.zeros((2, 2), np.uint16),
        stamp=1.0,
        source="t/x",
        seq=0,
        cam="c",
        depth_scale=0.001,
        camera_info=info,
        compression="png",
    )
    bad.data = bad.data[:30] + b"garbage"
    with pytest.raises(UndecodableDepth):
        depth_units(bad)
    bigger = depth_frame(
        np.zeros((4, 4), np.uint16),
        stamp=1.0,
        source="t/x",
        seq=0,
        cam="c",
        depth_scale=0.001,
        camera_info=CameraInfo(width=4, height=4, k=[1, 0, 2, 0, 1, 2, 0, 0, 1], frame_id="f"),
        compression="png",
    )
    bad.data = bigger.data  # a PNG of another size than declared: refused before decoding
    with pytest.raises(UndecodableDepth, match="header says 4x4"):
        depth_units(bad)


def test_the_matcher_pairs_depth_and_colour_by_seq_and_stamp():
    info = CameraInfo(width=2, height=2, k=[1, 0, 0.5, 0, 1, 0.5, 0, 0, 1], frame_id="f")
    matcher = DepthMatcher(keep=2)
    for seq in range(3):
        matcher.add(
            depth_frame(
                np.zeros((2, 2), np.uint16),
                stamp=10.0 + seq,
                source="t/x",
                seq=seq,
                cam="c",
                depth_scale=0.001,
                camera_info=info,
            )
        )
    assert matcher.match("c", 2, 12.0).seq == 2
    assert matcher.match("c", 0, 10.0) is None  # older than the kept ones
    assert matcher.match("c", 2, 12.5) is None  # same seq, another capture (a restarted camera)
    assert matcher.match("other", 2, 12.0) is None


def test_a_colour_frame_served_before_its_depth_waits_for_it_but_colour_only_cameras_never_wait():
    from types import SimpleNamespace

    info = CameraInfo(width=2, height=2, k=[1, 0, 0.5, 0, 1, 0.5, 0, 0, 1], frame_id="f")

    def depth(seq, cam="c"):
        return depth_frame(
            np.ones((2, 2), np.uint16),
            stamp=10.0 + seq / 30,
            source="t/x",
            seq=seq,
            cam=cam,
            depth_scale=0.001,
            camera_info=info,
        )

    def colour(seq, cam="c"):
        return SimpleNamespace(cam=cam, seq=seq, stamp=10.0 + seq / 30)

    matcher = DepthMatcher()
    assert not matcher.expects("c", 0, 10.0)  # no depth ever: colour goes straight on
    assert matcher.add(depth(0)) is None
    assert matcher.match("c", 0, 10.0) is not None
    # frame 1 is served before depth 1: it waits, and depth 1 releases it
    f1 = colour(1)
    assert matcher.match("c", 1, f1.stamp) is None and matcher.expects("c", 1, f1.stamp)
    assert matcher.wait(f1, "image 1") is None
    assert matcher.add(depth(1)) == (f1, "image 1")
    # frame 2 waits, its depth is lost; frame 3 replaces it
    f2, f3 = colour(2), colour(3)
    matcher.wait(f2, "image 2")
    assert matcher.wait(f3, "image 3") == (f2, "image 2")
    # a newer depth already in: this frame's depth is lost, no waiting, and the frame is overtaken (skipped)
    matcher.add(depth(5))
    assert not matcher.expects("c", 4, colour(4).stamp)
    assert matcher.overtaken("c", colour(4).stamp)
    assert not matcher.overtaken("c", colour(5).stamp) and not matcher.overtaken("c", colour(6).stamp)
    assert not matcher.overtaken("c", 10.0 + 5 / 30 - 2.0)  # colour lagging its depth by 2 s: not this rule's case
    assert not matcher.overtaken("other", 10.0)  # colour-only cameras are never overtaken
    # a camera whose depth stopped a while ago (source time) is waited for only until DEPTH_MISSES colour frames
    # asked in vain since its last depth (the frame for 4 was the first)
    assert [matcher.expects("c", seq, 10.0 + seq / 30) for seq in range(99, 99 + DEPTH_MISSES)] == [True, True, False]
    matcher.add(depth(120))  # its depth is back: the next frame waits for its own again
    assert matcher.expects("c", 150, 10.0 + 150 / 30)
    assert not matcher.expects("other", 1, 10.0)


def test_a_depth_camera_on_a_slow_worker_keeps_waiting_for_depth():
    """Vision serving one item a second or slower (a loaded machine): the newest depth it has served is more than
    EXPECT_DEPTH_S older than the colour frame, yet the camera is sending depth: the frame waits for its own."""
    from types import SimpleNamespace

    info = CameraInfo(width=2, height=2, k=[1, 0, 0.5, 0, 1, 0.5, 0, 0, 1], frame_id="f")
    matcher = DepthMatcher()
    for seq in range(0, 60, 6):  # 5 frames a second, every 6th capture served: 1.2 s apart
        stamp = 10.0 + seq / 5
        d = depth_frame(
            np.ones((2, 2), np.uint16), stamp=stamp, source="t/x", seq=seq, cam="c", depth_scale=0.001, camera_info=info
        )
        if seq % 12:  # every other time the colour frame is served first: it waits and its depth releases it
            assert matcher.match("c", seq, stamp) is None and matcher.expects("c", seq, stamp)
            matcher.wait(SimpleNamespace(cam="c", seq=seq, stamp=stamp), f"image {seq}")
            assert matcher.add(d) is not None
        else:
            matcher.add(d)
            assert matcher.match("c", seq, stamp) is d
