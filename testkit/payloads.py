"""Realistic samples for the benchmarks: the contract examples of testkit/examples.py, with a real
640x480 JPEG frame and a dozen detections."""

from __future__ import annotations

import cv2
import msgspec

from common.schema import Sample
from testkit.examples import examples
from testkit.harness import DATA
from testkit.images import read_image


def realistic_samples() -> dict[str, Sample]:
    by_name = {type(s).__name__: s for s in examples()}
    img = cv2.resize(read_image(str(DATA / "images" / "tabletop" / "smarties.png")), (640, 480))
    frame = by_name["Frame"]
    frame.encoding, frame.width, frame.height = "jpeg", 640, 480
    if frame.camera_info is not None:  # the example's intrinsics are for its own tiny size: these fit 640x480
        frame.camera_info = msgspec.structs.replace(
            frame.camera_info, width=640, height=480, k=[525.0, 0.0, 319.5, 0.0, 525.0, 239.5, 0.0, 0.0, 1.0]
        )
    frame.data = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()
    det = by_name["Detections"]
    det.objects = det.objects * 12
    return {
        "Frame 640x480 jpeg": frame,
        "Detections x12": det,
        "Hands x1": by_name["Hands"],
        "Transcript": by_name["Transcript"],
        "FusedCommand": by_name["FusedCommand"],
    }
