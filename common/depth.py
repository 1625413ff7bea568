"""A DepthFrame's bytes to and from a depth image: shared by the camera (encode) and every consumer (decode).

Depth images here are numpy arrays of the wire's units (uint16 for 16UC1, float32 for 32FC1); `metres()` turns
one into float32 metres with NaN where there is no measurement (0 or NaN on the wire), so that consumers never
mistake "no depth" for "at the camera".
"""

from __future__ import annotations

import numpy as np

from common.image import PNG_SIGNATURE, png_size
from common.schema import CameraInfo, DepthCompression, DepthEncoding, DepthFrame


class UndecodableDepth(ValueError):
    pass


def encode_depth(depth: np.ndarray, compression: DepthCompression = "none") -> tuple[DepthEncoding, bytes]:
    """(encoding, data) of a uint16 or float32 depth image. `png` is a lossless 16-bit PNG (uint16 only)."""
    encoding: DepthEncoding
    if depth.dtype == np.uint16:
        encoding = "16UC1"
    elif depth.dtype == np.float32:
        encoding = "32FC1"
    else:
        raise ValueError(f"depth must be uint16 (16UC1) or float32 (32FC1), not {depth.dtype}")
    if compression == "none":
        return encoding, np.ascontiguousarray(depth, depth.dtype.newbyteorder("<")).tobytes()
    if compression != "png":
        raise ValueError(f"depth compression must be none or png, not {compression!r}")
    if encoding != "16UC1":
        raise ValueError(
            "png depth compression carries 16UC1 only: send 32FC1 depth uncompressed or as uint16 "
            "units with a depth_scale"
        )
    import cv2

    ok, buf = cv2.imencode(".png", depth, [cv2.IMWRITE_PNG_COMPRESSION, 1])  # level 1: most of the gain, fast
    if not ok:
        raise ValueError(f"OpenCV could not encode a {depth.shape} depth image as PNG")
    return encoding, buf.tobytes()


def depth_frame(
    depth: np.ndarray,
    *,
    stamp: float,
    source: str,
    seq: int,
    cam: str,
    depth_scale: float,
    camera_info: CameraInfo,
    compression: DepthCompression = "none",
) -> DepthFrame:
    encoding, data = encode_depth(depth, compression)
    h, w = depth.shape[:2]
    return DepthFrame(
        stamp=stamp,
        source=source,
        seq=seq,
        cam=cam,
        width=w,
        height=h,
        encoding=encoding,
        compression=compression,
        depth_scale=depth_scale,
        camera_info=camera_info,
        data=data,
    )


def depth_units(frame: DepthFrame) -> np.ndarray:
    """The depth image in the wire's units (uint16 or float32, height × width); raises UndecodableDepth."""
    if frame.compression == "none":
        dtype = np.dtype("<u2") if frame.encoding == "16UC1" else np.dtype("<f4")
        if len(frame.data) != frame.width * frame.height * dtype.itemsize:
            raise UndecodableDepth(
                f"{frame.encoding} {frame.width}x{frame.height} needs "
                f"{frame.width * frame.height * dtype.itemsize} bytes, got {len(frame.data)}"
            )
        return np.frombuffer(frame.data, dtype).reshape(frame.height, frame.width)
    # png: check the header before decoding (a small file must not decode to a huge image)
    if not frame.data.startswith(PNG_SIGNATURE):
        raise UndecodableDepth("png depth: no PNG signature")
    try:
        size = png_size(frame.data)
    except ValueError as exc:
        raise UndecodableDepth(f"png depth: {exc}") from None
    if size != (frame.width, frame.height):
        raise UndecodableDepth(
            f"png depth header says {size[0]}x{size[1]}, the frame declares {frame.width}x{frame.height}"
        )
    import cv2

    img = cv2.imdecode(np.frombuffer(frame.data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 2:
        raise UndecodableDepth("png depth does not decode to a single-channel 16-bit image")
    return img


def metres(units: np.ndarray, depth_scale: float) -> np.ndarray:
    """float32 metres, NaN where there is no measurement (0, NaN or ±inf)."""
    m = units.astype(np.float32) * np.float32(depth_scale)
    m[~(m > 0) | ~np.isfinite(m)] = np.nan
    return m


def depth_metres(frame: DepthFrame) -> np.ndarray:
    """The frame's depth in float32 metres, NaN = no measurement; raises UndecodableDepth."""
    return metres(depth_units(frame), frame.depth_scale)
