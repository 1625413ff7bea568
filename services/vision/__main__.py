"""Process shell of the vision service: Frame -> Detections on <prefix>/vision/<cam>/objects."""

from __future__ import annotations

from common.image import frame_handler
from common.runner import Service, main_exit, service_parser
from common.schema import Detections, Frame
from services.vision.core import VisionPipeline
from services.vision.segment import ColorSegmenter, read_labels
from services.vision.yolo import COCO_NAMES, ModelError, YoloDetector, read_names

EPILOG = """\
examples:
  hri-vision                                         # colour segmentation, every camera
  hri-vision --labels data/demo/labels.json          # name the objects of a known tabletop
  hri-vision --backend onnx --model yolov8n.onnx     # a YOLO detector you exported to ONNX
  hri-vision --cams front,wrist
"""


def main(argv: list[str] | None = None) -> None:
    parser = service_parser("vision", "Detect objects (label, colour, box, score, stable id) and image quality "
                            "in camera frames; publish Detections for every processed frame.", EPILOG)
    parser.add_argument("--backend", choices=("color", "onnx"), default="color",
                        help="color: HSV segmentation, no model (default); onnx: a YOLO model given by --model")
    parser.add_argument("--model", default=None, help="YOLO ONNX model path (with --backend onnx)")
    parser.add_argument("--names", default=None, help="class names file, one per line (default: the 80 COCO names)")
    parser.add_argument("--conf", type=float, default=0.35, help="onnx confidence threshold (default 0.35)")
    parser.add_argument("--labels", default=None,
                        help='JSON file mapping colour -> label for the color backend, "*" for any colour '
                             '(default: every object is labelled "object")')
    parser.add_argument("--cams", default="*", help="comma-separated camera ids to process (default: all)")
    args = parser.parse_args(argv)

    service = Service("vision", args)
    try:
        if args.backend == "onnx" and not args.model:
            service.log.warning("--backend onnx without --model: no model ships with hri-fusion, so the color "
                                "backend runs; give --model PATH (a YOLOv8/v11 detector exported to ONNX)")
        if args.model:  # a model given means the onnx backend
            detector = YoloDetector(args.model, read_names(args.names) if args.names else COCO_NAMES, args.conf)
        else:
            labels, warnings = read_labels(args.labels) if args.labels else ({}, [])
            for warning in warnings:
                service.log.warning("%s", warning)
            detector = ColorSegmenter(labels=labels)
    except (ModelError, OSError, ValueError) as exc:
        service.log.error("%s", exc)
        main_exit(2)
    pipeline = VisionPipeline(detector)
    if not service.connect():
        main_exit(0)

    def on_image(frame: Frame, img) -> None:
        objects, quality = pipeline.process(frame.cam, img)
        service.publish(service.keys.objects(frame.cam), Detections(
            stamp=frame.stamp, source=service.source, seq=frame.seq, cam=frame.cam, width=frame.width,
            height=frame.height, objects=objects, quality=quality))

    for cam in args.cams.split(","):
        service.subscribe(service.keys.frame(cam.strip()), Frame, frame_handler(service, on_image), latest=True,
                          monotonic=True)
    main_exit(service.run())


if __name__ == "__main__":
    main()
