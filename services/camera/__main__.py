"""Process shell of the camera service: source -> Frame samples on hri/camera/{cam}/frame, and from an RGB-D
source DepthFrame samples on hri/camera/{cam}/depth (same stamp and seq, published just before the colour frame
so that a consumer holding the colour frame already has its depth)."""

from __future__ import annotations

import argparse
import threading
import time
from typing import Any

import numpy as np

from common.depth import depth_frame
from common.runner import App, Service, StartupError, serve, service_parser
from common.schema import Frame
from common.settings import add_option
from services.camera.opener import open_source
from services.camera.rgbd import Capture, Intrinsics, check_intrinsics, mirror_capture, read_intrinsics
from services.camera.source import SourceError, encode_image, fit_within, parse_size

EPILOG = """\
examples:
  hri-camera --source 0                              # webcam /dev/video0
  hri-camera --source demo/data/camera --fps 5 --loop
  hri-camera --source clip.mp4 --cam front --encoding bgr8
  hri-camera --source realsense                      # Intel RealSense: colour + aligned depth (extra: realsense)
  hri-camera --source rgbd_folder/ --loop            # NAME-color.png + NAME-depth.png + intrinsics.json
  hri-camera --source 0 --intrinsics webcam.json     # a colour camera's K travels with its frames
"""


def build_parser() -> argparse.ArgumentParser:
    parser = service_parser("camera", "Publish camera frames (Frame) on <prefix>/camera/<cam>/frame.", EPILOG)
    parser.add_argument(
        "--source",
        required=True,
        help="device index (0), 'realsense' or 'realsense:SERIAL', video file, image file, folder of "
        "images (name order), or folder of colour/depth pairs with an intrinsics.json (RGB-D)",
    )
    add_option(parser, "--cam", "cam0", "camera id used in keys and samples", metavar="ID")
    add_option(
        parser,
        "--fps",
        None,
        "frames published per second",
        kind=float,
        above=0,
        default_text="the video's own rate, 10 for images, as fast as the device",
    )
    add_option(parser, "--loop", False, "start over at the end of a file or folder")
    add_option(parser, "--count", None, "stop after N frames", kind=int, at_least=1, metavar="N", default_text="never")
    add_option(parser, "--encoding", "jpeg", "how frames are encoded on the wire", choices=("jpeg", "png", "bgr8"))
    add_option(parser, "--quality", 90, "JPEG quality", at_least=1, at_most=100)
    add_option(
        parser,
        "--intrinsics",
        None,
        "intrinsics JSON (width, height, fx, fy, cx, cy or K, depth_scale, frame_id, distortion; "
        "docs/vision.md): sent with every frame; overrides an RGB-D folder's own",
        kind=str,
        metavar="FILE",
        default_text="the source's own, if any",
    )
    add_option(
        parser,
        "--depth-compression",
        "none",
        "depth frames as raw 16-bit rows or a lossless 16-bit PNG (about 6x smaller on YCB-Video depth, "
        "~24 ms to encode a 640x480 frame: for slow links)",
        choices=("none", "png"),
    )
    add_option(
        parser,
        "--mirror",
        False,
        "flip colour and depth left-right (a selfie view); cx becomes width-1-cx and the "
        "frame_id gets '_mirrored': positions are then in the mirrored frame (x negated)",
    )
    add_option(parser, "--rs-size", "640x480", "RealSense resolution WIDTHxHEIGHT", metavar="WxH")
    add_option(
        parser,
        "--size",
        None,
        "video, image or folder: frames scaled to fit inside WIDTHxHEIGHT, aspect kept (e.g. 640x480: a 1080p "
        "clip costs every service a quarter of the pixels); not for depth sources (--rs-size for RealSense)",
        kind=str,
        metavar="WxH",
        default_text="the source's own",
    )
    return parser


def resize_colour_only(capture: Capture, size: tuple[int, int], has_intrinsics: bool, service: Service) -> None:
    """--size: the colour image fitted inside `size`; a capture with depth or intrinsics is left as it is (its
    pixels are tied to them), said once."""
    if capture.depth is None and capture.camera_info is None and not has_intrinsics:
        capture.color = fit_within(capture.color, size)
    else:
        service.counters.ratelog.warn(
            "size_ignored", "--size is ignored for a source with depth or intrinsics (RealSense: --rs-size)"
        )


def sizes(parser: argparse.ArgumentParser, args: argparse.Namespace) -> tuple[tuple[int, int], tuple[int, int] | None]:
    """(--rs-size, --size or None), or the parser's error."""
    try:
        rs_size = parse_size(args.rs_size)
    except ValueError:
        parser.error("--rs-size must be WIDTHxHEIGHT, e.g. 640x480")
    try:
        return rs_size, (parse_size(args.size) if args.size else None)
    except ValueError:
        parser.error("--size must be WIDTHxHEIGHT, e.g. 640x480")


