"""Time-windowed join on source stamps. Pure: the caller passes wall time in where it is needed.

- `StreamBuffer`: one per key, ordered by stamp, duplicates (same stamp) dropped, bounded by a
  time horizon behind its own watermark and by a hard item cap, so memory stays flat. What is late and
  when a stream that went back in time is followed again are the common stamp rules (`common/stamps.py`,
  with the horizon as the reordering tolerance); future stamps never get here (the runner rejects them).
- `SeenOnce`: duplicates of what is not buffered (a transcript delivered twice).
- `Liveness`: which modalities count as live (liveliness token present, or a sample arrived within
  `recent_s` of wall time); `Streams.watermark` is the latest stamp seen per modality.
- `ready()`, the policy: a window can be decided (`Ready`, by watermarks or by the deadline, saying which
  live modalities were behind) once every live modality's watermark has passed the window end, or once
  the wall-clock deadline has expired; else `Wait`.
- `Join`: the pending windows in decision order over the buffers; the buffers prune everything older
  than `obsolete_before()` (no pending window reaches back that far) and than their horizon.
"""

from __future__ import annotations

import bisect
import collections
from dataclasses import dataclass, field
from typing import Any, Generic, Iterable, Literal, Protocol, TypeVar

from common.stack import node, publishers_of
from common.stamps import DEFAULT_RESET_RUN, OUT_OF_ORDER, RESET, StampGuard


def waited_modalities(fusion: str = "fusion") -> tuple[str, ...]:
    """The modalities whose watermark a window waits for: the services that publish the fusion node's joined
    inputs (common/stack.py: objects -> vision; hands and event -> gesture)."""
    return tuple(dict.fromkeys(p for i in node(fusion).inputs if i.joined for p in publishers_of(i.topic)))


WAITED_MODALITIES = waited_modalities()

# What became of a sample offered to a buffer (`StreamBuffer.add`)
Buffered = Literal["added", "duplicate", "late", "reset"]


@dataclass
class StreamBuffer:
    horizon: float
    max_items: int = 4096
    reset_run: int = DEFAULT_RESET_RUN  # consistent samples behind the horizon that start a new timeline
    stamps: list[float] = field(default_factory=list)
    items: list[Any] = field(default_factory=list)
    idents: list[Any] = field(default_factory=list)
    watermark: float = 0.0
    guard: StampGuard = field(init=False)

    def __post_init__(self) -> None:
        self.guard = StampGuard(reset_run=self.reset_run, tolerance=self.horizon)

    def add(self, stamp: float, item: Any, ident: Any = None, keep_from: float | None = None) -> Buffered:
        """Insert in stamp order. Returns "added", "duplicate", "late" (older than the horizon) or "reset"
        (the last of `reset_run` consistent late samples: the stream restarted on a new timeline; the buffer
        starts again from it).

        A duplicate has the same stamp and the same `ident` (default: any item at that stamp).
        `keep_from`: keep samples from this stamp on even beyond the horizon (a transcript still needs them);
        the item cap still applies."""
        status: Buffered = "added"
        verdict = self.guard.check("", stamp, None)
        if verdict == OUT_OF_ORDER:
            return "late"
        if verdict == RESET:
            self.stamps.clear()
            self.items.clear()
            self.idents.clear()
            self.watermark = stamp
            status = "reset"
        i = bisect.bisect_left(self.stamps, stamp)
        j = bisect.bisect_right(self.stamps, stamp)
        if any(ident is None or self.idents[k] == ident for k in range(i, j)):
            return "duplicate"
        self.stamps.insert(j, stamp)
        self.items.insert(j, item)
        self.idents.insert(j, ident)
        self.watermark = max(self.watermark, stamp)
        self._prune(keep_from)
        return status

    def _prune(self, keep_from: float | None = None) -> None:
        oldest = self.watermark - self.horizon
        if keep_from is not None:
            oldest = min(oldest, keep_from)
        cut = bisect.bisect_left(self.stamps, oldest)
        cut = max(cut, len(self.stamps) - self.max_items)
        if cut > 0:
            del self.stamps[:cut]
            del self.items[:cut]
            del self.idents[:cut]

    def between(self, lo: float, hi: float) -> list[Any]:
        return self.items[bisect.bisect_left(self.stamps, lo) : bisect.bisect_right(self.stamps, hi)]

    def __len__(self) -> int:
        return len(self.stamps)


