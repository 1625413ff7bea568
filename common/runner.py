"""The process shell every service runs in.

It opens the session (waiting for the router), declares the liveliness token and
the stats queryable, validates every incoming sample in the Zenoh callback,
hands valid ones to a single worker thread through a bounded inbox with an
explicit policy per stream, and on SIGINT/SIGTERM undeclares everything, closes
the session and exits 0.

Policies:
- `latest`: one slot per key; a newer sample replaces an unprocessed one (counted
  as skipped). For camera frames: lag never grows.
- `fifo`: lossless up to `maxlen` queued samples (transcripts, events, commands);
  beyond that the oldest is dropped and counted, never silently.
"""

from __future__ import annotations

import argparse
import collections
import logging
import os
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, cast

import zenoh

import common.stack as stack
from common.codec import ENCODING, decode, encode
from common.counters import CounterName
from common.cpu import change_priority, limit_opencv_threads
from common.image import DEFAULT_MAX_PIXELS, check_frame_header
from common.keys import Keys, check_chunk
from common.schema import Frame, InvalidSample, Sample, Stats
from common.settings import add_option
from common.stamps import DEFAULT_MAX_SKEW_S, DEFAULT_RESET_RUN, FUTURE, OUT_OF_ORDER, RESET, StampGuard
from common.transport import add_zenoh_arguments, declare_recovering_publisher, open_session, resolve

LOG_FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"
SHUTDOWN_GRACE_S = 1.8  # the contract promises exit within 2 s of SIGTERM


def setup_logging(name: str, level: str | None = None) -> logging.Logger:
    level = (level or os.environ.get("HRI_LOG_LEVEL") or "INFO").upper()
    logging.basicConfig(level=level, format=LOG_FORMAT, stream=sys.stderr)
    return logging.getLogger(name)


def service_parser(name: str | stack.Node, description: str, epilog: str = "") -> argparse.ArgumentParser:
    """The flags every service takes; --max-pixels only for a node that reads images (common/stack.py)."""
    node = name if isinstance(name, stack.Node) else stack.node(name)
    name = node.name
    parser = argparse.ArgumentParser(
        prog=f"hri-{name}", description=description, epilog=epilog, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--instance",
        default=os.environ.get("HRI_INSTANCE"),
        help="this instance's id in liveliness/stats keys and `source` (default host-pid)",
    )
    parser.add_argument("--log-level", default=None, help="DEBUG, INFO, WARNING … (env HRI_LOG_LEVEL)")
    g = parser.add_argument_group("input checks (docs/foundation.md)")
    add_option(
        g,
        "--max-skew",
        DEFAULT_MAX_SKEW_S,
        "reject samples stamped more than S seconds ahead of this machine's clock",
        at_least=0,
        metavar="S",
    )
    add_option(
        g,
        "--timeline-run",
        DEFAULT_RESET_RUN,
        "follow a stream that went back in time after N consistent samples",
        at_least=1,
        metavar="N",
    )
    add_option(
        parser,
        "--nice",
        node.nice,
        "change this process's CPU priority by N (os.nice): > 0 yields (the frame services, which skip frames), "
        "< 0 asks for more (speech, where the system allows it: root or CAP_SYS_NICE; else it runs at 0)",
        at_least=-20,
        at_most=19,
        metavar="N",
    )
    add_option(
        parser,
        "--cv-threads",
        1,
        "OpenCV's thread pool (decoding, resizing): 1, as the services run side by side on the machine's cores; "
        "0 leaves OpenCV's own choice (every core)",
        at_least=0,
        metavar="N",
    )
    if node.reads_images:
        add_option(
            g,
            "--max-pixels",
            DEFAULT_MAX_PIXELS,
            "reject frames larger than N pixels before decoding them",
            at_least=1,
            metavar="N",
            default_text=f"{DEFAULT_MAX_PIXELS}: 4096x2160",
        )
    add_zenoh_arguments(parser)
    return parser


