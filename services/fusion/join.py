"""Time-windowed join on source stamps. Pure: the caller passes wall time in where it is needed.

- `StreamBuffer`: one per key, ordered by stamp, duplicates (same stamp) dropped, bounded by a
  time horizon behind its own watermark and by a hard item cap, so memory stays flat. What is late and
  when a stream that went back in time is followed again are the common stamp rules (`common/stamps.py`,
  with the horizon as the reordering tolerance); future stamps never get here (the runner rejects them).
- `Watermarks`: the latest stamp seen per modality, and which modalities count as live
  (liveliness token present, or a sample arrived within `recent_s` of wall time).
- `ready()`: a transcript's window can be decided once every live modality's watermark has
  passed the window end, or once the wall-clock deadline has expired.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Any, Iterable

from common.stamps import DEFAULT_RESET_RUN, OUT_OF_ORDER, RESET, StampGuard

WAITED_MODALITIES = ("vision", "gesture")


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

    def add(self, stamp: float, item: Any, ident: Any = None, keep_from: float | None = None) -> str:
        """Insert in stamp order. Returns "added", "duplicate", "late" (older than the horizon) or "reset"
        (the last of `reset_run` consistent late samples: the stream restarted on a new timeline; the buffer
        starts again from it).

        A duplicate has the same stamp and the same `ident` (default: any item at that stamp).
        `keep_from`: keep samples from this stamp on even beyond the horizon (a transcript still needs them);
        the item cap still applies."""
        status = "added"
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
        return self.items[bisect.bisect_left(self.stamps, lo):bisect.bisect_right(self.stamps, hi)]

    def __len__(self) -> int:
        return len(self.stamps)


class Streams:
    """Buffers per (modality, key)."""

    def __init__(self, horizon: float, max_items: int = 4096):
        self.horizon = horizon
        self.max_items = max_items
        self.buffers: dict[str, dict[str, StreamBuffer]] = {}

    def add(self, modality: str, key: str, stamp: float, item: Any, ident: Any = None,
            keep_from: float | None = None) -> str:
        per_key = self.buffers.setdefault(modality, {})
        buf = per_key.get(key)
        if buf is None:
            buf = per_key[key] = StreamBuffer(self.horizon, self.max_items)
        return buf.add(stamp, item, ident, keep_from)

    def between(self, modality: str, lo: float, hi: float) -> list[tuple[str, Any]]:
        """(key, item) in the window from every key of the modality, keys in name order."""
        out = []
        for key in sorted(self.buffers.get(modality, {})):
            out.extend((key, item) for item in self.buffers[modality][key].between(lo, hi))
        return out

    def watermark(self, modality: str) -> float:
        return max((b.watermark for b in self.buffers.get(modality, {}).values()), default=0.0)

    def size(self) -> int:
        return sum(len(b) for per_key in self.buffers.values() for b in per_key.values())


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


def ready(window_end: float, arrived_wall: float, now_wall: float, max_wait: float,
          watermarks: dict[str, float], live: Iterable[str]) -> tuple[bool, str]:
    """(decide now?, why). Watermarks pass the window end for every live modality, or the deadline hit."""
    behind = [m for m in live if watermarks.get(m, 0.0) < window_end]
    if not behind:
        return True, "watermarks"
    if now_wall - arrived_wall >= max_wait:
        return True, "deadline (waited for " + ", ".join(sorted(behind)) + ")"
    return False, ""
