"""Process shell of the camera service: source -> Frame samples on hri/camera/{cam}/frame."""

from __future__ import annotations

import threading
import time

from common.runner import Service, main_exit, service_parser
from common.schema import Frame
from services.camera.source import SourceError, encode_image, open_source

EPILOG = """\
examples:
  hri-camera --source 0                              # webcam /dev/video0
  hri-camera --source demo/data/camera --fps 5 --loop
  hri-camera --source clip.mp4 --cam front --encoding bgr8
"""


def main(argv: list[str] | None = None) -> None:
    parser = service_parser("camera", "Publish camera frames (Frame) on <prefix>/camera/<cam>/frame.", EPILOG)
    parser.add_argument("--source", required=True,
                        help="device index (0), video file, image file, or folder of images (name order)")
    parser.add_argument("--cam", default="cam0", help="camera id used in keys and samples (default cam0)")
    parser.add_argument("--fps", type=float, default=None,
                        help="publish rate; default: the video's own rate, 10 for images, as fast as the device")
    parser.add_argument("--loop", action="store_true", help="start over at the end of a file or folder")
    parser.add_argument("--count", type=int, default=None, help="stop after N frames")
    parser.add_argument("--encoding", choices=("jpeg", "png", "bgr8"), default="jpeg", help="default jpeg")
    parser.add_argument("--quality", type=int, default=90, help="JPEG quality 1–100 (default 90)")
    args = parser.parse_args(argv)
    if not 1 <= args.quality <= 100:
        parser.error("--quality must be within 1–100")

    service = Service("camera", args)
    try:
        source = open_source(args.source)
    except SourceError as exc:
        service.log.error("%s", exc)
        main_exit(2)
    service.on_close(source.close)
    fps = args.fps or source.native_fps or (10.0 if source.finite else None)
    key = service.keys.frame(args.cam)
    service.log.info("publishing %s on %s at %s", source.description, key, f"{fps:g} fps" if fps else "device rate")

    def loop(stop: threading.Event) -> None:
        seq, period = 0, (1.0 / fps if fps else 0.0)
        next_at = time.monotonic()
        while not stop.is_set():
            produced = False
            for img in source.frames():
                produced = True
                if period:
                    delay = next_at - time.monotonic()
                    if delay > 0 and stop.wait(delay):
                        return
                    next_at = max(next_at + period, time.monotonic() - period)
                stamp = time.time()  # capture time: the moment the frame is in hand
                h, w = img.shape[:2]
                service.publish(key, Frame(stamp=stamp, source=service.source, seq=seq, cam=args.cam, width=w,
                                           height=h, encoding=args.encoding,
                                           data=encode_image(img, args.encoding, args.quality)),
                                lossless=False)
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
