"""camera (image folder) -> vision -> hri echo, as real processes."""

import subprocess
import sys

import pytest

from tests.harness import DATA, ROOT, Client

pytestmark = pytest.mark.integration


def test_camera_folder_to_vision_to_echo(group, tmp_path):
    folder = tmp_path / "scene"
    folder.mkdir()
    for name in ("table.png", "pointing.png"):
        (folder / name).write_bytes((DATA / "demo" / name).read_bytes())
    group.router()
    group.service("vision", "--labels", str(DATA / "demo" / "labels.json"))
    group.service("camera", "--source", str(folder), "--fps", "10", "--loop")
    got = group.echo("hri/vision/cam0/objects", count=6, timeout=60)
    seqs = [d["seq"] for d in got]
    assert seqs == sorted(seqs)
    by_scene = {}
    for d in got:
        colours = sorted(o["color"] for o in d["objects"] if o["color"] in ("red", "green", "blue"))
        by_scene[d["width"]] = colours
        assert all(o["label"] == "candy" for o in d["objects"])
        assert set(d["quality"]) == {"brightness", "contrast", "sharpness"}
    assert by_scene[506] == ["blue", "blue", "green", "green", "red"]   # table.png
    assert by_scene[640] == ["blue", "red"]                               # pointing.png


def test_every_frame_gets_detections_even_when_nothing_is_seen(group, tmp_path):
    import cv2
    import numpy as np
    blank = tmp_path / "blank"
    blank.mkdir()
    cv2.imwrite(str(blank / "white.png"), np.full((240, 320, 3), 255, np.uint8))
    group.router()
    group.service("vision")
    client = Client(group.endpoint)
    try:
        client.wait_alive("vision", timeout=60)
        out = client.collect("hri/vision/*/objects")
        group.service("camera", "--source", str(blank), "--fps", "10", "--loop")
        samples = [s for _, s in out.wait(3, timeout=30)]
        assert [s.objects for s in samples] == [[], [], []]
        seqs = [s.seq for s in samples]
        assert seqs == sorted(set(seqs))
    finally:
        client.close()


def test_a_missing_model_is_a_clear_error_and_exit_code_2():
    res = subprocess.run([sys.executable, "-m", "services.vision", "--backend", "onnx", "--model", "/no/such.onnx",
                          "--connect", "tcp/127.0.0.1:9"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2
    assert "not found" in res.stderr and "--backend color" in res.stderr
