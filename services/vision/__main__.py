"""Process shell of the vision service: Frame (+ the DepthFrame of the same capture, when there is one) ->
Detections on <prefix>/vision/<cam>/objects."""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from common.budget import MaxRate
from common.depth import UndecodableDepth
from common.image import frame_fields, frame_handler
from common.runner import App, Delivery, Service, StartupError, serve, service_parser
from common.schema import DepthFrame, Detections, Frame, SpeechDecoding
from common.settings import add_option
from common.speech_first import EASED_PERIOD_S, EasedRate, SpeechFirst
from services.vision.colour_memory import MAX_MEASURED, REUSE_FRAMES, REUSE_IOU
from services.vision.core import VisionPipeline
from services.vision.depth import DepthImage, DepthMatcher
from services.vision.segment import ColorSegmenter, read_labels
from services.vision.yolo import FAMILIES, ModelError, YoloDetector, read_names

EPILOG = """\
examples:
  hri-vision                                         # colour segmentation, every camera
  hri-vision --labels data/demo/labels.json          # name the objects of a known tabletop
  hri-vision --backend onnx --model yolox_nano.onnx  # a YOLOX / YOLOv5 / YOLOv8-11 detector in ONNX (COCO-80)
  hri-vision --backend onnx --model best.onnx --labels classes.txt --conf 0.4   # your own classes
  hri-vision --cams front,wrist
"""


def build_parser() -> argparse.ArgumentParser:
    parser = service_parser(
        "vision",
        "Detect objects (label, colour, box, score, stable id) and image quality "
        "in camera frames; publish Detections for every processed frame.",
        EPILOG,
    )
    add_option(
        parser,
        "--backend",
        "color",
        "color: HSV segmentation, no model; onnx: a YOLO model given by --model",
        choices=("color", "onnx"),
    )
    add_option(
        parser,
        "--model",
        None,
        "ONNX detector path (YOLOX, YOLOv5 or YOLOv8/11 export); a model given means the onnx backend",
        kind=str,
        metavar="PATH",
        default_text="none",
    )
    add_option(
        parser,
        "--labels",
        None,
        'color backend: JSON file mapping colour -> label, "*" for any colour; onnx backend: the model\'s '
        "class names, one per line in class order, or a JSON list",
        kind=str,
        metavar="FILE",
        default_text='color: every object is "object"; onnx: the 80 COCO names',
    )
    parser.add_argument("--names", default=None, help=argparse.SUPPRESS)  # old spelling of --labels for onnx
    add_option(parser, "--conf", 0.3, "onnx: keep detections scoring at least this", at_least=0, at_most=1, metavar="P")
    add_option(
        parser, "--iou", 0.45, "onnx: non-maximum suppression's IoU threshold", at_least=0, at_most=1, metavar="P"
    )
    add_option(
        parser,
        "--family",
        "auto",
        "onnx: the export family (auto: read from the output shape)",
        choices=("auto", *FAMILIES),
    )
    add_option(
        parser,
        "--channels",
        None,
        "onnx: the input channel order",
        kind=str,
        choices=("rgb", "bgr"),
        default_text="the family's: bgr for yolox, rgb otherwise",
    )
    add_option(
        parser,
        "--input-scale",
        None,
        "onnx: multiply 0-255 pixels by this for the model",
        kind=float,
        above=0,
        metavar="X",
        default_text="1 for yolox, 1/255 otherwise",
    )
    add_option(
        parser,
        "--letterbox",
        None,
        "onnx: where the resized frame sits in the model input",
        kind=str,
        choices=("center", "topleft"),
        default_text="topleft for yolox, center otherwise",
    )
    add_option(
        parser,
        "--color-reuse",
        REUSE_FRAMES,
        "onnx: a still object's colour (its box overlapping the one measured at IoU >= "
        f"{REUSE_IOU}) is reused for up to N frames after it was measured; 0: measured on every frame",
        at_least=0,
        metavar="N",
    )
    add_option(
        parser,
        "--color-max",
        MAX_MEASURED,
        "onnx: measure at most N objects' colours per frame (the ones with none first, then the longest "
        "unmeasured); the others keep the colour of their box on the last frame (issue #42: a frame's cost "
        "bounded whatever the scene holds); 0: no cap",
        at_least=0,
        metavar="N",
    )
    add_option(
        parser,
        "--max-rate",
        0.0,
        "run the model on at most this many frames per second of source time per camera, the others skipped "
        "(`hri up` sets it from the machine's cores: common/budget.py); 0: every frame it can",
        at_least=0,
        metavar="HZ",
    )
    add_option(
        parser,
        "--speech-first",
        True,
        "while speech decodes an utterance (its SpeechDecoding samples), run the model on at most one frame every "
        "--speech-first-period, the others skipped, so that the decode gets the cores (issue #42)",
    )
    add_option(
        parser,
        "--speech-first-period",
        EASED_PERIOD_S,
        "while speech decodes: at most one frame every S seconds (a watermark for fusion's join)",
        above=0,
        metavar="S",
    )
    add_option(parser, "--cams", "*", "comma-separated camera ids to process (* for all)", metavar="IDS")
    return parser