class Preparer:
    """The source's image or capture made ready to publish: fitted to --size, with the intrinsics that belong to
    it (checked once per resolution), mirrored if asked."""

    def __init__(
        self,
        args: argparse.Namespace,
        intrinsics: Intrinsics | None,
        fit_size: tuple[int, int] | None,
        description: str,
        service: Service,
    ):
        self.args, self.intrinsics, self.fit_size = args, intrinsics, fit_size
        self.description, self.service = description, service
        self.checked: set[tuple[int, int]] = set()

    def __call__(self, item: Any) -> Capture:
        capture = item if isinstance(item, Capture) else Capture(item)
        intrinsics = self.intrinsics
        if self.fit_size is not None:
            resize_colour_only(capture, self.fit_size, intrinsics is not None, self.service)
        if intrinsics is not None:
            capture.camera_info = intrinsics.camera_info
            if capture.depth is not None and capture.depth.dtype == np.uint16 and intrinsics.depth_scale:
                capture.depth_scale = intrinsics.depth_scale
        if capture.camera_info is not None:
            size = capture.color.shape[1], capture.color.shape[0]
            if size not in self.checked:  # once per resolution: a wrong K is refused with the first frame
                check_intrinsics(capture.camera_info, *size, self.args.intrinsics or self.description)
                self.checked.add(size)
        return mirror_capture(capture) if self.args.mirror else capture


class CameraApp(App):
    """A source (device, file, folder, RealSense) -> Frame (+ DepthFrame from an RGB-D source) at a steady rate."""

    node = "camera"

    def __init__(self, args: argparse.Namespace, rs_size: tuple[int, int], fit_size: tuple[int, int] | None) -> None:
        self.args = args
        self.rs_size = rs_size
        self.fit_size = fit_size
        self.intrinsics: Intrinsics | None = None

    def open(self, service: Service) -> None:
        args = self.args
        try:
            self.intrinsics = read_intrinsics(args.intrinsics) if args.intrinsics else None
            self.source = open_source(args.source, self.rs_size, args.fps, self.intrinsics)
        except SourceError as exc:
            raise StartupError(str(exc)) from None
        service.on_close(self.source.close)
        self.service = service
        self.prepare = Preparer(args, self.intrinsics, self.fit_size, self.source.description, service)
        self.fps = args.fps or self.source.native_fps or (10.0 if self.source.finite else None)
        self.key = service.output_key("frame", cam=args.cam)
        self.depth_key = service.output_key("depth", cam=args.cam)
        rate = f"{self.fps:g} fps" if self.fps else "device rate"
        service.log.info("publishing %s on %s at %s", self.source.description, self.key, rate)

    def publish(self, capture: Capture, seq: int) -> None:
        """One capture: its depth first (whoever matches depth to colour has it when the colour frame arrives)."""
        args, service = self.args, self.service
        stamp = time.time()  # capture time: the moment the frame is in hand
        img = capture.color
        h, w = img.shape[:2]
        if capture.depth is not None and capture.camera_info is not None and capture.depth_scale:
            depth = depth_frame(
                capture.depth,
                stamp=stamp,
                source=service.source,
                seq=seq,
                cam=args.cam,
                depth_scale=capture.depth_scale,
                camera_info=capture.camera_info,
                compression=args.depth_compression,
            )
            service.publish(self.depth_key, depth, lossless=False)
        frame = Frame(
            stamp=stamp,
            source=service.source,
            seq=seq,
            cam=args.cam,
            width=w,
            height=h,
            encoding=args.encoding,
            data=encode_image(img, args.encoding, args.quality),
            camera_info=capture.camera_info,
        )
        service.publish(self.key, frame, lossless=False)

    def loop(self, stop: threading.Event) -> None:
        try:
            self._frames(stop)
        except SourceError as exc:
            self.service.fail(2, str(exc))

    def _frames(self, stop: threading.Event) -> None:
        """Publishes the source's frames at the rate asked, over again with --loop, until --count or stopped."""
        args = self.args
        pacer = Pacer(1.0 / self.fps if self.fps else 0.0)
        seq = 0
        while not stop.is_set():
            produced = False
            for item in self.source.frames():
                capture = self.prepare(item)
                produced = True
                if not pacer.wait(stop):
                    return
                self.publish(capture, seq)
                seq += 1
                if stop.is_set() or (args.count is not None and seq >= args.count):
                    stop.set()
                    return
            if not args.loop or not produced:
                self.service.log.info("source ended after %d frames", seq)
                stop.set()
                return
            self.source.rewind()


class Pacer:
    """Waits for the next frame's time at a steady period (0: no wait); a late frame does not make the next early."""

    def __init__(self, period: float) -> None:
        self.period = period
        self.next_at = time.monotonic()

    def wait(self, stop: threading.Event) -> bool:
        """False when stopped while waiting."""
        if not self.period:
            return True
        delay = self.next_at - time.monotonic()
        if delay > 0 and stop.wait(delay):
            return False
        self.next_at = max(self.next_at + self.period, time.monotonic() - self.period)
        return True


def main(argv: list[str] | None = None) -> None:
    parser = build_parser()
    args = parser.parse_args(argv)
    rs_size, fit_size = sizes(parser, args)
    serve(CameraApp(args, rs_size, fit_size), args)


if __name__ == "__main__":
    main()
