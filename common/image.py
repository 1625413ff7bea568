"""Turning a Frame's bytes back into an image: shared by every service that consumes frames.

Before anything is decoded, the encoded header's dimensions (PNG IHDR, JPEG SOF) are read and compared with
the Frame's declared `width`/`height` and a pixel cap: a 1 MB PNG that would decode to 15000x15000 pixels is
rejected in microseconds instead of stalling a service for seconds.
"""

from __future__ import annotations

import struct
from typing import Any, Callable, TypedDict

import numpy as np

from common.schema import Frame, InvalidSample

DEFAULT_MAX_PIXELS = 4096 * 2160  # DCI 4K; a UHD (3840x2160) camera fits
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# SOF markers carry the frame size; C4 (DHT), C8 (JPG) and CC (DAC) share the range but are not frames
JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}
JPEG_HEADER_SCAN_LIMIT = 1 << 20  # the SOF sits after the APPn/DQT segments, well within the first MiB


class UndecodableFrame(ValueError):
    pass


def png_size(data: bytes) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; raises ValueError if the header is not a PNG's."""
    if len(data) < 24 or not data.startswith(PNG_SIGNATURE) or data[12:16] != b"IHDR":
        raise ValueError("no PNG signature and IHDR chunk at the start")
    return struct.unpack(">II", data[16:24])


def jpeg_size(data: bytes) -> tuple[int, int]:
    """(width, height) from a JPEG's first SOF segment; raises ValueError if there is none to read."""
    if not data.startswith(b"\xff\xd8"):
        raise ValueError("no JPEG start-of-image marker")
    i, end = 2, min(len(data), JPEG_HEADER_SCAN_LIMIT)
    while i + 4 <= end:
        if data[i] != 0xFF:
            raise ValueError(f"no JPEG marker at byte {i}")
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # stand-alone markers
            i += 2
            continue
        if marker in (0xD9, 0xDA):
            raise ValueError("JPEG image data before any frame header (SOF)")
        length = struct.unpack(">H", data[i + 2 : i + 4])[0]
        if marker in JPEG_SOF:
            if length < 7 or i + 9 > len(data):
                raise ValueError("truncated JPEG frame header")
            height, width = struct.unpack(">HH", data[i + 5 : i + 9])
            return width, height
        i += 2 + length
    raise ValueError("no JPEG frame header (SOF) in the header segments")


def check_frame_header(frame: Frame, max_pixels: int | None = DEFAULT_MAX_PIXELS) -> None:
    """Raise InvalidSample unless the frame is within the pixel cap and its encoded header matches its declared
    width/height: `oversized` (more than `max_pixels`), `bad_value` (header unreadable or different)."""
    if max_pixels is not None and frame.width * frame.height > max_pixels:
        raise InvalidSample(
            "oversized", f"frame of {frame.width}x{frame.height} is over the cap of {max_pixels} pixels (--max-pixels)"
        )
    if frame.encoding == "bgr8":
        return  # its size is checked against width*height*3 by the schema
    try:
        width, height = png_size(frame.data) if frame.encoding == "png" else jpeg_size(frame.data)
    except (ValueError, struct.error) as exc:
        raise InvalidSample("bad_value", f"{frame.encoding} frame header unreadable: {exc}") from None
    if (width, height) != (frame.width, frame.height):
        raise InvalidSample(
            "bad_value",
            f"{frame.encoding} header says {width}x{height}, the frame declares {frame.width}x{frame.height}",
        )


def decode_image(data: bytes, encoding: str, width: int, height: int) -> np.ndarray:
    """A Frame's `data` -> BGR image; raises UndecodableFrame with the reason. Shared by every consumer."""
    if encoding == "bgr8":
        if len(data) != width * height * 3:
            raise UndecodableFrame(f"bgr8 frame of {width}x{height} needs {width * height * 3} bytes, got {len(data)}")
        return np.frombuffer(data, np.uint8).reshape(height, width, 3)
    import cv2  # here, not at the top: the runner checks headers in services that never decode an image

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise UndecodableFrame(f"{encoding} data ({len(data)} bytes) does not decode")
    if img.shape[1] != width or img.shape[0] != height:
        raise UndecodableFrame(f"decoded {img.shape[1]}x{img.shape[0]}, header says {width}x{height}")
    return img


def frame_image(frame: Frame) -> np.ndarray:
    """The BGR image carried by a Frame (raises UndecodableFrame)."""
    return decode_image(frame.data, frame.encoding, frame.width, frame.height)


class FrameFields(TypedDict):
    """The fields a sample made from one frame copies from it (Detections, Hands, Bodies, Faces, Persons ...)."""

    stamp: float
    source: str
    seq: int
    cam: str
    width: int
    height: int


def frame_fields(frame: Frame, source: str) -> FrameFields:
    """What a result about `frame` shares with it: its stamp (when the frame was captured, so that fusion joins
    on it), seq, camera and size; `source` is the publishing service's."""
    return FrameFields(
        stamp=frame.stamp, source=source, seq=frame.seq, cam=frame.cam, width=frame.width, height=frame.height
    )


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
