"""The RGB-D stack of the end-to-end tests over Zenoh: a router, vision with the real YOLOX-Nano, fusion, then the
camera replaying a colour/depth folder (so that vision is up before its first frame)."""

from __future__ import annotations

from pathlib import Path

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
