"""`hri view` under a 30 fps camera with one browser tab open: the server's CPU, and the frame delay from the
camera's stamp to the frame drawn in the page (Zenoh -> server -> browser), side by side with a bare zenoh
subscriber receiving the same samples in the same run.

    PYTHONPATH=. .venv/bin/python benchmarks/view.py [--seconds 20] [--fps 30]
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import threading
import time
from pathlib import Path

import cv2

from common.codec import encode
from common.schema import Detections, Frame
from services.vision.core import VisionPipeline
from services.vision.segment import ColorSegmenter
from testkit.browser import CHROMIUM, Browser
from testkit.harness import DATA, ROOT, Client, Proc, ProcessGroup
from testkit.images import read_image

BARE_SUBSCRIBER = """
import sys, threading, zenoh
from common.transport import open_client
s = open_client(sys.argv[1])
n = [0]
def on(sample):
    sample.payload.to_bytes(); n[0] += 1
sub = s.declare_subscriber("hri/**", on)
while True:
    threading.Event().wait(5.0)
    print("received", n[0], flush=True)
"""


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--fps", type=float, default=30.0)
    args = parser.parse_args()
    if CHROMIUM is None:
        print("benchmarks/view.py: chromium is not installed (scripts/setup.sh --test installs it); skipped")
        return 0

    image = cv2.resize(read_image(str(DATA / "demo" / "table.png")), (640, 480))
    jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()
    objects, quality = VisionPipeline(ColorSegmenter(labels={"*": "candy"})).process("bench", image)

    group = ProcessGroup()
    browser = None
    client = None
    stop = threading.Event()
    try:
        group.router()
        view = group.start("view", "hri.cli", "view", "--port", "0")
        bare = Proc("bare", [sys.executable, "-c", BARE_SUBSCRIBER, group.endpoint], env={"PYTHONPATH": str(ROOT)})
        group.procs.append(bare)
        deadline = time.monotonic() + 60
        while not (m := re.search(r"(http://\S+/)", view.output())):
            assert time.monotonic() < deadline and view.alive(), view.output()
            time.sleep(0.1)
        url = m.group(1)
        client = Client(group.endpoint)
        sent = [0]

        def camera() -> None:
            next_at = time.monotonic()
            while not stop.is_set():
                stamp = time.time()
                client.session.put(
                    "hri/camera/bench/frame",
                    encode(
                        Frame(
                            stamp=stamp,
                            source="bench/cam",
                            seq=sent[0],
                            cam="bench",
                            width=640,
                            height=480,
                            encoding="jpeg",
                            data=jpeg,
                        )
                    ),
                )
                client.session.put(
                    "hri/vision/bench/objects",
                    encode(
                        Detections(
                            stamp=stamp,
                            source="bench/vision",
                            seq=sent[0],
                            cam="bench",
                            width=640,
                            height=480,
                            objects=objects,
                            quality=quality,
                        )
                    ),
                )
                sent[0] += 1
                next_at += 1.0 / args.fps
                time.sleep(max(0.0, next_at - time.monotonic()))

        threading.Thread(target=camera, daemon=True).start()
        browser = Browser()
        tab = browser.tab(url)
        tab.wait_for("window.hriView && hriView.framesDrawn > 10", 60, "frames")
        time.sleep(2.0)
        tab.js("hriView.delays.length = 0")
        drawn0, sent0 = tab.js("hriView.framesDrawn"), sent[0]
        cpu0 = {p.name: cpu_seconds(p.pid) for p in (view, bare)}
        t0 = time.monotonic()
        time.sleep(args.seconds)
        elapsed = time.monotonic() - t0
        cpu = {p.name: (cpu_seconds(p.pid) - cpu0[p.name]) / elapsed * 100 for p in (view, bare)}
        drawn, delays = tab.js("hriView.framesDrawn") - drawn0, sorted(tab.js("hriView.delays"))
        assert "received" in bare.output() and bare.alive(), f"the bare subscriber did not run: {bare.output()}"
        frames_in = sent[0] - sent0
    finally:
        stop.set()
        if browser is not None:
            browser.close()
        if client is not None:
            client.close()
        group.close()

    def pct(p: float) -> float:
        return delays[min(len(delays) - 1, int(p * len(delays)))] * 1000

    print(
        f"input: {frames_in / elapsed:.1f} frames/s of 640x480 JPEG ({len(jpeg) / 1000:.0f} kB) + Detections "
        f"({len(objects)} objects) each, for {elapsed:.0f} s; one headless Chromium tab"
    )
    print(f"{'process':34s} {'CPU (% of one core)':>20s}")
    print(f"{'hri view (validates, serves page)':34s} {cpu['view']:20.1f}")
    print(f"{'bare zenoh subscriber, same keys':34s} {cpu['bare']:20.1f}")
    print(
        f"page: {drawn / elapsed:.1f} frames/s drawn (budget 10 per camera); frame delay camera stamp -> drawn: "
        f"p50 {pct(0.5):.0f} ms, p95 {pct(0.95):.0f} ms, max {delays[-1] * 1000:.0f} ms "
        f"({len(delays)} frames)"
        if delays
        else "page: no frames drawn"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
