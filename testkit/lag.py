"""What the frame-consuming services' benchmarks share: the side-by-side throughput report, the command line,
and the end-to-end lag of a real service process (frames at a fixed rate in, its output's stamp vs receive time)."""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Callable

import cv2
import numpy as np
import zenoh

from common.codec import decode
from common.runner import SamplePublisher
from common.schema import Frame, Sample
from testkit.harness import Client, ProcessGroup


def frame_lag(
    service: str,
    service_args: list[str],
    out_key: str,
    schema: type[Sample],
    frames: list[np.ndarray],
    seconds: float,
    fps: float = 30.0,
) -> None:
    """Publish `frames` (cycled) as camera `bench` at `fps` for `seconds` into a real `service` process and print
    lag = receive time - stamp of its outputs on `out_key`, p50/p99 per slice (it must not grow)."""
    group = ProcessGroup()
    group.router()
    group.service(service, *service_args)
    client = Client(group.endpoint)
    lags: list[tuple[float, float]] = []  # (seconds since start, lag)
    start = time.time()

    def on_output(sample: zenoh.Sample) -> None:
        out = decode(sample.payload.to_bytes(), schema)
        now = time.time()
        lags.append((now - start, now - out.stamp))

    try:
        client.wait_alive(service, timeout=90)
        sub = client.session.declare_subscriber(out_key, on_output)
        pub = SamplePublisher(client.session, "hri/camera/bench/frame", lossless=False)
        payloads = [cv2.imencode(".jpg", f, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes() for f in frames]
        h, w = frames[0].shape[:2]
        sent = 0
        start = time.time()
        next_at = time.monotonic()
        while time.time() - start < seconds:
            next_at += 1.0 / fps
            pub.put(
                Frame(
                    stamp=time.time(),
                    source="bench/cam",
                    seq=sent,
                    cam="bench",
                    width=w,
                    height=h,
                    encoding="jpeg",
                    data=payloads[sent % len(payloads)],
                )
            )
            sent += 1
            delay = next_at - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        time.sleep(1.0)
        sub.undeclare()
        pub.undeclare()
        stats = client.stats(service)
    finally:
        client.close()
        group.close()
    print(
        f"end-to-end lag at {fps:.0f} fps for {seconds:.0f} s: {sent} frames sent, {len(lags)} outputs received, "
        f"{stats['skipped']} stale frames skipped by the service"
    )
    print_lag_slices(lags, seconds)


def print_lag_slices(lags: list[tuple[float, float]], seconds: float) -> None:
    """p50/p99 of (time since start, lag) pairs per sixth of the run, then overall: a lag that grows is a backlog."""
    slice_s = max(seconds / 6, 1.0)
    for k in range(int(seconds // slice_s)):
        part = [lag for t, lag in lags if k * slice_s <= t < (k + 1) * slice_s]
        if part:
            p50, p99 = np.percentile(part, [50, 99]) * 1000
            print(
                f"  {k * slice_s:4.0f}-{(k + 1) * slice_s:3.0f} s  p50 {p50:6.1f} ms  p99 {p99:6.1f} ms  n={len(part)}"
            )
    if lags:
        p50, p99 = np.percentile([lag for _, lag in lags], [50, 99]) * 1000
        print(f"  overall    p50 {p50:6.1f} ms  p99 {p99:6.1f} ms")


def print_throughput(
    title: str, bare_label: str, bare_fps: list[float], service_label: str, service_fps: list[float]
) -> None:
    b, s = statistics.median(bare_fps), statistics.median(service_fps)
    print(f"{title} (median of {len(bare_fps)}):")
    print(f"  {bare_label:32s} {b:7.1f} frames/s")
    print(f"  {service_label:32s} {s:7.1f} frames/s   ratio {s / b:.2f}x (target >= 0.90x)")


def frame_benchmark_main(
    doc: str,
    service: str,
    out_key: str,
    schema: type[Sample],
    frames: Callable[[], list],
    throughput: Callable[[list, int], None],
) -> None:
    parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the lag run (default 60)")
    parser.add_argument("--frames", type=int, default=300, help="frames per throughput measurement (default 300)")
    args = parser.parse_args()
    images = frames()
    throughput(images, args.frames)
    frame_lag(service, [], out_key, schema, images, args.seconds)
