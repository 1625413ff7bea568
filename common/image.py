"""Turning a Frame's bytes back into an image: shared by every service that consumes frames."""

from __future__ import annotations

import cv2
import numpy as np

from typing import Any, Callable

from common.schema import Frame


class UndecodableFrame(ValueError):
    pass


def decode_image(data: bytes, encoding: str, width: int, height: int) -> np.ndarray:
    """A Frame's `data` -> BGR image; raises UndecodableFrame with the reason. Shared by every consumer."""
    if encoding == "bgr8":
        if len(data) != width * height * 3:
            raise UndecodableFrame(f"bgr8 frame of {width}x{height} needs {width * height * 3} bytes, got {len(data)}")
        return np.frombuffer(data, np.uint8).reshape(height, width, 3)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise UndecodableFrame(f"{encoding} data ({len(data)} bytes) does not decode")
    if img.shape[1] != width or img.shape[0] != height:
        raise UndecodableFrame(f"decoded {img.shape[1]}x{img.shape[0]}, header says {width}x{height}")
    return img


def frame_image(frame: Frame) -> np.ndarray:
    """The BGR image carried by a Frame (raises UndecodableFrame)."""
    return decode_image(frame.data, frame.encoding, frame.width, frame.height)


def frame_handler(service: Any, handle: Callable[[Frame, np.ndarray], None]) -> Callable[[Any], None]:
    """A runner handler for Frame subscriptions: decodes the image and calls `handle(frame, image)`; a frame
    whose image does not decode is rejected as `undecodable` in the service's counters, with the reason."""
    def on_frame(delivery: Any) -> None:
        try:
            img = frame_image(delivery.sample)
        except UndecodableFrame as exc:
            service.counters.reject("undecodable", str(exc), delivery.key)
            return
        handle(delivery.sample, img)
    return on_frame