class RateLimitedLog:
    """One log line per reason per interval: the first at once, then a summary with the count.

    A flood of bad samples costs one line per reason every `interval` seconds, not one per sample."""

    def __init__(self, log: logging.Logger, interval: float = 10.0, clock: Callable[[], float] = time.monotonic):
        self._log = log
        self._interval = interval
        self._clock = clock
        self._lock = threading.Lock()
        self._last: dict[str, float] = {}
        self._pending: dict[str, tuple[int, str]] = {}  # reason -> (suppressed count, latest message)

    def warn(self, reason: str, message: str, level: int = logging.WARNING, exc_info: bool = False) -> None:
        now = self._clock()
        with self._lock:
            last = self._last.get(reason)
            if last is not None and now - last < self._interval:
                n, _ = self._pending.get(reason, (0, ""))
                self._pending[reason] = (n + 1, message)
                return
            self._last[reason] = now
            n, _ = self._pending.pop(reason, (0, ""))
        self._log.log(
            level,
            "%s%s",
            message,
            f" (and {n} more like it in the last {self._interval:g} s)" if n else "",
            exc_info=exc_info,
        )

    def flush(self) -> None:
        """Write the summaries whose interval is over (called periodically, so a flood that stops is reported)."""
        now = self._clock()
        with self._lock:
            due = [(r, n, m) for r, (n, m) in self._pending.items() if now - self._last[r] >= self._interval]
            for r, _, _ in due:
                del self._pending[r]
                self._last[r] = now
        for reason, n, message in due:
            self._log.warning("%d more %s in the last %g s, the latest: %s", n, reason, self._interval, message)


class Counters:
    """Thread-safe counters, exposed through the stats queryable; rejections are logged at a rate limit."""

    def __init__(self, log: logging.Logger, log_interval: float = 10.0):
        self._lock = threading.Lock()
        self._log = log
        self.ratelog = RateLimitedLog(log, log_interval)
        self.received = 0
        self.published = 0
        self.skipped = 0
        self.rejected: collections.Counter[str] = collections.Counter()
        self.other: collections.Counter[str] = collections.Counter()

    def add(self, name: CounterName, n: int = 1) -> None:
        with self._lock:
            if name in ("received", "published", "skipped"):
                setattr(self, name, getattr(self, name) + n)
            else:
                self.other[name] += n

    def set(self, name: str, value: int | None) -> None:
        """A gauge among the counters of `other` (e.g. a clock offset in ms); None removes it."""
        with self._lock:
            if value is None:
                self.other.pop(name, None)
            else:
                self.other[name] = value

    def reject(self, reason: str, detail: str, key: str = "") -> None:
        with self._lock:
            self.rejected[reason] += 1
            n = self.rejected[reason]
        self.ratelog.warn(reason, f"dropped invalid sample{f' on {key}' if key else ''} ({reason}, #{n}): {detail}")

    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            return {
                "received": self.received,
                "published": self.published,
                "skipped": self.skipped,
                "rejected": dict(self.rejected),
                "other": dict(self.other),
            }


@dataclass(slots=True)
class Delivery:
    key: str
    sample: Any
    received_at: float  # wall time the callback ran (for lag measurement, never for joins)
    timeline_reset: bool = False  # the first sample of a stream's new timeline: per-stream state may restart
    zenoh_time: float | None = None  # the Zenoh (HLC) timestamp the router or publisher added, UNIX seconds


