"""Real video through the gesture core in tests and benchmarks: a clip's first frames, a decoded image as the
camera's Frame, and a run of images through `GestureCore` as the service runs it (one stream, fresh at the start)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from common.schema import Frame

if TYPE_CHECKING:  # MediaPipe loads with the gesture core: only for callers that run it
    from services.gesture.core import FrameResult, GestureSettings


def read_frames(path: Path | str, limit: int) -> list[np.ndarray]:
    """The first `limit` frames of a video as OpenCV decodes them (BGR); fewer when the video is shorter."""
    cap = cv2.VideoCapture(str(path))
    frames: list[np.ndarray] = []
    try:
        while len(frames) < limit:
            ok, img = cap.read()
            if not ok:
                break
            frames.append(np.asarray(img))
    finally:
        cap.release()
    return frames


def bgr_frame(img: np.ndarray, seq: int, stamp: float, cam: str = "cam0", source: str = "camera/test") -> Frame:
    """`img` as the camera publishes it uncompressed (bgr8)."""
    h, w = img.shape[:2]
    return Frame(stamp=stamp, source=source, seq=seq, cam=cam, width=w, height=h, encoding="bgr8", data=img.tobytes())


def run_gesture(settings: GestureSettings, images: list[np.ndarray], fps: float) -> list[FrameResult]:
    """Each image through the gesture core as one camera's stream at `fps` (frame k stamped k / fps)."""
    from services.gesture.core import GestureCore

    core = GestureCore(settings, "gesture/test", depth_kept=2)
    try:
        return [core.process(bgr_frame(img, k, k / fps), img, fresh=k == 0) for k, img in enumerate(images)]
    finally:
        core.close()


_CLIP_RUNS: dict[tuple[str, int, float, str], list[FrameResult]] = {}


def run_gesture_on_clip(settings: GestureSettings, path: Path, frames: int, fps: float) -> list[FrameResult]:
    """`run_gesture` over the first `frames` frames of the clip at `path`, run once per test session for the same
    settings: tests that compare two paths on one clip often share one of them (an every-frame reference), and the
    gesture core on a clip is seconds of CPU. The results are shared: read them, do not change them."""
    key = (str(path), frames, fps, repr(settings))
    if key not in _CLIP_RUNS:
        _CLIP_RUNS[key] = run_gesture(settings, read_frames(path, frames), fps)
    return _CLIP_RUNS[key]
