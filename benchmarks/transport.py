"""Per-sample cost of the contract path vs raw zenoh-python + msgpack, same payloads, one run.

contract: encode (validate + pack) -> SamplePublisher.put -> router -> subscriber -> decode (unpack + validate)
raw:      msgpack.packb(dict)      -> Publisher.put       -> router -> subscriber -> msgpack.unpackb

Both paths use the same router, sessions, congestion control (BLOCK) and payload dicts; the ratio is the price
of the contract. Two figures per payload:
- latency: one sample in flight at a time, publish -> decoded in the subscriber (what a sample costs in a live
  pipeline, where sensors publish at 5-30 Hz);
- burst: samples published back to back, total time / n (saturated throughput; here the Python work of both
  ends shares one GIL, so validation shows at its worst).
- codec: encode + decode alone, no zenoh (contract: msgspec typed encode/validate/decode; raw: msgpack
  packb/unpackb of the same dict): the part of the price the contract itself adds.
Target: <= 1.3x.

Depth (the real YCB-Video 640x480 depth image of ../shared/data/rgbd/ycb_video, when present): a DepthFrame raw
(16UC1 rows, 600 kB) and as a lossless 16-bit PNG go through the same paths, so their rows give the wire cost
of each; then the PNG's encode and decode time (OpenCV) and size: what compressing buys and costs.

Usage: python benchmarks/transport.py [--n 2000]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import msgpack  # noqa: E402
import zenoh  # noqa: E402

from common.codec import ENCODING, decode, encode  # noqa: E402
from common.runner import SamplePublisher  # noqa: E402
from benchmarks.payloads import realistic_samples  # noqa: E402
from common.transport import open_client  # noqa: E402
from tests.harness import ProcessGroup  # noqa: E402


def run_once(pub_session, sub_session, key: str, n: int, send, on_payload) -> float:
    """Seconds per sample for n samples published back to back until the last is decoded."""
    done = threading.Event()
    count = [0]

    def callback(sample: zenoh.Sample) -> None:
        on_payload(sample.payload.to_bytes())
        count[0] += 1
        if count[0] == n:
            done.set()

    sub = sub_session.declare_subscriber(key, callback)
    time.sleep(0.3)  # let the subscription reach the router
    t0 = time.perf_counter()
    for _ in range(n):
        send()
    if not done.wait(60):
        raise RuntimeError(f"only {count[0]}/{n} samples arrived on {key}")
    elapsed = time.perf_counter() - t0
    sub.undeclare()
    return elapsed / n


def run_latency(pub_session, sub_session, key: str, n: int, send, on_payload) -> float:
    """Median seconds from publish to decoded, one sample in flight."""
    arrived = threading.Event()

    def callback(sample: zenoh.Sample) -> None:
        on_payload(sample.payload.to_bytes())
        arrived.set()

    sub = sub_session.declare_subscriber(key, callback)
    time.sleep(0.3)
    times = []
    for _ in range(n):
        arrived.clear()
        t0 = time.perf_counter()
        send()
        if not arrived.wait(5):
            raise RuntimeError(f"a sample on {key} did not arrive within 5 s")
        times.append(time.perf_counter() - t0)
    sub.undeclare()
    return statistics.median(times)


def codec_us(encode_one, decode_one, payload: bytes, n: int) -> float:
    """Best-of-5 µs for one encode plus one decode."""
    import timeit
    enc = min(timeit.repeat(encode_one, number=n, repeat=5)) / n
    dec = min(timeit.repeat(lambda: decode_one(payload), number=n, repeat=5)) / n
    return (enc + dec) * 1e6


def depth_samples() -> dict:
    """DepthFrame raw and PNG of the real YCB-Video depth image (empty without ../shared)."""
    import os

    import cv2

    from common.depth import depth_frame
    from common.schema import CameraInfo
    shared = Path(os.environ.get("HRI_SHARED") or Path(__file__).resolve().parent.parent.parent / "shared")
    path = shared / "data" / "rgbd" / "ycb_video" / "000002-depth.png"
    if not path.is_file():
        print(f"(no {path}: the depth rows are skipped; set HRI_SHARED)")
        return {}
    depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    info = CameraInfo(width=640, height=480, k=[1066.778, 0.0, 312.9869, 0.0, 1067.487, 241.3109, 0.0, 0.0, 1.0],
                      frame_id="ycb_camera_optical_frame")
    return {f"DepthFrame 640x480 {c}": depth_frame(depth, stamp=time.time(), source="bench/cam", seq=0, cam="bench",
                                                   depth_scale=0.0001, camera_info=info, compression=c)
            for c in ("none", "png")}


def png_cost(samples: dict) -> None:
    """Encode and decode time of the depth PNG (OpenCV), best of 5 × 20, and the sizes."""
    import timeit

    from common.depth import depth_units, encode_depth
    if not samples:
        return
    raw, png = samples["DepthFrame 640x480 none"], samples["DepthFrame 640x480 png"]
    depth = depth_units(raw)
    enc = min(timeit.repeat(lambda: encode_depth(depth, "png"), number=20, repeat=5)) / 20
    dec = min(timeit.repeat(lambda: depth_units(png), number=20, repeat=5)) / 20
    print(f"depth 640x480: raw {len(raw.data)} bytes, PNG {len(png.data)} bytes "
          f"({len(png.data) / len(raw.data):.2f}x); PNG encode {enc * 1000:.1f} ms, decode {dec * 1000:.1f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=3000, help="samples per measurement (default 3000)")
    parser.add_argument("--repeats", type=int, default=3, help="alternating measurements per path (default 3)")
    args = parser.parse_args()

    group = ProcessGroup()
    group.router()
    pub_s, sub_s = open_client(group.endpoint), open_client(group.endpoint)
    try:
        print(f"{'':31s}{'latency (1 in flight)':^30s} {'burst (back to back)':^30s} {'codec only':^30s}")
        print(f"{'payload':22s} {'bytes':>8s} {'raw µs':>9s} {'contract µs':>12s} {'ratio':>6s}  "
              f"{'raw µs':>9s} {'contract µs':>12s} {'ratio':>6s}  {'raw µs':>9s} {'contract µs':>12s} {'ratio':>6s}")
        worst, worst_burst = 0.0, 0.0
        depth = depth_samples()
        for i, (label, sample) in enumerate({**realistic_samples(), **depth}.items()):
            schema = type(sample)
            as_dict = sample.to_dict()
            size = len(msgpack.packb(as_dict, use_bin_type=True))
            raw_key, contract_key = f"bench/raw/{i}", f"bench/contract/{i}"
            raw_pub = pub_s.declare_publisher(raw_key, encoding=zenoh.Encoding(ENCODING),
                                              congestion_control=zenoh.CongestionControl.BLOCK,
                                              priority=zenoh.Priority.DATA_HIGH)
            contract_pub = SamplePublisher(pub_s, contract_key, lossless=True)
            n = max(200, args.n // 10) if size > 10_000 else args.n
            raw_send = lambda: raw_pub.put(msgpack.packb(as_dict, use_bin_type=True))  # noqa: E731
            raw_recv = lambda b: msgpack.unpackb(b, raw=False)  # noqa: E731
            contract_send = lambda: contract_pub.put(sample)  # noqa: E731
            contract_recv = lambda b: decode(b, schema)  # noqa: E731
            figures = {}
            for mode, measure in (("latency", run_latency), ("burst", run_once)):
                raw_times, contract_times = [], []
                for _ in range(args.repeats):  # alternate so drift hits both paths alike
                    raw_times.append(measure(pub_s, sub_s, raw_key, n, raw_send, raw_recv))
                    contract_times.append(measure(pub_s, sub_s, contract_key, n, contract_send, contract_recv))
                raw_us, contract_us = statistics.median(raw_times) * 1e6, statistics.median(contract_times) * 1e6
                figures[mode] = (raw_us, contract_us, contract_us / raw_us)
            payload = encode(sample)
            raw_payload = msgpack.packb(as_dict, use_bin_type=True)
            raw_codec = codec_us(lambda: msgpack.packb(as_dict, use_bin_type=True), raw_recv, raw_payload, n)
            contract_codec = codec_us(lambda: encode(sample), contract_recv, payload, n)
            figures["codec"] = (raw_codec, contract_codec, contract_codec / raw_codec)
            worst = max(worst, figures["latency"][2])
            worst_burst = max(worst_burst, figures["burst"][2])
            (lr, lc, lx), (br, bc, bx), (cr, cc, cx) = figures["latency"], figures["burst"], figures["codec"]
            print(f"{label:22s} {size:8d} {lr:9.1f} {lc:12.1f} {lx:5.2f}x  {br:9.1f} {bc:12.1f} {bx:5.2f}x  "
                  f"{cr:9.1f} {cc:12.1f} {cx:5.2f}x", flush=True)
            raw_pub.undeclare()
            contract_pub.undeclare()
        print(f"worst ratio: latency {worst:.2f}x, burst {worst_burst:.2f}x (target <= 1.30x)")
        png_cost(depth)
    finally:
        pub_s.close()
        sub_s.close()
        group.close()


if __name__ == "__main__":
    main()
