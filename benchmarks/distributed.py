"""The stack across (namespace) hosts: latency, reconnection after a cut link, commands lost over outages.

1. latency: last word -> command. A final Transcript is published (its `end`, the last word, is the publish
   time) and the FusedCommand it causes is timed at the subscriber: router, fusion and this process all on
   loopback, vs router, fusion and this process each in its own network namespace (testkit/netns.py: veth
   links through the router's namespace). Only fusion runs (a "turn left" needs no vision): the figure is the
   price of the extra hops, not of perception.
2. reconnection: the perception host (a camera service) loses its link for --outage seconds (5 by default);
   time from the link's return until its liveliness token is back on the router, p50/max over the outages.
3. commands lost / duplicated: during each outage --per-outage commands are published by fusion while a
   recovering consumer (testkit/recovering_echo.py) sits behind the cut link; after every outage the consumer
   must have every command once, in order. Goal 0 and 0.

Needs root (network namespaces). Usage:
  python benchmarks/distributed.py [--n 40] [--outages 10] [--outage 5] [--per-outage 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

from hri.cli import make_transcript
from testkit.harness import DATA, Client, ProcessGroup
from testkit.netns import NetnsGroup, Network, cleanup_leftovers, unavailable

WORDS = ["turn left", "turn right"]


def latencies(client: Client, n: int) -> list[float]:
    out = client.collect("hri/fusion/command")
    time.sleep(1.0)
    result = []
    for i in range(n):
        before = len(out.seen)
        t0 = time.time()
        client.publish(
            "hri/speech/kbd/transcript",
            make_transcript(WORDS[i % 2], mic="kbd", end=t0, confidence=0.95, source="bench/kbd", seconds_per_word=0.2),
        )
        out.wait(before + 1, timeout=10)
        result.append(time.time() - t0)
        time.sleep(0.05)
    return result


def loopback_latency(n: int) -> list[float]:
    g = ProcessGroup()
    try:
        g.router()
        g.service("fusion")
        client = Client(g.endpoint)
        try:
            client.wait_alive("fusion", timeout=60)
            return latencies(client, n)
        finally:
            client.close()
    finally:
        g.close()


def consumer_ids(proc) -> list[str]:
    return [json.loads(line)["id"] for line in proc.output().splitlines() if line.startswith("{")]


def wait(condition, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.02)
    return False


def distributed(args) -> dict:
    net = Network()
    g = NetnsGroup(net)
    try:
        g.router()
        g.service("fusion", host="speech")
        g.service("camera", "--source", str(DATA / "demo" / "table.png"), "--fps", "5", "--loop", host="perception")
        consumer = g.start(
            "consumer",
            "testkit.recovering_echo",
            net.endpoint("perception"),
            "hri/fusion/command",
            connect=False,
            host="perception",
        )
        client = Client(g.endpoint)
        try:
            client.wait_alive("fusion", timeout=60)
            client.wait_alive("camera", timeout=60)
            wait(lambda: "ready" in consumer.output(), 30)
            lat = latencies(client, args.n)
            wait(lambda: len(consumer_ids(consumer)) >= args.n, 10)
            base = len(consumer_ids(consumer))  # the consumer saw the timed commands too
            sent = client.collect("hri/fusion/command")
            reconnect, lost, duplicated, late = [], 0, 0, 0
            for k in range(args.outages):
                net.set_link("perception", up=False)
                t_cut = time.monotonic()
                time.sleep(min(3.5, args.outage * 0.7))  # past the lease: the consumer's session is gone
                for i in range(args.per_outage):
                    client.publish(
                        "hri/speech/kbd/transcript",
                        make_transcript(
                            WORDS[i % 2],
                            mic="kbd",
                            end=time.time(),
                            confidence=0.95,
                            source="bench/kbd",
                            seconds_per_word=0.2,
                        ),
                    )
                    time.sleep(0.1)
                time.sleep(max(0.0, t_cut + args.outage - time.monotonic()))
                net.set_link("perception", up=True)
                t_up = time.monotonic()
                back = wait(lambda: any(s == "camera" for s, _ in client.alive(0.3)), 30)
                if back:
                    reconnect.append(time.monotonic() - t_up)
                expected = len(consumer_ids(consumer)) + args.per_outage
                sent.drain(0.0)
                if not wait(lambda expected=expected: len(consumer_ids(consumer)) >= expected, 10):
                    late += 1
                time.sleep(0.5)
                sent.drain(0.0)
                got = consumer_ids(consumer)[base:]
                want = [s.id for _, s in sent.seen]
                lost = len(set(want) - set(got))
                duplicated = len(got) - len(set(got))
                took = f"{reconnect[-1]:.2f} s" if back else "not within 30 s"
                print(
                    f"  outage {k + 1}/{args.outages}: reconnected {took} after the link returned; "
                    f"commands sent {len(want)}, at the consumer {len(got)}, lost {lost},"
                    f" duplicated {duplicated}, in order {got == want}",
                    flush=True,
                )
            return {
                "latency": lat,
                "reconnect": reconnect,
                "lost": lost,
                "duplicated": duplicated,
                "in_order": consumer_ids(consumer)[base:] == [s.id for _, s in sent.seen],
                "commands": len(sent.seen),
                "late": late,
            }
        finally:
            client.close()
    finally:
        g.close()
        net.close()


def ms(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return 1000 * xs[min(len(xs) - 1, int(q * len(xs)))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=40, help="commands timed per setup")
    parser.add_argument("--outages", type=int, default=10, help="link cuts")
    parser.add_argument("--outage", type=float, default=5.0, help="seconds each cut lasts")
    parser.add_argument("--per-outage", type=int, default=3, help="commands published during each cut")
    args = parser.parse_args()
    reason = unavailable()
    if reason:
        raise SystemExit(f"benchmarks/distributed.py: {reason}")
    cleanup_leftovers()
    loop = loopback_latency(args.n)
    d = distributed(args)
    lat = d["latency"]
    print(f"last word -> command, {args.n} commands (p50 / p95 ms):")
    print(f"  all on loopback          {ms(loop, 0.5):7.1f} / {ms(loop, 0.95):7.1f}")
    print(f"  separate namespaces      {ms(lat, 0.5):7.1f} / {ms(lat, 0.95):7.1f}")
    print(f"  ratio (p50)              {statistics.median(lat) / statistics.median(loop):7.2f}x")
    rec = d["reconnect"]
    if rec:
        print(
            f"reconnection after a {args.outage:g} s cut, {len(rec)} outages: "
            f"p50 {1000 * statistics.median(rec):.0f} ms, max {1000 * max(rec):.0f} ms "
            "(link up -> liveliness token back)"
        )
    print(
        f"commands over {args.outages} outages ({d['commands']} sent, {args.per_outage} per outage while cut): "
        f"lost {d['lost']}, duplicated {d['duplicated']}, in order {d['in_order']}; outages after which the "
        f"consumer needed more than 10 s to catch up: {d['late']}"
    )


if __name__ == "__main__":
    main()
