"""Which source a `--source` spec names: the one place that knows every kind (plain sources in source.py, RGB-D
ones in rgbd.py), so neither of those imports the other's."""

from __future__ import annotations

import os
from pathlib import Path

import cv2

from services.camera.rgbd import RgbdFolderSource, is_rgbd_folder, open_realsense
from services.camera.source import IMAGE_EXTENSIONS, CaptureSource, ImageListSource, Source, SourceError


def open_source(
    spec: str, realsense_size: tuple[int, int] = (640, 480), fps: float | None = None, intrinsics=None
) -> Source:
    """'0' -> V4L2 device 0, 'realsense[:SERIAL]' -> an Intel RealSense (RGB-D), a folder of colour/depth pairs
    with an intrinsics.json -> RGB-D captures, another folder -> its images in name order, an image file, else a
    video file."""
    if spec == "realsense" or spec.startswith("realsense:"):
        return open_realsense(spec, realsense_size, fps)
    if spec.isdigit():
        cap = cv2.VideoCapture(int(spec))
        if not cap.isOpened():
            raise SourceError(
                f"cannot open camera device {spec} (/dev/video{spec}): is a camera attached and "
                f"readable by this user? Use --source PATH for a video file or image folder."
            )
        return CaptureSource(cap, f"camera device {spec}", finite=False)
    path = Path(spec)
    if not path.exists():
        raise SourceError(
            f"source {spec!r} does not exist: give a device index, a video file, an image file or a folder of images"
        )
    if path.is_dir():
        if is_rgbd_folder(path):
            return RgbdFolderSource(path, intrinsics)
        images = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS)
        if not images:
            raise SourceError(f"folder {spec} holds no images ({', '.join(sorted(IMAGE_EXTENSIONS))})")
        return ImageListSource(images, f"image folder {spec} ({len(images)} images)")
    if path.suffix.lower() in IMAGE_EXTENSIONS:
        return ImageListSource([path], f"image {spec}")
    if not os.access(path, os.R_OK):
        raise SourceError(f"cannot read {spec}: permission denied")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise SourceError(f"cannot open video file {spec}: not a video OpenCV can decode")
    return CaptureSource(cap, f"video {spec}", finite=True)
