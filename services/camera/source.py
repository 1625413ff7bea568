"""Frame sources and frame encoding — no Zenoh here."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import cv2
import numpy as np

IMAGE_EXTENSIONS = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp"}


class SourceError(RuntimeError):
    """A source that cannot be opened or read; the message says which and what to do."""


@dataclass
class Source:
    """An opened source. `frames()` yields BGR images (colour sources) or `rgbd.Capture`s (RGB-D sources);
    `native_fps` is None when the source has no clock."""

    description: str
    native_fps: float | None
    finite: bool

    def frames(self) -> Iterator[Any]:  # np.ndarray, or rgbd.Capture (rgbd imports this module: no cycle)
        raise NotImplementedError

    def rewind(self) -> None:
        """Start over (for --loop)."""

    def close(self) -> None:
        pass


class ImageListSource(Source):
    def __init__(self, paths: list[Path], description: str):
        super().__init__(description, None, True)
        self.paths = paths

    def frames(self) -> Iterator[np.ndarray]:
        for path in self.paths:
            img = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if img is None:
                raise SourceError(f"cannot decode image {path}: is it a valid image file?")
            yield img


class CaptureSource(Source):
    def __init__(self, cap: cv2.VideoCapture, description: str, finite: bool):
        fps = cap.get(cv2.CAP_PROP_FPS)
        super().__init__(description, fps if fps and 0 < fps < 1000 else None, finite)
        self.cap = cap

    def frames(self) -> Iterator[np.ndarray]:
        while True:
            ok, img = self.cap.read()
            if not ok:
                if self.finite:
                    return
                raise SourceError(f"{self.description} stopped delivering frames (unplugged or in use?)")
            yield img

    def rewind(self) -> None:
        self.cap.set(cv2.CAP_PROP_POS_FRAMES, 0)

    def close(self) -> None:
        self.cap.release()


def parse_size(text: str) -> tuple[int, int]:
    """'640x480' -> (640, 480); ValueError for anything else."""
    parts = text.lower().split("x")
    size = tuple(int(v) for v in parts)
    if len(size) != 2 or min(size) <= 0:
        raise ValueError(f"{text!r} is not WIDTHxHEIGHT")
    return size[0], size[1]


def fit_within(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The image scaled to fit inside `size` (width, height), its aspect kept (no stretched faces, nothing cut
    off); unchanged when it already has that width or height and fits. Area averaging down, linear up."""
    h, w = img.shape[:2]
    scale = min(size[0] / w, size[1] / h)
    out_w, out_h = max(1, int(round(w * scale))), max(1, int(round(h * scale)))
    if (out_w, out_h) == (w, h):
        return img
    return cv2.resize(img, (out_w, out_h), interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)


def encode_image(img: np.ndarray, encoding: str, jpeg_quality: int = 90) -> bytes:
    """BGR image -> bytes for a Frame's `data`."""
    if encoding == "bgr8":
        return np.ascontiguousarray(img, dtype=np.uint8).tobytes()
    ext, params = (".jpg", [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality]) if encoding == "jpeg" else (".png", [])
    ok, buf = cv2.imencode(ext, img, params)
    if not ok:
        raise SourceError(f"OpenCV could not encode a {img.shape} frame as {encoding}")
    return buf.tobytes()
