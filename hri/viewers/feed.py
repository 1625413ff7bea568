"""Shell: the live stack (or a recording) as a stream of decoded samples for a viewer bridge.

`LiveFeed` subscribes to `<prefix>/**`, validates every sample under the contract (an invalid one is counted,
logged rate-limited and dropped), polls the services' Stats, and hands (key, sample, receive_ns) to a sink on
ONE worker thread: zenoh's callbacks only enqueue, so a slow viewer never slows the stack. Streams (frames,
depth, detections, hands, bodies, faces, persons) keep only their latest sample per key while the viewer is
behind (replaced ones are counted as skipped); events (words, gestures, commands, questions, stats, audio)
queue in order and are served first, dropped and counted only past MAX_BACKLOG. `replay_recording` feeds a
recording's samples to the same sink.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from common.codec import decode
from common.keys import Keys
from common.schema import Bodies, DepthFrame, Detections, Faces, Frame, Hands, InvalidSample, Persons, Sample, Stats

Sink = Callable[[str, Sample, int], None]
STATS_EVERY_S = 2.0
MAX_BACKLOG = 1000  # events waiting for the sink; past it new ones are dropped (a viewer must not grow memory)
STREAMS = (Frame, DepthFrame, Detections, Hands, Bodies, Faces, Persons)  # the latest per key is enough
Item = tuple[str, Sample, int]


@dataclass
class FeedCounts:
    received: int = 0
    shown: int = 0
    invalid: dict[str, int] = field(default_factory=dict)  # key -> invalid samples
    dropped: int = 0  # events dropped: the sink was too slow
    skipped: int = 0  # stream samples replaced by a newer one before the sink took them
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
        self.inbox = Inbox()
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
        self._put((key, sample, receive_ns))

    def _put(self, item: Item) -> None:
        outcome = self.inbox.put(item)
        if outcome == "skipped":
            self.counts.skipped += 1
        elif outcome == "dropped":
            self.counts.dropped += 1
            self.bad.warning("the viewer is behind: dropped a sample on %s", item[0])

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
        self._put((key, stats, time.time_ns()))

    def close(self) -> None:
        self.stop.set()
        try:
            self.subscriber.undeclare()
        except Exception:
            pass
        self.inbox.close()
        self.worker.join(timeout=5.0)


class Inbox:
    """Events in order (served first, bounded), streams latest-per-key; `get` blocks, None once closed."""

    def __init__(self) -> None:
        self.events: collections.deque[Item] = collections.deque()
        self.streams: dict[str, Item] = {}  # insertion order = the order keys became pending (kept when replaced)
        self.ready = threading.Condition()
        self.closed = False

    def put(self, item: Item) -> str:
        """'queued', 'skipped' (a pending sample of the same stream was replaced) or 'dropped' (events full)."""
        with self.ready:
            outcome = "queued"
            if isinstance(item[1], STREAMS):
                # replaced in place: the key keeps its turn (popping and re-adding sent the busiest stream, the
                # camera's frames, to the back every time, so a slow viewer could serve it never)
                outcome = "skipped" if item[0] in self.streams else "queued"
                self.streams[item[0]] = item
            elif len(self.events) >= MAX_BACKLOG:
                return "dropped"
            else:
                self.events.append(item)
            self.ready.notify()
            return outcome

    def get(self) -> Item | None:
        with self.ready:
            while not (self.events or self.streams or self.closed):
                self.ready.wait()
            if self.events:
                return self.events.popleft()
            if self.streams:
                return self.streams.pop(next(iter(self.streams)))
            return None

    def close(self) -> None:
        with self.ready:
            self.closed = True
            self.ready.notify_all()


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
