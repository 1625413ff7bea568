import time

import pytest

from common.image import decode_image
from tests.harness import DATA

pytestmark = pytest.mark.integration


def test_camera_frames_reach_echo_and_everything_stops_cleanly(group):
    router = group.router()
    camera = group.service("camera", "--source", str(DATA / "images" / "tabletop"), "--fps", "20", "--loop")
    frames = group.echo("hri/camera/*/frame", count=5, timeout=30)
    assert len(frames) == 5
    seqs = [f["seq"] for f in frames]
    assert seqs == sorted(seqs) and len(set(seqs)) == 5
    assert all(f["encoding"] == "jpeg" and f["data"].endswith("bytes>") for f in frames)
    for proc in (camera, router):
        code, took = proc.terminate(timeout=2.0)
        assert code == 0, f"{proc.name} exit code {code}\n{proc.output()}"
        assert took < 2.0
        assert proc.children_gone()