def make_detector(args: argparse.Namespace, log: logging.Logger) -> YoloDetector | ColorSegmenter:
    """The detector the arguments ask for: an ONNX model when one is given, else colour segmentation."""
    if args.backend == "onnx" and not args.model:
        log.warning(
            "--backend onnx without --model: no model ships with hri-fusion, so the color "
            "backend runs; give --model PATH (a YOLOX, YOLOv5 or YOLOv8/11 detector exported to "
            "ONNX)"
        )
    if args.model:  # a model given means the onnx backend
        names_file = args.names or args.labels
        detector = YoloDetector(
            args.model,
            read_names(names_file) if names_file else None,
            args.conf,
            args.iou,
            args.family,
            args.channels,
            args.input_scale,
            args.letterbox,
        )
        log.info("%s: %s", args.model, detector.describe())
        # onnxruntime sets its buffers up on the first run (~2x a later one): done here, before the service is live
        detector.detect(np.full((*detector.input_hw, 3), 114, np.uint8))
        return detector
    labels, warnings = read_labels(args.labels) if args.labels else ({}, [])
    for warning in warnings:
        log.warning("%s", warning)
    return ColorSegmenter(labels=labels)


class VisionApp(App):
    """Frame (+ the DepthFrame of the same capture) -> the pipeline (services/vision/core.py) -> Detections."""

    node = "vision"

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.depths = DepthMatcher()
        self.speech_first = SpeechFirst()
        self.eased_rate = EasedRate(args.speech_first_period)
        self.max_rates: dict[str, MaxRate] = {}  # cam -> its pace (--max-rate)
        self.rate_skipped = 0

    def open(self, service: Service) -> None:
        if self.args.max_rate > 0:
            service.counters.set("max_rate_mhz", round(1000 * self.args.max_rate))  # the rate it runs at, in stats
        try:
            self.pipeline = VisionPipeline(
                make_detector(self.args, service.log), self.args.color_reuse, self.args.color_max
            )
        except (ModelError, OSError, ValueError) as exc:
            raise StartupError(str(exc)) from None
        self.service = service

    def wire(self, service: Service) -> None:
        if self.args.speech_first:
            service.subscribe_input("decoding", self.on_decoding)
        for cam in self.args.cams.split(","):
            # the camera sends depth just before colour, so its slot is usually served first
            service.subscribe_input("depth", self.on_depth, cam=cam.strip())
            service.subscribe_input("frame", frame_handler(service, self.on_image), cam=cam.strip())

    def depth_image(self, frame: Frame, depth: DepthFrame) -> DepthImage | None:
        """The decoded depth image of this capture, or None (counted) when it does not fit the colour frame."""
        service = self.service
        if (depth.width, depth.height) != (frame.width, frame.height):
            service.counters.reject(
                "bad_value",
                f"depth {depth.width}x{depth.height} is not aligned to the colour "
                f"frame {frame.width}x{frame.height} (seq {frame.seq}): no positions",
                service.keys.depth(frame.cam),
            )
            return None
        try:
            return DepthImage.from_frame(depth)
        except UndecodableDepth as exc:
            service.counters.reject("undecodable", str(exc), service.keys.depth(frame.cam))
            return None

    def process(self, frame: Frame, img: np.ndarray, depth: DepthImage | None) -> None:
        objects, quality = self.pipeline.process(frame.cam, img, depth)
        detections = Detections(
            **frame_fields(frame, self.service.source),
            objects=objects,
            quality=quality,
            frame_id=depth.camera_info.frame_id if depth is not None else None,
        )
        self.service.publish_output("objects", detections, cam=frame.cam)
        for name, count in self.pipeline.colour_counts().items():
            self.service.counters.set(name, count)

    def on_depth(self, delivery: Delivery) -> None:
        depth = delivery.sample
        assert isinstance(depth, DepthFrame)  # the runner validated it as the topic's schema
        ready = self.depths.add(depth)  # decoded only when a colour frame claims it
        if ready is not None:  # the colour frame of this capture was served first and waited for it
            frame, img = ready
            self.process(frame, img, self.depth_image(frame, depth))

    def on_decoding(self, delivery: Delivery) -> None:
        notice = delivery.sample
        assert isinstance(notice, SpeechDecoding)  # the runner validated it as the topic's schema
        self.speech_first.heard(notice.mic, notice.decoding, time.monotonic())

    def on_image(self, frame: Frame, img: np.ndarray) -> None:
        depths, counters = self.depths, self.service.counters
        if not self.max_rates.setdefault(frame.cam, MaxRate(self.args.max_rate)).take(frame.stamp):
            counters.add("skipped")  # the budget's rate (--max-rate): this frame is not due
            self.rate_skipped += 1
            counters.set("skipped_by_max_rate", self.rate_skipped)
            return
        now = time.monotonic()
        if not self.eased_rate.take(now, self.speech_first.easing(now)):
            counters.add("skipped")  # speech first: this frame gives its CPU to the decode
            self.speech_first.eased += 1
            counters.set("eased_for_speech", self.speech_first.eased)
            return
        depth = depths.match(frame.cam, frame.seq, frame.stamp)
        if depth is None and depths.expects(frame.cam, frame.seq, frame.stamp):
            if depths.wait(frame, img) is not None:
                counters.add("skipped")  # an older frame whose depth never came: latest-only
            return
        if depth is None and depths.overtaken(frame.cam, frame.stamp):
            counters.add("skipped")  # its depth was replaced by a newer capture's, whose colour frame comes next
            return
        if depths.take_waiting(frame.cam) is not None:
            counters.add("skipped")
        self.process(frame, img, None if depth is None else self.depth_image(frame, depth))


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    serve(VisionApp(args), args)


if __name__ == "__main__":
    main()
