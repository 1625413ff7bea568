"""Per-sample cost of the contract path vs raw zenoh-python + msgpack, same payloads, one run.

contract: encode (validate + pack) -> SamplePublisher.put -> router -> subscriber -> decode (unpack + validate)
raw:      msgpack.packb(dict)      -> Publisher.put       -> router -> subscriber -> msgpack.unpackb

Both paths use the same router, sessions, congestion control (BLOCK) and payload dicts; the ratio is the price
of the contract. Two figures per payload:
- latency: one sample in flight at a time, publish -> decoded in the subscriber (what a sample costs in a live
  pipeline, where sensors publish at 5-30 Hz);
- burst: samples published back to back, total time / n (saturated throughput; here the Python work of both
  ends shares one GIL, so validation shows at its worst). Printed twice: wall time, and this process's CPU
  time (both ends and zenoh's threads; the router is another process, the same for both paths). On a machine
  shared with other work the wall figure moves by 2x between runs; the CPU figure is what the contract costs.
- ratios: the median over the alternating repeats of (contract / raw) of neighbouring runs, so a load change
  during the run hits both sides of each ratio alike.
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
import threading
import time
from pathlib import Path

import msgpack
import zenoh

from common.codec import ENCODING, decode, encode
from common.runner import SamplePublisher
from common.transport import open_client
from testkit.harness import ProcessGroup
from testkit.images import read_image
from testkit.payloads import realistic_samples


def run_once(pub_session, sub_session, key: str, n: int, send, on_payload) -> tuple[float, float]:
    """(wall, CPU) seconds per sample for n samples published back to back until the last is decoded."""
    done = threading.Event()
    count = [0]

    def callback(sample: zenoh.Sample) -> None:
        on_payload(sample.payload.to_bytes())
        count[0] += 1
        if count[0] == n:
            done.set()

    sub = sub_session.declare_subscriber(key, callback)
    time.sleep(0.3)  # let the subscription reach the router
    t0, cpu0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        send()
    if not done.wait(60):
        raise RuntimeError(f"only {count[0]}/{n} samples arrived on {key}")
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    sub.undeclare()
    return elapsed / n, cpu / n


def run_latency(pub_session, sub_session, key: str, n: int, send, on_payload) -> tuple[float]:
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
    return (statistics.median(times),)


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
    depth = read_image(str(path), cv2.IMREAD_UNCHANGED)
    info = CameraInfo(
        width=640,
        height=480,
        k=[1066.778, 0.0, 312.9869, 0.0, 1067.487, 241.3109, 0.0, 0.0, 1.0],
        frame_id="ycb_camera_optical_frame",
    )
    return {
        f"DepthFrame 640x480 {c}": depth_frame(
            depth,
            stamp=time.time(),
            source="bench/cam",
            seq=0,
            cam="bench",
            depth_scale=0.0001,
            camera_info=info,
            compression=c,
        )
        for c in ("none", "png")
    }


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
    print(
        f"depth 640x480: raw {len(raw.data)} bytes, PNG {len(png.data)} bytes "
        f"({len(png.data) / len(raw.data):.2f}x); PNG encode {enc * 1000:.1f} ms, decode {dec * 1000:.1f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=3000, help="samples per measurement (default 3000)")
    parser.add_argument("--repeats", type=int, default=5, help="alternating measurements per path (default 5)")
    args = parser.parse_args()

    group = ProcessGroup()
    group.router()
    pub_s, sub_s = open_client(group.endpoint), open_client(group.endpoint)
    try:
        columns = ("latency (1 in flight)", "burst (back to back)", "burst, CPU", "codec only")
        print(f"{'':31s}" + " ".join(f"{c:^30s}" for c in columns))
        print(f"{'payload':22s} {'bytes':>8s}" + f" {'raw µs':>9s} {'contract µs':>12s} {'ratio':>6s} " * 4)
        worst = {"latency": 0.0, "burst": 0.0, "burst_cpu": 0.0}
        depth = depth_samples()
        for i, (label, sample) in enumerate({**realistic_samples(), **depth}.items()):
            schema = type(sample)
            as_dict = sample.to_dict()
            size = len(msgpack.packb(as_dict, use_bin_type=True))
            raw_key, contract_key = f"bench/raw/{i}", f"bench/contract/{i}"
            raw_pub = pub_s.declare_publisher(
                raw_key,
                encoding=zenoh.Encoding(ENCODING),
                congestion_control=zenoh.CongestionControl.BLOCK,
                priority=zenoh.Priority.DATA_HIGH,
            )
            contract_pub = SamplePublisher(pub_s, contract_key, lossless=True)
            n = max(200, args.n // 10) if size > 10_000 else args.n
            # (the lambdas are used within this iteration only: B023 does not apply)
            raw_send = lambda: raw_pub.put(msgpack.packb(as_dict, use_bin_type=True))  # noqa: E731, B023
            raw_recv = lambda b: msgpack.unpackb(b, raw=False)  # noqa: E731, B023
            contract_send = lambda: contract_pub.put(sample)  # noqa: E731, B023
            contract_recv = lambda b: decode(b, schema)  # noqa: E731, B023
            figures = {}
            for modes, measure in ((("latency",), run_latency), (("burst", "burst_cpu"), run_once)):
                raw_runs, contract_runs = [], []
                for _ in range(args.repeats):  # alternate so drift hits both paths alike
                    raw_runs.append(measure(pub_s, sub_s, raw_key, n, raw_send, raw_recv))
                    contract_runs.append(measure(pub_s, sub_s, contract_key, n, contract_send, contract_recv))
                for j, mode in enumerate(modes):
                    raw_t, contract_t = [r[j] for r in raw_runs], [c[j] for c in contract_runs]
                    ratio = statistics.median(c / r for r, c in zip(raw_t, contract_t))
                    figures[mode] = (statistics.median(raw_t) * 1e6, statistics.median(contract_t) * 1e6, ratio)
            payload = encode(sample)
            raw_payload = msgpack.packb(as_dict, use_bin_type=True)
            raw_codec = codec_us(
                lambda: msgpack.packb(as_dict, use_bin_type=True),  # noqa: B023
                raw_recv,
                raw_payload,
                n,
            )
            contract_codec = codec_us(lambda: encode(sample), contract_recv, payload, n)  # noqa: B023
            figures["codec"] = (raw_codec, contract_codec, contract_codec / raw_codec)
            for mode in worst:
                worst[mode] = max(worst[mode], figures[mode][2])
            print(
                f"{label:22s} {size:8d}"
                + "".join(
                    f" {r:9.1f} {c:12.1f} {x:5.2f}x "
                    for r, c, x in (figures[m] for m in ("latency", "burst", "burst_cpu", "codec"))
                ),
                flush=True,
            )
            raw_pub.undeclare()
            contract_pub.undeclare()
        print(
            f"worst ratio: latency {worst['latency']:.2f}x, burst {worst['burst']:.2f}x, "
            f"burst CPU {worst['burst_cpu']:.2f}x (target <= 1.30x)"
        )
        png_cost(depth)
    finally:
        pub_s.close()
        sub_s.close()
        group.close()


if __name__ == "__main__":
    main()