class Inbox:
    """Bounded mailbox between Zenoh callback threads and the one worker thread."""

    def __init__(self, counters: Counters):
        self._cond = threading.Condition()
        self._fifo: collections.deque[tuple[Callable, Delivery, int]] = collections.deque()
        self._fifo_len: collections.Counter[int] = collections.Counter()
        self._latest: dict[str, tuple[Callable, Delivery]] = {}
        self._counters = counters
        self._closed = False

    def put_fifo(self, handler: Callable, delivery: Delivery, channel: int, maxlen: int) -> None:
        with self._cond:
            if self._fifo_len[channel] >= maxlen:
                # drop the oldest of this channel: count it, keep the stream moving
                for i, (_, _, ch) in enumerate(self._fifo):
                    if ch == channel:
                        del self._fifo[i]
                        self._fifo_len[channel] -= 1
                        self._counters.add("dropped_overflow")
                        break
            self._fifo.append((handler, delivery, channel))
            self._fifo_len[channel] += 1
            self._cond.notify()

    def put_latest(self, handler: Callable, delivery: Delivery) -> None:
        with self._cond:
            if delivery.key in self._latest:
                self._counters.add("skipped")
            self._latest[delivery.key] = (handler, delivery)
            self._cond.notify()

    def get(self, timeout: float | None) -> tuple[Callable, Delivery] | None:
        """Next item: lossless streams first (they are small and urgent), then the oldest latest-slot."""
        with self._cond:
            if not self._fifo and not self._latest and not self._closed:
                self._cond.wait(timeout)
            if self._fifo:
                handler, delivery, channel = self._fifo.popleft()
                self._fifo_len[channel] -= 1
                return handler, delivery
            if self._latest:
                key = next(iter(self._latest))  # insertion order: round-robin across cameras
                return self._latest.pop(key)
            return None

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        return self._closed


class UndeclaredTopic(ValueError):
    """A service subscribed to (or published on) a topic its node does not declare in common/stack.py."""


