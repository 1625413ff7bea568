"""What the ros2 service costs: the latency it adds to a fused command, and its CPU at 30 fps of people and objects.

Latency: a router and the ros2 service; this process publishes a FusedCommand on the stack's key, one at a time,
and receives it twice: as the stack's sample (a plain zenoh subscriber decoding the MessagePack: the bare path)
and as the ROS 2 message on rmw_zenoh's key (decoded with rosbags, as a ROS node would). The added latency is
the difference per command; the figures of the bare path are printed beside it.

CPU: Persons (3 people, one with a skeleton in Bodies, one face in Faces) and Detections (12 objects, half with
positions) at 30 fps each for --seconds; the ros2 service's own CPU time over that time (utime + stime from
/proc), as a share of one core. Beside it, in this process: the same samples converted and serialised by the
core alone (services/ros2/core.py + rosbags CDR), and rosbags serialising the same ROS messages prebuilt (the
bare library), per frame.

Usage: python benchmarks/ros2.py [--commands 200] [--seconds 10]
"""

from __future__ import annotations

import argparse
import functools
import os
import statistics
import threading
import time
from typing import Any

import msgspec
import zenoh

from common.codec import decode
from common.schema import Bodies, Detections, Faces, FusedCommand, Persons
from services.ros2 import core
from services.ros2.config import Ros2Config
from services.ros2.rmw import topic_key
from services.ros2.types import deserialize, serialize
from testkit.examples import examples
from testkit.harness import Client, ProcessGroup
from testkit.payloads import realistic_samples

TICK = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK  # utime, stime


def people() -> tuple[Persons, Bodies, Faces]:
    by_name = {type(s).__name__: s for s in examples()}
    persons: Persons = by_name["Persons"]
    template = persons.persons[0]
    crowd = [template] + [
        msgspec.structs.replace(template, id=f"person-{i}", face=None, has_body=False, speaking=0.1) for i in (2, 3)
    ]
    return msgspec.structs.replace(persons, persons=crowd), by_name["Bodies"], by_name["Faces"]


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def latency(group: ProcessGroup, client: Client, n: int) -> None:
    command = realistic_samples()["FusedCommand"]
    assert isinstance(command, FusedCommand)
    arrived: dict[str, dict[str, float]] = {"stack": {}, "ros": {}}
    both = threading.Condition()

    def on_stack(sample: zenoh.Sample) -> None:
        got = decode(sample.payload.to_bytes(), FusedCommand)
        with both:
            arrived["stack"][got.id] = time.perf_counter()
            both.notify_all()

    def on_ros(sample: zenoh.Sample) -> None:
        got = deserialize(sample.payload.to_bytes(), core.FUSED_COMMAND)
        with both:
            arrived["ros"][got.id] = time.perf_counter()
            both.notify_all()

    subs = [
        client.session.declare_subscriber("hri/fusion/command", on_stack),
        client.session.declare_subscriber(topic_key(0, "/hri_fusion/command", core.FUSED_COMMAND), on_ros),
    ]
    client.wait_matched(["hri/fusion/command"])
    sent: dict[str, float] = {}

    def arrived_both(cid: str) -> bool:
        return cid in arrived["stack"] and cid in arrived["ros"]

    for i in range(n + 20):  # the first 20 warm up (publishers declared on first use)
        cid = f"bench-{i}"
        sent[cid] = time.perf_counter()
        client.publish("hri/fusion/command", msgspec.structs.replace(command, id=cid, stamp=time.time()))
        with both:
            both.wait_for(functools.partial(arrived_both, cid), timeout=5)
    for sub in subs:
        sub.undeclare()
    ids = [f"bench-{i}" for i in range(20, n + 20) if f"bench-{i}" in arrived["ros"]]
    bare = [(arrived["stack"][c] - sent[c]) * 1e3 for c in ids]
    ros = [(arrived["ros"][c] - sent[c]) * 1e3 for c in ids]
    added = [r - b for r, b in zip(ros, bare)]
    print(f"\nfused command -> ROS 2 message, {len(ids)} commands one at a time (ms):")
    print(f"  {'path':40s} {'median':>8s} {'p95':>8s}")
    print(
        f"  {'stack sample (zenoh + msgpack, bare)':40s} {statistics.median(bare):8.2f} {percentile(bare, 0.95):8.2f}"
    )
    print(f"  {'ROS 2 message (via the ros2 service)':40s} {statistics.median(ros):8.2f} {percentile(ros, 0.95):8.2f}")
    print(f"  {'added by the ros2 service':40s} {statistics.median(added):8.2f} {percentile(added, 0.95):8.2f}")


def cpu_at_30fps(group: ProcessGroup, client: Client, ros2_pid: int, seconds: float) -> None:
    persons, bodies, faces = people()
    detections = realistic_samples()["Detections x12"]
    assert isinstance(detections, Detections)
    keys = {
        "hri/gesture/cam0/persons": persons,
        "hri/gesture/cam0/bodies": bodies,
        "hri/gesture/cam0/faces": faces,
        "hri/vision/cam0/objects": detections,
    }
    client.wait_matched(list(keys))
    frames, t0 = int(seconds * 30), time.perf_counter()
    cpu0 = cpu_seconds(ros2_pid)
    for i in range(frames):
        stamp = time.time()
        for key, sample in keys.items():
            client.publish(key, msgspec.structs.replace(sample, stamp=stamp, seq=i))
        time.sleep(max(0.0, t0 + (i + 1) / 30 - time.perf_counter()))
    time.sleep(0.5)  # the last ones drain
    wall = time.perf_counter() - t0
    used = cpu_seconds(ros2_pid) - cpu0
    print(f"\n30 fps of Persons x3 + Bodies + Faces + Detections x12 for {wall:.1f} s:")
    print(f"  ros2 service process CPU: {100 * used / wall:.1f} % of one core ({1e3 * used / frames:.2f} ms per frame)")

    config, latch = Ros2Config(), core.Latch()

    def convert_all() -> list[Any]:
        outs = core.persons_messages(persons, config, latch) + core.bodies_messages(bodies, config)
        outs += core.faces_messages(faces, config) + core.detections_messages(detections, config)
        return [serialize(o.message, o.type) for o in outs]

    prebuilt = core.persons_messages(persons, config, core.Latch()) + core.bodies_messages(bodies, config)
    prebuilt += core.faces_messages(faces, config) + core.detections_messages(detections, config)
    reps = 300
    c0 = time.process_time()
    for _ in range(reps):
        convert_all()
    ours = (time.process_time() - c0) / reps
    c0 = time.process_time()
    for _ in range(reps):
        for o in prebuilt:
            serialize(o.message, o.type)
    bare = (time.process_time() - c0) / reps
    print(f"  in-process, per frame ({len(prebuilt)} ROS messages):")
    print(f"    core mapping + CDR (services/ros2/core.py)   {1e3 * ours:.3f} ms CPU")
    print(f"    rosbags CDR of the same messages, prebuilt   {1e3 * bare:.3f} ms CPU (the bare library)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--commands", type=int, default=200)
    ap.add_argument("--seconds", type=float, default=10.0)
    args = ap.parse_args()
    group = ProcessGroup()
    try:
        group.router()
        ros2 = group.service("ros2")
        client = Client(group.endpoint)
        client.wait_alive("ros2", timeout=60)
        latency(group, client, args.commands)
        cpu_at_30fps(group, client, ros2.pid, args.seconds)
        client.close()
    finally:
        group.close()


if __name__ == "__main__":
    main()
