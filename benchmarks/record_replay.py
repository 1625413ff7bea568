"""`hri record` / `hri replay` against the bare libraries doing the same work, one run, same payloads.

record: a publisher sends n samples back to back (BLOCK) through the router to
  - bare:  a process whose zenoh callback hands payloads to mcap.Writer.add_message (zstd), nothing else;
  - hri:   `hri record --count n` (queue, stamp decode under the contract, SessionWriter, progress line).
  Figure: samples/s from the first put to the recorder's exit with a finished file (fixed start/finish costs
  are included in both).
replay: the same file, as fast as possible, into a subscriber here:
  - bare:  a process that reads it with mcap.reader and puts each payload on a BLOCK publisher;
  - hri:   `hri replay --speed 0`.
  Figure: samples/s from the first to the last arrival.
Also: the per-sample cost of the in-process core (SessionWriter.add vs Writer.add_message), no zenoh.
Usage: python benchmarks/record_replay.py [--n 2000]
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from common.codec import ENCODING, encode
from common.keys import Keys
from common.transport import open_client
from hri.recording import SessionWriter
from testkit.harness import Proc, ProcessGroup
from testkit.payloads import realistic_samples


def payloads() -> dict[str, tuple[str, bytes]]:
    samples, keys = realistic_samples(), Keys()
    return {
        "Transcript": (keys.transcript("mic0"), encode(samples["Transcript"])),
        "Detections x12": (keys.objects("cam0"), encode(samples["Detections x12"])),
        "Frame 640x480 jpeg": (keys.frame("cam0"), encode(samples["Frame 640x480 jpeg"])),
    }


# -- the bare-library child processes ------------------------------------------------------------
def bare_recorder(endpoint: str, out: str, n: int) -> None:
    s = open_client(endpoint)
    f = open(out, "wb")
    writer = Writer(f, compression=CompressionType.ZSTD)
    writer.start()
    channels: dict[str, int] = {}
    lock, done, count = threading.Lock(), threading.Event(), [0]

    def on(sample: zenoh.Sample) -> None:
        with lock:
            if count[0] >= n:
                return
            key = str(sample.key_expr)
            if key not in channels:
                channels[key] = writer.register_channel(key, "msgpack", 0)
            t = time.time_ns()
            writer.add_message(channels[key], t, sample.payload.to_bytes(), t)
            count[0] += 1
            if count[0] == n:
                done.set()

    sub = s.declare_subscriber("hri/**", on)
    print("recording", flush=True)
    done.wait()
    sub.undeclare()
    writer.finish()
    f.close()
    s.close()


def bare_replayer(endpoint: str, path: str) -> None:
    s = open_client(endpoint)
    pubs: dict[str, zenoh.Publisher] = {}
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            pub = pubs.get(channel.topic)
            if pub is None:
                pub = pubs[channel.topic] = s.declare_publisher(
                    channel.topic,
                    encoding=zenoh.Encoding(ENCODING),
                    congestion_control=zenoh.CongestionControl.BLOCK,
                    priority=zenoh.Priority.DATA_HIGH,
                )
            pub.put(message.data)
    time.sleep(0.3)
    s.close()


# -- the measurements -------------------------------------------------------------------------------
def wait_line(proc, text: str, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while text not in proc.output():
        if not proc.alive() or time.monotonic() > deadline:
            raise RuntimeError(f"{proc.name} did not start:\n{proc.output()}")
        time.sleep(0.05)


def wait_matched(s: zenoh.Session, key: str) -> None:
    pub = s.declare_publisher(key)
    while not pub.matching_status.matching:  # type: ignore[attr-defined]  # zenoh's stub types matching_status as bool; it is a MatchingStatus
        time.sleep(0.02)
    pub.undeclare()


def measure_record(
    group: ProcessGroup, pub_s: zenoh.Session, key: str, payload: bytes, n: int, argv: list[str], out: Path
) -> float:
    proc = Proc("recorder", [sys.executable, *argv])
    group.procs.append(proc)
    wait_line(proc, "recording")
    wait_matched(pub_s, key)
    pub = pub_s.declare_publisher(
        key,
        encoding=zenoh.Encoding(ENCODING),
        congestion_control=zenoh.CongestionControl.BLOCK,
        priority=zenoh.Priority.DATA_HIGH,
    )
    t0 = time.perf_counter()
    for _ in range(n):
        pub.put(payload)
    proc.popen.wait(120)
    elapsed = time.perf_counter() - t0
    pub.undeclare()
    if proc.popen.returncode != 0:
        raise RuntimeError(f"recorder failed:\n{proc.output()}")
    with open(out, "rb") as f:
        got = sum(1 for _ in make_reader(f).iter_messages())
    if got != n:
        raise RuntimeError(f"recorder wrote {got}/{n} samples")
    return n / elapsed


def measure_replay(group: ProcessGroup, sub_s: zenoh.Session, n: int, argv: list[str]) -> float:
    times: list[float] = []
    done = threading.Event()

    def on(_sample: zenoh.Sample) -> None:
        times.append(time.perf_counter())
        if len(times) == n:
            done.set()

    sub = sub_s.declare_subscriber("hri/**", on)
    time.sleep(0.3)
    proc = Proc("replayer", [sys.executable, *argv])
    group.procs.append(proc)
    if not done.wait(120):
        raise RuntimeError(f"only {len(times)}/{n} replayed samples arrived:\n{proc.output()}")
    proc.popen.wait(30)
    sub.undeclare()
    return (n - 1) / (times[-1] - times[0])


def core_costs(key: str, payload: bytes, n: int) -> tuple[float, float]:
    """µs per sample: bare Writer.add_message vs SessionWriter.add (stamp decode + tallies)."""
    bare = Writer(io.BytesIO(), compression=CompressionType.ZSTD)
    bare.start()
    ch = bare.register_channel(key, "msgpack", 0)
    t0 = time.perf_counter()
    for i in range(n):
        bare.add_message(ch, i, payload, i)
    bare.finish()
    t_bare = (time.perf_counter() - t0) / n
    core = SessionWriter(io.BytesIO(), Keys())
    t0 = time.perf_counter()
    for i in range(n):
        core.add(key, payload, i)
    core.finish()
    t_core = (time.perf_counter() - t0) / n
    return t_bare * 1e6, t_core * 1e6


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--bare-recorder":
        bare_recorder(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--bare-replayer":
        bare_replayer(sys.argv[2], sys.argv[3])
        return
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=2000, help="samples per measurement (frames: n/10)")
    args = parser.parse_args()

    group = ProcessGroup()
    group.router()
    pub_s, sub_s = open_client(group.endpoint), open_client(group.endpoint)
    me = str(Path(__file__).resolve())
    tmp = Path(tempfile.mkdtemp(prefix="bench-record-"))
    try:
        print(
            f"{'payload':20s} {'bytes':>7s} | {'core µs/sample':^22s} | {'record samples/s':^24s} | "
            f"{'replay samples/s':^24s}"
        )
        print(
            f"{'':20s} {'':7s} | {'mcap':>7s} {'hri':>7s} {'ratio':>6s} | {'bare':>8s} {'hri':>8s} {'ratio':>6s} | "
            f"{'bare':>8s} {'hri':>8s} {'ratio':>6s}"
        )
        for label, (key, payload) in payloads().items():
            n = max(100, args.n // 10) if len(payload) > 10_000 else args.n
            cb, cc = core_costs(key, payload, n)
            bare_out, hri_out = tmp / f"bare-{n}.mcap", tmp / f"hri-{n}.mcap"
            for p in (bare_out, hri_out):
                p.unlink(missing_ok=True)
            rb = measure_record(
                group, pub_s, key, payload, n, [me, "--bare-recorder", group.endpoint, str(bare_out), str(n)], bare_out
            )
            rh = measure_record(
                group,
                pub_s,
                key,
                payload,
                n,
                [
                    "-m",
                    "hri.cli",
                    "record",
                    "-o",
                    str(hri_out),
                    "hri/**",
                    "--count",
                    str(n),
                    "--connect",
                    group.endpoint,
                ],
                hri_out,
            )
            pb = measure_replay(group, sub_s, n, [me, "--bare-replayer", group.endpoint, str(hri_out)])
            ph = measure_replay(
                group,
                sub_s,
                n,
                ["-m", "hri.cli", "replay", str(hri_out), "--speed", "0", "--connect", group.endpoint],
            )
            print(
                f"{label:20s} {len(payload):7d} | {cb:7.1f} {cc:7.1f} {cc / cb:5.2f}x | {rb:8.0f} {rh:8.0f} "
                f"{rb / rh:5.2f}x | {pb:8.0f} {ph:8.0f} {pb / ph:5.2f}x",
                flush=True,
            )
        print("ratios: > 1 means the hri path is slower than the bare library by that factor")
    finally:
        pub_s.close()
        sub_s.close()
        group.close()


if __name__ == "__main__":
    main()