class Service:
    """A running hri service: session, liveliness, stats, validated inputs, one worker thread."""

    def __init__(
        self,
        name: str | stack.Node,
        args: argparse.Namespace,
        log: logging.Logger | None = None,
        recovering: bool = False,
    ):
        """`name`: the node of the stack this service runs (common/stack.py), or its name. `recovering`: this
        service publishes with `publish(..., recovering=True)` (its session then stamps its samples itself,
        which Zenoh's AdvancedPublisher needs)."""
        self.node = name if isinstance(name, stack.Node) else stack.node(name)
        name = self.node.name
        resolve(args)
        limit_opencv_threads(getattr(args, "cv_threads", 0))
        self.recovering = recovering
        args.user = args.user or name  # on a secured robot each service logs in as itself (common/security.py)
        self.name = check_chunk(name, "service name")
        self.instance = check_chunk(args.instance or f"{socket.gethostname()}-{os.getpid()}", "instance")
        self.source = f"{self.name}/{self.instance}"
        self.args = args
        self.keys = Keys(args.prefix)
        self.log = log or setup_logging(f"hri.{name}", getattr(args, "log_level", None))
        refused = change_priority(getattr(args, "nice", 0))
        if refused:
            self.log.info("%s", refused)
        self.counters = Counters(self.log)
        self.stop_event = threading.Event()
        self.session: zenoh.Session | None = None
        self._inbox = Inbox(self.counters)
        self._subscribers: list[Any] = []
        self._declared: list[Any] = []
        self._publishers: dict[tuple[str, bool, bool, bool], "SamplePublisher"] = {}
        self._on_close: list[Callable[[], None]] = []
        self._started = time.monotonic()
        self._channels = 0

    # -- set-up ------------------------------------------------------------
    def connect(self) -> bool:
        """Open the session and answer stats. False if asked to stop while waiting for the router. The liveliness
        token comes in `run()`, after the service's subscriptions: "alive" means listening."""
        self._install_signal_handlers()
        self.session = open_session(self.args, self.log, self.stop_event, timestamping=self.recovering)
        if self.session is None:
            return False
        self._declared.append(
            self.session.declare_queryable(self.keys.stats(self.name, self.instance), self._answer_stats)
        )
        return True

    def _install_signal_handlers(self) -> None:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, lambda *_: self.stop_event.set())

    def subscribe_input(self, topic: str, handler: Callable[[Delivery], None], **chunks: str) -> None:
        """Receive `topic`, one of this node's declared inputs (common/stack.py), on the key its chunks give
        (e.g. cam="front"; a chunk not given is '*'): validated as the topic's schema, queued with the input's
        policy, maxlen and stamp order, and handed to `handler` on the worker thread. A topic the node does not
        declare raises UndeclaredTopic (at start-up: the declaration is the one description of the stack)."""
        if topic not in self.node.input_names():
            raise UndeclaredTopic(
                f"{self.name} subscribes to {topic!r}, which its Node in common/stack.py does not declare as an "
                f"input (it declares {', '.join(self.node.input_names()) or 'none'}): add Input({topic!r}, ...) there"
            )
        declared = self.node.input(topic)
        t = stack.topic(topic)
        self._subscribe(
            self.keys.key(topic, **chunks),
            t.schema,
            handler,
            latest=declared.policy == "latest",
            maxlen=declared.maxlen,
            monotonic=declared.monotonic,
            image=t.image,
        )

    def output_key(self, topic: str, **chunks: str) -> str:
        """The key of `topic`, one of this node's declared outputs (common/stack.py), with these chunks."""
        if topic not in self.node.outputs:
            raise UndeclaredTopic(
                f"{self.name} publishes on {topic!r}, which its Node in common/stack.py does not declare as an "
                f"output (it declares {', '.join(self.node.outputs) or 'none'}): add it to outputs there"
            )
        return self.keys.key(topic, **chunks)

    def publish_output(
        self,
        topic: str,
        sample: Sample,
        *,
        lossless: bool = True,
        realtime: bool = False,
        recovering: bool = False,
        **chunks: str,
    ) -> None:
        """`publish` on the key of `topic`, one of this node's declared outputs (see `output_key`)."""
        self.publish(
            self.output_key(topic, **chunks), sample, lossless=lossless, realtime=realtime, recovering=recovering
        )

    def _subscribe(
        self,
        keyexpr: str,
        schema: type[Sample],
        handler: Callable[[Delivery], None],
        *,
        latest: bool = False,
        maxlen: int = 1000,
        monotonic: bool = False,
        image: bool = False,
    ) -> None:
        """Validate samples on `keyexpr` as `schema` and hand valid ones to `handler` on the worker thread.

        Every sample stamped more than --max-skew ahead of this machine's clock is rejected as future_stamp.
        `monotonic`: per key, a sample older than the newest accepted is rejected as out_of_order, until
        --timeline-run consistent older samples show the stream restarted on a new timeline (counted as
        timeline_reset; common/stamps.py). `image`: the sample's encoded header is checked against its
        width/height and --max-pixels first (common/image.py).
        """
        assert self.session is not None, "connect() first"
        channel = self._channels
        self._channels += 1
        guard = StampGuard(
            max_skew=getattr(self.args, "max_skew", DEFAULT_MAX_SKEW_S),
            reset_run=getattr(self.args, "timeline_run", DEFAULT_RESET_RUN),
        )
        guard_lock = threading.Lock()  # zenoh may call back from several threads
        max_pixels = getattr(self.args, "max_pixels", DEFAULT_MAX_PIXELS)

        def on_sample(zsample: zenoh.Sample) -> None:
            key = str(zsample.key_expr)
            self.counters.add("received")
            try:
                sample = decode(zsample.payload.to_bytes(), schema)
                if image:  # an image topic's schema is Frame (common/stack.py check_stack)
                    check_frame_header(cast(Frame, sample), max_pixels)
            except InvalidSample as exc:
                self.counters.reject(exc.reason, exc.detail, key)
                return
            now = time.time()
            if monotonic:
                with guard_lock:
                    verdict = guard.check(key, sample.stamp, now)
                    high = guard.high(key)
            else:
                verdict = FUTURE if guard.is_future(sample.stamp, now) else "accepted"
            if verdict == FUTURE:
                self.counters.reject(
                    FUTURE,
                    f"stamp {sample.stamp:.6f} is {sample.stamp - now:.3g} s ahead of "
                    f"this machine's clock (more than --max-skew {guard.max_skew:g} s): is the "
                    f"sender's clock synchronised (NTP)?",
                    key,
                )
                return
            if verdict == OUT_OF_ORDER:
                self.counters.reject(
                    OUT_OF_ORDER,
                    f"stamp {sample.stamp:.6f} is older than {high:.6f} already "
                    f"seen ({guard.reset_run} consistent older samples start a new timeline)",
                    key,
                )
                return
            if verdict == RESET:
                self.counters.add(RESET)
                self.counters.ratelog.warn(
                    RESET,
                    f"{key} went back in time: following its new timeline from "
                    f"stamp {sample.stamp:.6f} (a clock step or a restarted replay?)",
                )
            ts = zsample.timestamp
            delivery = Delivery(
                key,
                sample,
                time.time(),
                verdict == RESET,
                ts.get_time_as_ntp64().as_secs_f64() if ts is not None else None,
            )
            if latest:
                self._inbox.put_latest(handler, delivery)
            else:
                self._inbox.put_fifo(handler, delivery, channel, maxlen)

        self._subscribers.append(self.session.declare_subscriber(keyexpr, on_sample))

    def publish(
        self, key: str, sample: Sample, *, lossless: bool = True, realtime: bool = False, recovering: bool = False
    ) -> None:
        """`recovering`: what must not be lost across a dropped link (commands): kept in a cache that recovering
        subscribers fetch what they missed from (common/transport.py declare_recovering_publisher)."""
        slot = (key, lossless, realtime, recovering)
        pub = self._publishers.get(slot)
        if pub is None:  # one declared publisher per key and QoS (a stop and a pick_up share a key, not a QoS)
            assert self.session is not None, "connect() first"
            assert self.recovering or not recovering, "Service(..., recovering=True) for recovering publishers"
            pub = self._publishers[slot] = SamplePublisher(
                self.session, key, lossless=lossless, realtime=realtime, recovering=recovering
            )
        pub.put(sample)
        self.counters.add("published")

    def on_close(self, fn: Callable[[], None]) -> None:
        self._on_close.append(fn)

    def stats(self) -> Stats:
        snap = self.counters.snapshot()
        return Stats(
            stamp=time.time(),
            source=self.source,
            service=self.name,
            instance=self.instance,
            uptime=time.monotonic() - self._started,
            **snap,
        )

    def _answer_stats(self, query: zenoh.Query) -> None:
        try:
            query.reply(self.keys.stats(self.name, self.instance), encode(self.stats()), encoding=ENCODING)
        except Exception as exc:  # a stats reply must never take the service down
            self.log.warning("could not answer a stats query: %s", exc)

    # -- running -----------------------------------------------------------
    def run(
        self,
        loop: Callable[[threading.Event], None] | None = None,
        tick: Callable[[], None] | None = None,
        tick_interval: float = 0.05,
    ) -> int:
        """Run until SIGINT/SIGTERM (or until `loop` returns). Returns the process exit code."""
        if self.session is None and not self.connect():
            return 0
        assert self.session is not None
        self._declared.append(self.session.liveliness().declare_token(self.keys.alive(self.name, self.instance)))
        worker = threading.Thread(
            target=self._work, args=(loop, tick, tick_interval), name=f"{self.name}-worker", daemon=True
        )
        worker.start()
        self.log.info("%s %s running (prefix %s)", self.name, self.instance, self.keys.prefix)
        while not self.stop_event.wait(0.2):
            self.counters.ratelog.flush()
            if not worker.is_alive():
                break
        return self.shutdown(worker)

    def _work(self, loop: Callable | None, tick: Callable | None, tick_interval: float) -> None:
        try:
            if loop is not None:
                loop(self.stop_event)
                return
            while not self.stop_event.is_set():
                item = self._inbox.get(tick_interval if tick else 0.5)
                if item is not None:
                    handler, delivery = item
                    try:
                        handler(delivery)
                    except Exception:
                        self.counters.add("handler_error")
                        self.counters.ratelog.warn(
                            "handler_error",
                            f"error while handling a sample on {delivery.key}; it is dropped, the service goes on",
                            logging.ERROR,
                            exc_info=True,
                        )
                if tick is not None:
                    tick()
        except Exception:
            self.log.exception("worker failed")
            self._exit_code = 1

    _exit_code = 0

    def fail(self, code: int, message: str) -> None:
        """Log a fatal error and stop the service with exit code `code`."""
        self.log.error("%s", message)
        self._exit_code = code
        self.stop_event.set()

    def shutdown(self, worker: threading.Thread | None = None) -> int:
        self.stop_event.set()
        watchdog = threading.Thread(target=self._force_exit, daemon=True)
        watchdog.start()
        for sub in self._subscribers:
            _quietly(sub.undeclare)
        self._inbox.close()
        if worker is not None and worker is not threading.current_thread():
            worker.join(1.0)
        for fn in self._on_close:
            _quietly(fn)
        for pub in self._publishers.values():
            _quietly(pub.undeclare)
        for obj in reversed(self._declared):
            _quietly(obj.undeclare)
        if self.session is not None:
            _quietly(self.session.close)
        self.log.info("%s %s stopped: %s", self.name, self.instance, self.counters.snapshot())
        return self._exit_code

    def _force_exit(self) -> None:
        time.sleep(SHUTDOWN_GRACE_S)
        self.log.error("shutdown took longer than %.1f s; forcing exit", SHUTDOWN_GRACE_S)
        logging.shutdown()
        os._exit(self._exit_code)