class Streams:
    """Buffers per (modality, key)."""

    def __init__(self, horizon: float, max_items: int = 4096):
        self.horizon = horizon
        self.max_items = max_items
        self.buffers: dict[str, dict[str, StreamBuffer]] = {}

    def add(
        self, modality: str, key: str, stamp: float, item: Any, ident: Any = None, keep_from: float | None = None
    ) -> Buffered:
        per_key = self.buffers.setdefault(modality, {})
        buf = per_key.get(key)
        if buf is None:
            buf = per_key[key] = StreamBuffer(self.horizon, self.max_items)
        return buf.add(stamp, item, ident, keep_from)

    def between(self, modality: str, lo: float, hi: float) -> list[tuple[str, Any]]:
        """(key, item) in the window from every key of the modality, keys in name order."""
        out: list[tuple[str, Any]] = []
        for key in sorted(self.buffers.get(modality, {})):
            out.extend((key, item) for item in self.buffers[modality][key].between(lo, hi))
        return out

    def watermark(self, modality: str) -> float:
        return max((b.watermark for b in self.buffers.get(modality, {}).values()), default=0.0)

    def size(self) -> int:
        return sum(len(b) for per_key in self.buffers.values() for b in per_key.values())


class SeenOnce:
    """Samples that are not buffered (transcripts open windows instead) are deduplicated by their ident: the
    idents seen within `horizon` of source time, at most `cap` of them."""

    def __init__(self, horizon: float, cap: int = 1024):
        self.horizon = horizon
        self.cap = cap
        self.seen: collections.OrderedDict[Any, float] = collections.OrderedDict()

    def first(self, ident: Any, stamp: float) -> bool:
        """True the first time `ident` comes; False for a duplicate."""
        if ident in self.seen:
            return False
        self.seen[ident] = stamp
        while self.seen and (len(self.seen) > self.cap or next(iter(self.seen.values())) < stamp - self.horizon):
            self.seen.popitem(last=False)
        return True

    def __len__(self) -> int:
        return len(self.seen)


class Liveness:
    """Which modalities to wait for: a liveliness token is present, or samples arrived recently."""

    def __init__(self, recent_s: float = 2.0):
        self.recent_s = recent_s
        self.tokens: dict[str, set[str]] = {}
        self.last_arrival: dict[str, float] = {}

    def token(self, modality: str, instance: str, present: bool) -> None:
        inst = self.tokens.setdefault(modality, set())
        (inst.add if present else inst.discard)(instance)

    def arrived(self, modality: str, wall: float) -> None:
        self.last_arrival[modality] = max(self.last_arrival.get(modality, 0.0), wall)

    def live(self, modality: str, wall: float) -> bool:
        return bool(self.tokens.get(modality)) or wall - self.last_arrival.get(modality, -1e18) <= self.recent_s


@dataclass(frozen=True)
class Ready:
    """Decide the window now: every live modality's watermark passed its end (`by="watermarks"`), or the
    deadline expired while the live modalities in `behind` had not got there yet."""

    by: Literal["watermarks", "deadline"]
    behind: tuple[str, ...] = ()

    def __str__(self) -> str:  # how explanations say it
        return self.by if self.by == "watermarks" else "deadline (waited for " + ", ".join(self.behind) + ")"


@dataclass(frozen=True)
class Wait:
    """Not yet: the live modalities in `behind` have not reached the window end and the deadline is ahead."""

    behind: tuple[str, ...]


def ready(
    window_end: float,
    arrived_wall: float,
    now_wall: float,
    max_wait: float,
    watermarks: dict[str, float],
    live: Iterable[str],
) -> Ready | Wait:
    """Watermarks pass the window end for every live modality, or the deadline hit."""
    behind = tuple(sorted(m for m in live if watermarks.get(m, 0.0) < window_end))
    if not behind:
        return Ready("watermarks")
    if now_wall - arrived_wall >= max_wait:
        return Ready("deadline", behind)
    return Wait(behind)


class Window(Protocol):
    lo: float  # source time the window starts at
    hi: float  # source time it ends at
    arrived: float  # wall time its opener arrived (the deadline counts from it)

    @property
    def order(self) -> Any: ...  # windows are decided in this order


W = TypeVar("W", bound=Window)


