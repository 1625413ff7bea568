"""RGB-D sources of the camera service (services/camera/rgbd.py), no Zenoh: the intrinsics file, colour/depth
folders, mirroring, and an Intel RealSense through the real pyrealsense2 frame API (a software device fed with
the real RealSense tabletop frame of ../shared/data/rgbd/realsense_tabletop)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from common.depth import metres
from services.camera.opener import open_source
from services.camera.rgbd import (
    Capture,
    RgbdFolderSource,
    find_pairs,
    import_realsense,
    mirror_capture,
    parse_intrinsics,
    read_intrinsics,
    realsense_capture,
)
from services.camera.source import SourceError
from services.vision.depth import object_depth
from testkit.shared import shared_path

YCB = {
    "width": 640,
    "height": 480,
    "fx": 1066.778,
    "fy": 1067.487,
    "cx": 312.9869,
    "cy": 241.3109,
    "depth_scale": 0.0001,
}


def test_intrinsics_from_fx_fy_cx_cy_or_k():
    a = parse_intrinsics(YCB)
    assert a.camera_info.k == [1066.778, 0.0, 312.9869, 0.0, 1067.487, 241.3109, 0.0, 0.0, 1.0]
    assert a.depth_scale == 0.0001 and a.camera_info.frame_id == "camera_color_optical_frame"
    nested = parse_intrinsics(
        {
            "width": 640,
            "height": 480,
            "K": [[1066.778, 0, 312.9869], [0, 1067.487, 241.3109], [0, 0, 1]],
            "frame_id": "ycb",
        }
    )
    assert nested.camera_info.k == a.camera_info.k and nested.camera_info.frame_id == "ycb"
    assert nested.depth_scale is None
    flat = parse_intrinsics(
        {
            "width": 640,
            "height": 480,
            "K": a.camera_info.k,
            "distortion_model": "plumb_bob",
            "distortion": [0.1, -0.2, 0, 0, 0.05],
        }
    )
    assert flat.camera_info.distortion == [0.1, -0.2, 0.0, 0.0, 0.05]


@pytest.mark.parametrize(
    "spec,message",
    [
        ({"height": 480, "fx": 1, "fy": 1, "cx": 1, "cy": 1}, "width must be a positive integer"),
        ({"width": 640, "height": 480, "fx": 1, "cy": 1}, "missing fy, cx"),
        ({"width": 640, "height": 480, "K": [1, 2, 3]}, "K must be 3×3"),
        ({"width": 640, "height": 480, "K": [500, 0, 320, 1, 500, 240, 0, 0, 1]}, "not a camera matrix"),
        ({**YCB, "fx": -5}, "focal lengths must be > 0"),
        ({**YCB, "fx": "big"}, "fx must be a finite number"),
        ({**YCB, "depth_scale": 0}, "depth_scale must be > 0"),
    ],
)
def test_bad_intrinsics_say_what_is_wrong(spec, message):
    with pytest.raises(SourceError, match=message):
        parse_intrinsics(spec, "intrinsics.json")


def test_an_unreadable_intrinsics_file(tmp_path):
    with pytest.raises(SourceError, match="cannot read intrinsics file"):
        read_intrinsics(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{fx: 1")
    with pytest.raises(SourceError, match="is not JSON"):
        read_intrinsics(tmp_path / "bad.json")


def ycb_folder(tmp_path, intrinsics=YCB):
    src = shared_path("data/rgbd/ycb_video")
    folder = tmp_path / "ycb"
    folder.mkdir(parents=True)
    for p in src.glob("*.png"):
        (folder / p.name).write_bytes(p.read_bytes())
    if intrinsics is not None:
        (folder / "intrinsics.json").write_text(json.dumps(intrinsics))
    return folder


def test_a_colour_depth_folder_is_an_rgbd_source(tmp_path):
    folder = ycb_folder(tmp_path)
    (folder / "notes.txt").write_text("not an image")
    (folder / "000009-color.png").write_bytes((folder / "000002-color.png").read_bytes())  # no depth: not a pair
    assert [(c.name, d.name) for c, d in find_pairs(folder)] == [
        ("000002-color.png", "000002-depth.png"),
        ("000004-color.png", "000004-depth.png"),
    ]
    source = open_source(str(folder))
    assert isinstance(source, RgbdFolderSource) and source.finite
    captures = list(source.frames())
    assert len(captures) == 2
    for c, name in zip(captures, ("000002", "000004")):
        assert c.color.shape == (480, 640, 3) and c.depth.dtype == np.uint16 and c.depth_scale == 0.0001
        assert np.array_equal(c.depth, cv2.imread(str(folder / f"{name}-depth.png"), cv2.IMREAD_UNCHANGED))
        assert c.camera_info.fx == 1066.778


def test_rgbd_folder_errors_are_clear(tmp_path):
    with pytest.raises(SourceError, match="intrinsics are for 1280x720 but the images are 640x480"):
        open_source(str(ycb_folder(tmp_path / "a", {**YCB, "width": 1280, "height": 720})))
    with pytest.raises(SourceError, match="has no intrinsics.json"):
        open_source(str(ycb_folder(tmp_path / "b", None)))
    with pytest.raises(SourceError, match="16-bit depth images need depth_scale"):
        open_source(str(ycb_folder(tmp_path / "c", {k: v for k, v in YCB.items() if k != "depth_scale"})))
    folder = ycb_folder(tmp_path / "d")
    small = cv2.imread(str(folder / "000002-depth.png"), cv2.IMREAD_UNCHANGED)[::2, ::2]
    cv2.imwrite(str(folder / "000002-depth.png"), small)
    with pytest.raises(SourceError, match="must be aligned to the colour image"):
        open_source(str(folder))


def test_mirroring_flips_colour_and_depth_together_and_adjusts_cx(tmp_path):
    capture = next(open_source(str(ycb_folder(tmp_path))).frames())
    m = mirror_capture(capture)
    assert np.array_equal(m.color, capture.color[:, ::-1]) and np.array_equal(m.depth, capture.depth[:, ::-1])
    assert m.camera_info.cx == pytest.approx(640 - 1 - 312.9869)
    assert m.camera_info.frame_id == "camera_color_optical_frame_mirrored"
    assert mirror_capture(Capture(capture.color)).camera_info is None  # a colour-only capture stays so


# ---------------------------------------------------------------------------
# Intel RealSense
# ---------------------------------------------------------------------------
def realsense():
    try:
        return import_realsense()
    except SourceError as exc:
        pytest.skip(str(exc))


def test_without_pyrealsense2_the_error_says_how_to_install(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_realsense(name, *args, **kwargs):
        if name == "pyrealsense2":
            raise ImportError("No module named 'pyrealsense2'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_realsense)
    with pytest.raises(SourceError, match=r"needs pyrealsense2.*hri-fusion\[realsense\]"):
        open_source("realsense")


def test_without_a_device_the_error_says_what_to_check():
    rs = realsense()
    if len(rs.context().query_devices()):
        pytest.skip("a RealSense is connected to this machine")
    with pytest.raises(SourceError, match="no RealSense device found"):
        open_source("realsense")


def test_a_real_realsense_frame_through_the_pyrealsense2_pipeline():
    """The real tabletop frame goes through a software device, the syncer and rs.align (what RealSenseSource
    runs), and comes out as a Capture with its intrinsics and the sensor's depth scale; the brick on the board
    is then found at the depth the frame says."""
    rs = realsense()
    data = np.load(shared_path("data/rgbd/realsense_tabletop/realsense_frame.npz"))
    width, height = (int(v) for v in data["image_size"])
    fx, fy, cx, cy = (float(v) for v in data["intrinsics"])
    colour_rgb = np.ascontiguousarray(data["color"])
    depth = np.ascontiguousarray(data["depth"].reshape(height, width))

    intrinsics = rs.intrinsics()
    intrinsics.width, intrinsics.height = width, height
    intrinsics.fx, intrinsics.fy, intrinsics.ppx, intrinsics.ppy = fx, fy, cx, cy
    intrinsics.model, intrinsics.coeffs = rs.distortion.none, [0.0] * 5
    device = rs.software_device()
    sensors, profiles = [], []
    for uid, (name, kind, fmt, bpp) in enumerate(
        [("Depth", rs.stream.depth, rs.format.z16, 2), ("Color", rs.stream.color, rs.format.rgb8, 3)]
    ):
        stream = rs.video_stream()
        stream.type, stream.index, stream.uid = kind, 0, uid
        stream.width, stream.height, stream.fps, stream.bpp, stream.fmt = width, height, 30, bpp, fmt
        stream.intrinsics = intrinsics
        sensor = device.add_sensor(name)
        sensors.append(sensor)
        profiles.append(sensor.add_video_stream(stream))
    sensors[0].add_read_only_option(rs.option.depth_units, 0.001)
    identity = rs.extrinsics()
    identity.rotation, identity.translation = [1, 0, 0, 0, 1, 0, 0, 0, 1], [0, 0, 0]
    profiles[0].register_extrinsics_to(profiles[1], identity)  # aligned already: same optical centre
    syncer = rs.syncer()
    for sensor, profile in zip(sensors, profiles):
        sensor.open(profile)
        sensor.start(syncer)
    align = rs.align(rs.stream.color)
    capture = None
    try:
        for n in range(4):  # the syncer pairs the streams after the first frames
            for sensor, profile, pixels, bpp in zip(sensors, profiles, (depth, colour_rgb), (2, 3)):
                frame = rs.software_video_frame()
                frame.pixels, frame.bpp, frame.stride = pixels, bpp, width * bpp
                frame.timestamp, frame.frame_number = n * 33.3, n
                frame.domain = rs.timestamp_domain.hardware_clock
                frame.profile = profile.as_video_stream_profile()
                sensor.on_video_frame(frame)
            capture = realsense_capture(
                rs,
                align.process(syncer.wait_for_frames(5000)),
                sensors[0].get_option(rs.option.depth_units),
                "rs_color_optical_frame",
            )
            if capture is not None:
                break
    finally:
        for sensor in sensors:
            sensor.stop()
            sensor.close()
    assert capture is not None, "the syncer never delivered colour and depth together"
    assert np.array_equal(capture.color, cv2.cvtColor(colour_rgb, cv2.COLOR_RGB2BGR))  # RGB -> BGR
    assert capture.depth.shape == (height, width) and capture.depth.dtype == np.uint16
    assert (capture.depth == depth).mean() > 0.95  # rs.align re-projects: a few edge pixels move
    assert capture.depth_scale == pytest.approx(0.001)
    info = capture.camera_info
    assert (info.width, info.height, info.frame_id) == (width, height, "rs_color_optical_frame")
    assert np.allclose([info.fx, info.fy, info.cx, info.cy], [fx, fy, cx, cy]) and info.distortion_model == "none"

    # the brick: its box also holds the board ~6 cm behind it, which most of a looser box is
    box = (550, 405, 100, 110)
    got = object_depth(metres(capture.depth, capture.depth_scale), info, box)
    x, y, w, h = box
    region = depth[y : y + h, x : x + w].astype(float) / 1000
    assert np.median(region[region > 0]) > 0.5  # the board
    top = region[(region > 0) & (region < np.percentile(region[region > 0], 10) + 0.01)]  # the brick's top face
    assert abs(got.position[2] - np.median(top)) < 0.01, (got.position, np.median(top))
    assert 0.02 < got.extent[0] < 0.045 and 0.02 < got.extent[1] < 0.045  # a 2×2 Duplo brick: 3.2 cm
