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
Also: the per-sample cost of the in-process core (SessionWriter.add vs Writer.add_message), no zenoh, with the
viewer channels of issue #36 (Foxglove shapes beside the raw payload) and without (`--no-viewers`, the old file).
lag (issue #36): a real camera (the demo photo, 640x480-ish PNG, JPEG on the wire, 30 fps) and vision; the lag of
  each service's output (receive time at a tap here - the sample's stamp) while nothing, `hri record`,
  `hri foxglove` with a foxglove.sdk.v1 client subscribed to every channel, or `hri rerun --save` is attached,
  one after another in one run (the baseline measured first and last: the machine is shared).
Usage (from the checkout's root): python -m benchmarks.record_replay [--n 2000] [--lag-seconds 15] [--only core|lag|all]
"""

from __future__ import annotations

import argparse
import io
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Callable

import zenoh
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from common.codec import ENCODING, encode
from common.keys import Keys
from common.transport import open_client
from hri.recording import SessionWriter, is_raw_channel, raw_payload
from testkit.harness import Client, Proc, ProcessGroup
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
        for schema, channel, message in make_reader(f).iter_messages():
            if not is_raw_channel(schema, channel):
                continue  # the viewer channels (issue #36) are not replayed
            pub = pubs.get(channel.topic)
            if pub is None:
                pub = pubs[channel.topic] = s.declare_publisher(
                    channel.topic,
                    encoding=zenoh.Encoding(ENCODING),
                    congestion_control=zenoh.CongestionControl.BLOCK,
                    priority=zenoh.Priority.DATA_HIGH,
                )
            pub.put(raw_payload(schema, channel, message.data))
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
        got = sum(1 for sc, ch, _ in make_reader(f).iter_messages() if is_raw_channel(sc, ch))
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


def core_costs(key: str, payload: bytes, n: int) -> tuple[float, float, float]:
    """µs per sample: bare Writer.add_message vs SessionWriter.add (stamp decode + tallies), without and with
    the viewer channels."""
    bare = Writer(io.BytesIO(), compression=CompressionType.ZSTD)
    bare.start()
    ch = bare.register_channel(key, "msgpack", 0)
    t0 = time.perf_counter()
    for i in range(n):
        bare.add_message(ch, i, payload, i)
    bare.finish()
    t_bare = (time.perf_counter() - t0) / n
    costs = []
    for viewers in (False, True):
        core = SessionWriter(io.BytesIO(), Keys(), viewers=viewers)
        t0 = time.perf_counter()
        for i in range(n):
            core.add(key, payload, i)
        core.finish()
        costs.append((time.perf_counter() - t0) / n)
    return t_bare * 1e6, costs[0] * 1e6, costs[1] * 1e6


def core_table(n_small: int) -> None:
    print(
        f"{'payload':20s} {'bytes':>7s} | core µs/sample: {'mcap':>7s} {'hri raw':>8s} {'+viewers':>9s} {'added':>7s}"
    )
    for label, (key, payload) in payloads().items():
        n = max(100, n_small // 10) if len(payload) > 10_000 else n_small
        bare, raw, viewers = core_costs(key, payload, n)
        print(f"{label:20s} {len(payload):7d} | {'':15s} {bare:7.1f} {raw:8.1f} {viewers:9.1f} {viewers - raw:6.1f}µ")


def process_table(group: ProcessGroup, pub_s: zenoh.Session, sub_s: zenoh.Session, n_small: int, tmp: Path) -> None:
    me = str(Path(__file__).resolve())
    print(f"{'payload':20s} {'bytes':>7s} | {'record samples/s':^24s} | {'replay samples/s':^24s}")
    print(f"{'':20s} {'':7s} | {'bare':>8s} {'hri':>8s} {'ratio':>6s} | {'bare':>8s} {'hri':>8s} {'ratio':>6s}")
    for label, (key, payload) in payloads().items():
        n = max(100, n_small // 10) if len(payload) > 10_000 else n_small
        bare_out, hri_out = tmp / f"bare-{n}.mcap", tmp / f"hri-{n}.mcap"
        for p in (bare_out, hri_out):
            p.unlink(missing_ok=True)
        bare_argv = [me, "--bare-recorder", group.endpoint, str(bare_out), str(n)]
        rb = measure_record(group, pub_s, key, payload, n, bare_argv, bare_out)
        hri_argv = ["-m", "hri.cli", "record", "-o", str(hri_out), "hri/**", "--count", str(n)]
        rh = measure_record(group, pub_s, key, payload, n, hri_argv + ["--connect", group.endpoint], hri_out)
        pb = measure_replay(group, sub_s, n, [me, "--bare-replayer", group.endpoint, str(hri_out)])
        replay_argv = ["-m", "hri.cli", "replay", str(hri_out), "--speed", "0", "--connect", group.endpoint]
        ph = measure_replay(group, sub_s, n, replay_argv)
        record = f"{rb:8.0f} {rh:8.0f} {rb / rh:5.2f}x"
        print(f"{label:20s} {len(payload):7d} | {record} | {pb:8.0f} {ph:8.0f} {pb / ph:5.2f}x", flush=True)
    print("ratios: > 1 means the hri path is slower than the bare library by that factor (hri record writes the")
    print("viewer channels too when foxglove-sdk is installed)")


# -- live lag with a viewer attached (issue #36) ------------------------------------------------------
class LagTap:
    """receive time - stamp of every camera frame and vision output, per service, while `attached` runs."""

    def __init__(self, s: zenoh.Session, keys: Keys):
        from common.codec import decode
        from common.schema import Detections, Frame

        self.lags: dict[str, list[float]] = {"camera": [], "vision": []}
        self.on = False

        def tap(name: str, schema: type) -> Callable[[zenoh.Sample], None]:
            def on(sample: zenoh.Sample) -> None:
                if self.on:
                    self.lags[name].append(time.time() - decode(sample.payload.to_bytes(), schema).stamp)

            return on

        self.subs = [
            s.declare_subscriber(keys.frame("*"), tap("camera", Frame)),
            s.declare_subscriber(keys.objects("*"), tap("vision", Detections)),
        ]

    def measure(self, seconds: float) -> dict[str, tuple[float, float, int]]:
        for v in self.lags.values():
            v.clear()
        self.on = True
        time.sleep(seconds)
        self.on = False
        out = {}
        for name, lags in self.lags.items():
            ms = sorted(x * 1000 for x in lags) or [float("nan")]
            out[name] = (statistics.median(ms), ms[min(len(ms) - 1, int(0.99 * len(ms)))], len(lags))
        return out


def foxglove_client(url: str, stop: threading.Event, counts: dict[str, int]) -> None:
    """A Foxglove client subscribed to every channel it is offered, counting the bytes it gets."""
    import asyncio
    import json

    import websockets
    from websockets.typing import Subprotocol

    async def run() -> None:
        async with websockets.connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1")], max_size=None) as ws:
            while not stop.is_set():
                try:
                    raw = await asyncio.wait_for(ws.recv(), timeout=0.5)
                except asyncio.TimeoutError:
                    continue
                if isinstance(raw, str):
                    msg = json.loads(raw)
                    if msg.get("op") == "advertise":
                        subs = [{"id": c["id"], "channelId": c["id"]} for c in msg["channels"]]
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                else:
                    counts["messages"] += 1
                    counts["bytes"] += len(raw)

    asyncio.run(run())


def attach(group: ProcessGroup, what: str, tmp: Path) -> tuple[Proc | None, Callable[[], None]]:
    """Start the viewer bridge `what`; (its process, a function that stops what else was started)."""
    import re

    base = [sys.executable, "-m", "hri.cli"]
    connect = ["--connect", group.endpoint]
    if what == "nothing":
        return None, lambda: None
    if what == "hri record":
        proc = Proc(what, base + ["record", "-o", str(tmp / "lag.mcap"), "--force", *connect])
        wait_line(proc, "recording")
        return proc, lambda: None
    if what == "hri rerun --save":
        proc = Proc(what, base + ["rerun", "--save", str(tmp / "lag.rrd"), *connect])
        time.sleep(3)  # rerun-sdk's start-up
        return proc, lambda: None
    proc = Proc(what, base + ["foxglove", "--port", "0", *connect])
    wait_line(proc, "ws://")
    port = re.search(r"ws://127\.0\.0\.1:(\d+)", proc.output())
    assert port is not None
    stop, counts = threading.Event(), {"messages": 0, "bytes": 0}
    client = threading.Thread(target=foxglove_client, args=(f"ws://127.0.0.1:{port.group(1)}", stop, counts))
    client.start()

    def done() -> None:
        stop.set()
        client.join(5)
        print(f"    (the Foxglove client got {counts['messages']} messages, {counts['bytes'] / 1e6:.0f} MB)")

    return proc, done


def lag_table(group: ProcessGroup, seconds: float, tmp: Path) -> None:
    table = Path(__file__).resolve().parents[1] / "data" / "demo" / "table.png"
    group.service("camera", "--source", str(table), "--cam", "bench", "--fps", "30", "--loop")
    group.service("vision", "--labels", str(table.with_name("labels.json")))
    tap_s = open_client(group.endpoint)
    try:
        Client(group.endpoint).wait_alive("vision", timeout=90)
        tap = LagTap(tap_s, Keys())
        time.sleep(3)  # the services warm up
        print(f"lag at 30 fps, {seconds:.0f} s each, ms (p50 / p99 / samples) — one run, one after another:")
        print(f"{'attached':22s} | {'camera':^22s} | {'vision':^22s}")
        for what in ("nothing", "hri record", "hri foxglove + client", "hri rerun --save", "nothing"):
            proc, done = attach(group, what, tmp)
            time.sleep(1)
            got = tap.measure(seconds)
            done()
            if proc is not None:
                proc.terminate(timeout=10)
            cells = " | ".join(f"{p50:6.1f} {p99:7.1f} {n:6d}" for p50, p99, n in got.values())
            print(f"{what:22s} | {cells}", flush=True)
    finally:
        tap_s.close()


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--bare-recorder":
        bare_recorder(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--bare-replayer":
        bare_replayer(sys.argv[2], sys.argv[3])
        return
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=2000, help="samples per measurement (frames: n/10)")
    parser.add_argument("--lag-seconds", type=float, default=15.0, help="seconds per lag measurement")
    parser.add_argument("--only", choices=("core", "lag", "all"), default="all")
    args = parser.parse_args()

    core_table(args.n)
    if args.only == "core":
        return
    group = ProcessGroup()
    group.router()
    pub_s, sub_s = open_client(group.endpoint), open_client(group.endpoint)
    tmp = Path(tempfile.mkdtemp(prefix="bench-record-"))
    try:
        if args.only == "all":
            process_table(group, pub_s, sub_s, args.n, tmp)
        lag_table(group, args.lag_seconds, tmp)
    finally:
        pub_s.close()
        sub_s.close()
        group.close()


if __name__ == "__main__":
    main()
