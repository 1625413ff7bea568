"""The RGB-D stack of the end-to-end tests over Zenoh: a router, vision with the real YOLOX-Nano, fusion, then the
camera replaying a colour/depth folder (so that vision is up before its first frame)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from common.schema import Detections
from testkit import words
from testkit.harness import Client, ProcessGroup
from testkit.shared import yolox_model


def start(group: ProcessGroup, folder: Path, *fusion_args: str) -> Client:
    """Start camera -> vision -> fusion (with `fusion_args`) on `folder` (5 frames a second, looped) and return a
    connected client."""
    group.router()
    group.service("vision", "--backend", "onnx", "--model", str(yolox_model()))
    group.service("fusion", *fusion_args)
    client = Client(group.endpoint)
    client.wait_alive("vision", timeout=90)
    client.wait_alive("fusion", timeout=60)
    group.service("camera", "--source", str(folder), "--fps", "5", "--loop")
    return client


def words_end_over(
    client: Client, text: str, ready: Callable[[Detections], bool], what: str, timeout: float = 90
) -> Detections:
    """A vision sample of cam0 whose stamp the words `text` may end at: every vision sample over fusion's window for
    them is `ready` and the window has closed (testkit.words). Vision's first samples come before any depth (no
    positions), and on a loaded machine vision lags the clock by seconds: words ending "now" were joined with those
    (issue #41: the nearest bottle taken by its box, a fingertip's touch instead of the 3-D ray)."""
    objects = client.collect("hri/vision/cam0/objects")
    try:
        return words.words_end_over(text, objects, ready, what, timeout=timeout)
    except AssertionError as e:
        raise AssertionError(f"{e}; vision's stats {client.stats('vision', timeout=10)}") from None
