"""camera (image folder) -> vision -> hri echo, as real processes."""

import subprocess
import sys

import pytest

from testkit.harness import DATA, ROOT, Client
from testkit.images import read_image

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
    assert by_scene[506] == ["blue", "blue", "green", "green", "red"]  # table.png
    assert by_scene[640] == ["blue", "red"]  # pointing.png


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
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "services.vision",
            "--backend",
            "onnx",
            "--model",
            "/no/such.onnx",
            "--connect",
            "tcp/127.0.0.1:9",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 2
    assert "not found" in res.stderr and "--backend color" in res.stderr


def _frame(img, seq: int, stamp: float, encoding: str = "jpeg", data: bytes | None = None, cam: str = "cam0"):
    import cv2

    from common.schema import Frame

    if data is None:
        data = cv2.imencode(".jpg" if encoding == "jpeg" else ".png", img)[1].tobytes()
    return Frame(
        stamp=stamp,
        source="test/cam",
        seq=seq,
        cam=cam,
        width=img.shape[1],
        height=img.shape[0],
        encoding=encoding,  # type: ignore[arg-type]  # the test sends every encoding, valid or not
        data=data,
    )


def test_undecodable_frames_are_counted_and_the_service_goes_on(group):
    import time

    import cv2

    img = read_image(str(DATA / "demo" / "table.png"))
    group.router()
    proc = group.service("vision")
    client = Client(group.endpoint)
    try:
        client.wait_alive("vision", timeout=60)
        out = client.collect("hri/vision/cam0/objects")
        good_jpeg = cv2.imencode(".jpg", img)[1].tobytes()
        # two cameras: each has its own latest-frame slot, so neither bad frame can be skipped for the other
        client.publish(
            "hri/camera/bad1/frame", _frame(img, 1, time.time(), data=good_jpeg[: len(good_jpeg) // 3], cam="bad1")
        )
        small = cv2.imencode(".png", cv2.resize(img, (100, 80)))[1].tobytes()  # header says 506×460
        client.publish("hri/camera/bad2/frame", _frame(img, 2, time.time(), "png", data=small, cam="bad2"))
        time.sleep(0.5)
        client.publish("hri/camera/cam0/frame", _frame(img, 3, time.time()))
        ((_, det),) = out.wait(1, timeout=30)
        assert det.seq == 3 and len(det.objects) >= 6
        stats = client.stats("vision")
        # the truncated JPEG fails to decode; the PNG's header (100x80) contradicts its frame: rejected unread
        assert stats["rejected"].get("undecodable", 0) == 1 and stats["rejected"].get("bad_value", 0) == 1, stats
        assert proc.alive() and "does not decode" in proc.output()
        assert "png header says 100x80, the frame declares 506x460" in proc.output()
    finally:
        client.close()


def test_a_burst_of_frames_is_skipped_to_the_latest_not_queued(group):
    import time

    import cv2

    big = cv2.resize(read_image(str(DATA / "images" / "tabletop" / "smarties.png")), (1280, 1104))
    group.router()
    group.service("vision")
    client = Client(group.endpoint)
    try:
        client.wait_alive("vision", timeout=60)
        out = client.collect("hri/vision/cam0/objects")
        data = cv2.imencode(".jpg", big)[1].tobytes()
        stamps = []
        for seq in range(40):  # back to back: far faster than a 1280-pixel frame is processed
            stamps.append(time.time())
            client.publish("hri/camera/cam0/frame", _frame(big, seq, stamps[-1], data=data))
        last = out.wait(1, timeout=60, where=lambda k, s: s.seq == 39)[0][1]
        assert last.stamp == stamps[39]  # Detections carry the frame's own stamp
        time.sleep(0.5)
        got = [s for _, s in out.drain(0.5)]
        seqs = [s.seq for s in got]
        assert seqs == sorted(seqs) and len(got) < 40
        stats = client.stats("vision")
        assert stats["skipped"] >= 1 and stats["published"] + stats["skipped"] == 40, stats
        assert all(len(s.objects) >= 12 for s in got)  # the photo's candies, at any frame it processed
    finally:
        client.close()


def test_a_bad_labels_file_is_a_clear_error_and_exit_code_2(tmp_path):
    bad = tmp_path / "labels.json"
    bad.write_text('{"pink": "candy"}')
    res = subprocess.run(
        [sys.executable, "-m", "services.vision", "--labels", str(bad), "--connect", "tcp/127.0.0.1:9"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 2
    assert "not colours" in res.stderr


def test_onnx_backend_without_a_model_runs_the_color_backend(group):
    import time

    img = read_image(str(DATA / "demo" / "table.png"))
    group.router()
    proc = group.service("vision", "--backend", "onnx")
    client = Client(group.endpoint)
    try:
        client.wait_alive("vision", timeout=60)
        out = client.collect("hri/vision/cam0/objects")
        client.publish("hri/camera/cam0/frame", _frame(img, 0, time.time()))
        ((_, det),) = out.wait(1, timeout=30)
        assert sorted(o.color for o in det.objects if o.color in ("red", "green", "blue")) == [
            "blue",
            "blue",
            "green",
            "green",
            "red",
        ]
        assert "without --model" in proc.output()
    finally:
        client.close()


def test_the_real_yolox_model_through_the_service_finds_the_cup(group, tmp_path):
    """`--backend onnx --model yolox_nano.onnx` as a real process: the family is logged, the cup is published."""
    pytest.importorskip("onnxruntime")
    from testkit.shared import yolox_model

    model = yolox_model()
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "coffee.png").write_bytes((DATA / "images" / "coffee.png").read_bytes())
    group.router()
    proc = group.service("vision", "--backend", "onnx", "--model", str(model))
    group.service("camera", "--source", str(folder), "--fps", "5", "--loop")
    got = group.echo("hri/vision/cam0/objects", count=2, timeout=60)
    for d in got:
        cups = [o for o in d["objects"] if o["label"] == "cup"]
        assert len(cups) == 1 and cups[0]["score"] > 0.6, d["objects"]
        x, y, w, h = cups[0]["bbox"]
        assert abs(x + w / 2 - 292) < 30 and abs(y + h / 2 - 160) < 30, cups[0]  # the cup's centre, by eye
    assert "yolox detector" in proc.output()