class SamplePublisher:
    """A declared publisher that encodes (and so validates) every sample it sends."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        *,
        lossless: bool = True,
        realtime: bool = False,
        recovering: bool = False,
    ):
        self.key = key
        qos: dict[str, Any] = dict(  # one set of options for both kinds of publisher
            encoding=zenoh.Encoding(ENCODING),
            congestion_control=zenoh.CongestionControl.BLOCK if lossless else zenoh.CongestionControl.DROP,
            priority=zenoh.Priority.REAL_TIME
            if realtime
            else (zenoh.Priority.DATA_HIGH if lossless else zenoh.Priority.DATA),
            express=realtime,
        )
        self._pub = (
            declare_recovering_publisher(session, key, **qos) if recovering else session.declare_publisher(key, **qos)
        )

    def put(self, sample: Sample) -> None:
        self._pub.put(encode(sample))

    def undeclare(self) -> None:
        self._pub.undeclare()


def _quietly(fn: Callable[[], Any]) -> None:
    try:
        fn()
    except Exception:
        pass


def main_exit(code: int) -> None:
    logging.shutdown()
    sys.exit(code)


class StartupError(Exception):
    """A service cannot start as configured (a missing model, an unreadable file): logged, exit code 2."""


class App:
    """The one shape of a service: its pure core and settings (built in `__init__` from the parsed arguments),
    what it needs before the session opens (`open`), what it subscribes (`wire`, with the handlers that call the
    core and publish), and, for a source such as the camera, a `loop` run on the worker thread instead of
    handlers. `serve` drives it; `__main__.py` only parses the arguments and calls `serve`."""

    node: str = ""  # the node of common/stack.py this app runs
    recovering = False  # see Service(recovering=...)

    def open(self, service: Service) -> None:
        """Load what the app needs (models, sources, files) before connecting; StartupError if it cannot."""

    def wire(self, service: Service) -> None:
        """Subscribe the app's inputs (`service.subscribe_input`) once the session is open."""

    loop: Callable[[threading.Event], None] | None = None
    tick: Callable[[], None] | None = None
    tick_interval = 0.05


def serve(app: App, args: argparse.Namespace) -> None:
    """Run `app` as a process: open it, connect, wire its inputs, run until stopped; exits with the code."""
    service = Service(app.node, args, recovering=app.recovering)
    try:
        app.open(service)
    except StartupError as exc:
        service.log.error("%s", exc)
        main_exit(2)
    if not service.connect():
        main_exit(0)
    app.wire(service)
    main_exit(service.run(loop=app.loop, tick=app.tick, tick_interval=app.tick_interval))
