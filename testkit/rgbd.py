"""The RGB-D stack of the end-to-end tests over Zenoh: a router, vision with the real YOLOX-Nano, fusion, then the
camera replaying a colour/depth folder (so that vision is up before its first frame)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from common.schema import Detections
from hri.cli import make_transcript
from services.fusion.core import Config as FusionConfig
from testkit.harness import Client, ProcessGroup
from testkit.shared import yolox_model


def start(group: ProcessGroup, folder: Path) -> Client:
    """Start camera -> vision -> fusion on `folder` (5 frames a second, looped) and return a connected client."""
    group.router()
    group.service("vision", "--backend", "onnx", "--model", str(yolox_model()))
    group.service("fusion")
    client = Client(group.endpoint)
    client.wait_alive("vision", timeout=90)
    client.wait_alive("fusion", timeout=60)
    group.service("camera", "--source", str(folder), "--fps", "5", "--loop")
    return client


def words_end_over(
    client: Client, text: str, ready: Callable[[Detections], bool], what: str, timeout: float = 90
) -> Detections:
    """A vision sample whose capture stamp the words `text` may end at: every sample vision published over fusion's
    window for those words (window_before s before their start to window_after s after their end) is `ready`, and the
    window has closed (a later sample arrived). Vision's first samples come before any depth (no positions), and on a
    loaded machine vision lags the clock by seconds: words ending "now" could be joined with those, or with nothing
    (issue #41: the nearest bottle taken by its box, a fingertip's touch instead of the 3-D ray)."""
    objects = client.collect("hri/vision/cam0/objects")
    cfg = FusionConfig()
    deadline = time.monotonic() + timeout
    samples: list[Detections] = []
    while time.monotonic() < deadline:
        samples = [det for _, det in objects.drain(0.5)]  # every sample so far
        for det in reversed(samples):
            words = make_transcript(text, mic="kbd", end=det.stamp, confidence=0.95, source="test/kbd")
            lo, hi = words.start - cfg.window_before, det.stamp + cfg.window_after
            window = [d for d in samples if lo <= d.stamp <= hi]
            if samples[-1].stamp > hi and all(ready(d) for d in window):
                return det
    seen = [(round(d.stamp, 2), [(o.label, o.position is not None) for o in d.objects]) for d in samples]
    raise AssertionError(
        f"vision never reported {what} over a word window for {text!r}: {len(seen)} samples, the last {seen[-3:]}; "
        f"vision's stats {client.stats('vision', timeout=10)}"
    )
