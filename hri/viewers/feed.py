"""Shell: the live stack (or a recording) as a stream of decoded samples for a viewer bridge.

`LiveFeed` subscribes to `<prefix>/**`, validates every sample under the contract (an invalid one is counted,
logged rate-limited and dropped), polls the services' Stats, and hands (key, sample, receive_ns) to a sink on
ONE worker thread: zenoh's callbacks only enqueue, so a slow viewer costs the bridge a backlog (dropped and
counted past `max_backlog`), never the stack. `replay_recording` feeds a recording's samples to the same sink.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from common.codec import decode
from common.keys import Keys
from common.schema import InvalidSample, Sample, Stats

Sink = Callable[[str, Sample, int], None]
STATS_EVERY_S = 2.0
MAX_BACKLOG = 256  # samples waiting for the sink; past it new ones are dropped (a viewer must not grow memory)


@dataclass
class FeedCounts:
    received: int = 0
    shown: int = 0
    invalid: dict[str, int] = field(default_factory=dict)  # key -> invalid samples
    dropped: int = 0  # the sink was too slow
    failed: int = 0  # the sink raised on a valid sample


class RateLimitedLog:
    """Logs the first few occurrences, then every 100th: bad input never floods the log."""

    def __init__(self, log: logging.Logger):
        self.log = log
        self.count = 0

    def warning(self, fmt: str, *args: Any) -> None:
        self.count += 1
        if self.count <= 5 or self.count % 100 == 0:
            self.log.warning(fmt + " (#%d)", *args, self.count)


class LiveFeed:
    def __init__(self, session: Any, keys: Keys, sink: Sink, log: logging.Logger, skip: tuple[str, ...] = ()):
        import zenoh

        self.session, self.keys, self.sink, self.log = session, keys, sink, log
        self.counts = FeedCounts()
        self.bad = RateLimitedLog(log)
        self.inbox: queue.Queue[tuple[str, Sample, int] | None] = queue.Queue(MAX_BACKLOG)
        self.stop = threading.Event()
        skipped = [zenoh.KeyExpr(expr) for expr in skip]

        def on_sample(sample: zenoh.Sample) -> None:
            key = str(sample.key_expr)
            if sample.kind != zenoh.SampleKind.PUT or any(s.intersects(key) for s in skipped):
                return
            self.take(key, sample.payload.to_bytes(), time.time_ns())

        self.subscriber = session.declare_subscriber(f"{keys.prefix}/**", on_sample)
        self.worker = threading.Thread(target=self._work, name="viewer-feed", daemon=True)
        self.worker.start()
        self.poller = threading.Thread(target=self._poll_stats, name="viewer-stats", daemon=True)
        self.poller.start()

    def take(self, key: str, payload: bytes, receive_ns: int) -> None:
        self.counts.received += 1
        schema = self.keys.schema_for(key)
        if schema is None:
            return  # not ours (liveliness, another tool's keys): nothing a viewer would show
        try:
            sample = decode(payload, schema)
        except InvalidSample as exc:
            self.counts.invalid[key] = self.counts.invalid.get(key, 0) + 1
            self.bad.warning("dropped an invalid sample on %s: %s", key, exc.reason)
            return
        try:
            self.inbox.put_nowait((key, sample, receive_ns))
        except queue.Full:
            self.counts.dropped += 1
            self.bad.warning("the viewer is behind: dropped a sample on %s", key)

    def _work(self) -> None:
        while True:
            item = self.inbox.get()
            if item is None:
                return
            try:
                self.sink(*item)
                self.counts.shown += 1
            except Exception as exc:  # a viewer's library refusing one sample must not end the bridge
                self.counts.failed += 1
                self.bad.warning("could not show a sample on %s: %s: %s", item[0], type(exc).__name__, exc)

    def _poll_stats(self) -> None:
        while not self.stop.wait(STATS_EVERY_S):
            try:
                for reply in self.session.get(self.keys.stats("*", "*"), timeout=1.0):
                    if reply.ok is not None:
                        self._stats_reply(str(reply.ok.key_expr), reply.ok.payload.to_bytes())
            except Exception as exc:  # the session is closing, or the router went away for a while
                if not self.stop.is_set():
                    self.log.debug("stats query failed: %s", exc)

    def _stats_reply(self, key: str, payload: bytes) -> None:
        try:
            stats = decode(payload, Stats)
        except InvalidSample as exc:
            self.bad.warning("dropped an invalid Stats reply on %s: %s", key, exc.reason)
            return
        try:
            self.inbox.put_nowait((key, stats, time.time_ns()))
        except queue.Full:
            self.counts.dropped += 1

    def close(self) -> None:
        self.stop.set()
        try:
            self.subscriber.undeclare()
        except Exception:
            pass
        self.inbox.put(None)
        self.worker.join(timeout=5.0)


def replay_recording(path: str, sink: Sink, keys: Keys | None = None) -> int:
    """Every valid contract sample of a recording to `sink` with its recorded receive time; returns the count."""
    from hri.recording import SessionReader, contract_sample

    reader = SessionReader(path)
    keys = keys or Keys(reader.metadata().get("prefix") or Keys().prefix)
    n = 0
    try:
        for m in reader.messages():
            sample = contract_sample(m.key, m.payload, keys)
            if sample is not None:
                sink(m.key, sample, m.log_ns)
                n += 1
    finally:
        reader.close()
    return n
