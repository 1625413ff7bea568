"""Process shell of the camera service: source -> Frame samples on hri/camera/{cam}/frame, and from an RGB-D
source DepthFrame samples on hri/camera/{cam}/depth (same stamp and seq, published just before the colour frame
so that a consumer holding the colour frame already has its depth)."""

from __future__ import annotations

import argparse
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from common.depth import depth_frame
from common.runner import Service, main_exit, service_parser
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
        "--start-at",
        None,
        "wall time (Unix seconds) to start at; frames are then stamped start + n / fps, their place in the "
        "file's own timeline, so a speech service given the same --start-at plays the file's audio in step",
        kind=float,
        above=0,
        metavar="T",
        default_text="at once, stamped when read",
    )
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


@dataclass(frozen=True)
class ClipClock:
    """Frame stamps: capture time (the moment the frame is in hand), or with --start-at and a frame rate the frame's
    place in the file's own timeline anchored at that wall time (a speech service given the same plays its audio)."""

    start_at: float | None
    period: float  # s per frame, 0 without a frame rate

    def wait(self, stop: threading.Event) -> None:
        """Until --start-at (if any), or until stopped."""
        if self.start_at is not None and self.period:
            stop.wait(max(0.0, self.start_at - time.time()))

    def stamp(self, seq: int) -> float:
        if self.start_at is None or not self.period:
            return time.time()
        return self.start_at + seq * self.period


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


def main(argv: list[str] | None = None) -> None:
    parser = build_parser()
    args = parser.parse_args(argv)
    rs_size, fit_size = sizes(parser, args)

    service = Service("camera", args)
    try:
        intrinsics = read_intrinsics(args.intrinsics) if args.intrinsics else None
        source = open_source(args.source, rs_size, args.fps, intrinsics)
    except SourceError as exc:
        service.log.error("%s", exc)
        main_exit(2)
    service.on_close(source.close)
    fps = args.fps or source.native_fps or (10.0 if source.finite else None)
    key = service.output_key("frame", cam=args.cam)
    depth_key = service.output_key("depth", cam=args.cam)
    prepare = Preparer(args, intrinsics, fit_size, source.description, service)

    service.log.info("publishing %s on %s at %s", source.description, key, f"{fps:g} fps" if fps else "device rate")

    def loop(stop: threading.Event) -> None:
        seq, period = 0, (1.0 / fps if fps else 0.0)
        clock = ClipClock(args.start_at, period)
        clock.wait(stop)  # stopped meanwhile: the loop below does not start
        next_at = time.monotonic()
        while not stop.is_set():
            produced = False
            for item in source.frames():
                capture = prepare(item)
                produced = True
                if period:
                    delay = next_at - time.monotonic()
                    if delay > 0 and stop.wait(delay):
                        return
                    next_at = max(next_at + period, time.monotonic() - period)
                stamp = clock.stamp(seq)
                img = capture.color
                h, w = img.shape[:2]
                if capture.depth is not None and capture.camera_info is not None and capture.depth_scale:
                    # depth first: whoever matches depth to colour has it when the colour frame arrives
                    service.publish(
                        depth_key,
                        depth_frame(
                            capture.depth,
                            stamp=stamp,
                            source=service.source,
                            seq=seq,
                            cam=args.cam,
                            depth_scale=capture.depth_scale,
                            camera_info=capture.camera_info,
                            compression=args.depth_compression,
                        ),
                        lossless=False,
                    )
                service.publish(
                    key,
                    Frame(
                        stamp=stamp,
                        source=service.source,
                        seq=seq,
                        cam=args.cam,
                        width=w,
                        height=h,
                        encoding=args.encoding,
                        data=encode_image(img, args.encoding, args.quality),
                        camera_info=capture.camera_info,
                    ),
                    lossless=False,
                )
                seq += 1
                if stop.is_set() or (args.count is not None and seq >= args.count):
                    stop.set()
                    return
            if not args.loop or not produced:
                service.log.info("source ended after %d frames", seq)
                stop.set()
                return
            source.rewind()

    def guarded_loop(stop: threading.Event) -> None:
        try:
            loop(stop)
        except SourceError as exc:
            service.fail(2, str(exc))

    main_exit(service.run(loop=guarded_loop))


if __name__ == "__main__":
    main()