class Join(Generic[W]):
    """Windows waiting for their inputs, over the buffers they read. Pure: wall time is passed in."""

    def __init__(self, horizon: float, lookback: float, max_wait: float, live_recent_s: float):
        self.streams = Streams(horizon)
        self.liveness = Liveness(live_recent_s)
        self.lookback = lookback  # a window also reads this much before its start (vision describes the scene)
        self.max_wait = max_wait
        self.windows: list[W] = []

    def obsolete_before(self) -> float | None:
        """Buffered samples older than this are needed by no pending window (None: no window is pending; the
        buffers' horizon alone decides)."""
        start = min((w.lo for w in self.windows), default=None)
        return None if start is None else start - self.lookback

    def add(self, modality: str, key: str, stamp: float, item: Any, wall: float, ident: Any = None) -> Buffered:
        """Buffer a sample ("added", "duplicate", "late" or "reset": `StreamBuffer.add`)."""
        self.liveness.arrived(modality, wall)
        return self.streams.add(modality, key, stamp, item, ident, self.obsolete_before())

    def open(self, window: W) -> None:
        self.windows.append(window)
        self.windows.sort(key=lambda w: w.order)

    def due(self, wall: float) -> list[tuple[W, Ready]]:
        """The windows to decide now, in order, each with why; a window that must wait holds back the later
        ones (decisions keep the order of `Window.order`)."""
        live = [m for m in WAITED_MODALITIES if self.liveness.live(m, wall)]
        marks = {m: self.streams.watermark(m) for m in WAITED_MODALITIES}
        out: list[tuple[W, Ready]] = []
        while self.windows:
            head = self.windows[0]
            verdict = ready(head.hi, head.arrived, wall, self.max_wait, marks, live)
            if isinstance(verdict, Wait):
                break
            out.append((self.windows.pop(0), verdict))
        return out

    def __len__(self) -> int:
        return len(self.windows)


class ClockOffsets:
    """A running estimate of each source's clock offset against this machine's clock. Pure: times passed in.

    Per sample: `stamp` (source clock, when the thing was observed), `ref` (the router's Zenoh HLC timestamp
    added when the sample reached it, or None), `wall` (this machine's clock on arrival). Every delay (the
    source's processing, the network) makes `stamp - ref` and `ref - wall` *smaller* than the true clock
    differences, never larger, so the estimate is the classic minimum-delay filter: the maximum over a sliding
    window of `window` samples of `stamp - ref` (source vs router), plus the maximum over the last samples of
    all sources of `ref - wall` (router vs this machine). One slow sample cannot move it; a clock that steps
    shows within `window` samples. Without router timestamps `ref` is `wall` and the second term is 0.

    What it cannot separate: a source's fastest pipeline delay (the inference time of a detection) reads as its
    clock being that much *behind*. A source whose samples are late by design (`late_by_design`: a transcript is
    stamped at the utterance end and published after recognition, 0.2-2 s later) is not given a clock offset from
    that delay: `offsets()` holds it only when its stamps run *ahead* (no delay can do that), and `delays()` holds
    its fastest stamp-to-arrival time otherwise (its processing delay, plus any clock lag too small to tell).
    """

    def __init__(self, window: int = 64, idle_s: float = 60.0):
        self.window = window
        self.idle_s = idle_s  # a source silent this long (wall) is dropped: `hri say` is a new source every time
        self._source: dict[str, collections.deque[float]] = {}
        self._last: dict[str, float] = {}
        self._router: collections.deque[float] = collections.deque(maxlen=window)
        self._late: set[str] = set()

    def add(self, source: str, stamp: float, ref: float | None, wall: float, late_by_design: bool = False) -> None:
        ref = wall if ref is None else ref
        if late_by_design:
            self._late.add(source)
        self._source.setdefault(source, collections.deque(maxlen=self.window)).append(stamp - ref)
        self._last[source] = wall
        self._router.append(ref - wall)

    def expire(self, wall: float) -> list[str]:
        """Forget the sources silent for `idle_s`; returns them (so their reported offsets go too)."""
        gone = [s for s, last in self._last.items() if wall - last > self.idle_s]
        for source in gone:
            self.forget(source)
        return gone

    def router_offset(self) -> float:
        """The router's clock minus this machine's (0 while nothing arrived)."""
        return max(self._router, default=0.0)

    def _estimates(self) -> dict[str, float]:
        """Per source: max(stamp - ref) + the router's offset (a clock offset less the fastest delay)."""
        router = self.router_offset()
        return {s: max(d) + router for s, d in self._source.items() if d}

    def offset(self, source: str) -> float | None:
        """Source clock minus this machine's clock, in seconds (None: nothing from it yet, or a source late by
        design whose stamps do not run ahead: see `delay`)."""
        return self.offsets().get(source)

    def offsets(self) -> dict[str, float]:
        return {s: v for s, v in self._estimates().items() if s not in self._late or v > 0}

    def delay(self, source: str) -> float | None:
        """Seconds from stamp to arrival at the fastest, for a source late by design (None otherwise)."""
        return self.delays().get(source)

    def delays(self) -> dict[str, float]:
        return {s: -v for s, v in self._estimates().items() if s in self._late and v <= 0}

    def forget(self, source: str) -> None:
        """A source that left (its liveliness token went away): a new instance starts a new estimate."""
        self._source.pop(source, None)
        self._last.pop(source, None)
        self._late.discard(source)


def clock_verdict(offset: float, ahead_tolerance: float, behind_tolerance: float) -> str | None:
    """ "ahead" / "behind" when an offset uses more than the join window allows, else None."""
    if offset > ahead_tolerance:
        return "ahead"
    if offset < -behind_tolerance:
        return "behind"
    return None
