"""Image boxes `[x, y, w, h]` in pixels: the one intersection-over-union that vision's tracker, the face tracker and
the person tracker share, and their greedy matching."""

from __future__ import annotations

from typing import Iterable, Sequence


def iou(a: Sequence[float], b: Sequence[float]) -> float:
    """Intersection over union of two `[x, y, w, h]` boxes; 0 when they do not overlap (or both are empty)."""
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    iw = max(0.0, min(ax + aw, bx + bw) - max(ax, bx))
    ih = max(0.0, min(ay + ah, by + bh) - max(ay, by))
    inter = iw * ih
    union = aw * ah + bw * bh - inter
    return inter / union if union > 0 else 0.0


def match_in_order(pairs: Iterable[tuple[float, int, int]]) -> dict[int, int]:
    """Greedy one-to-one matching: `(score, a, b)` pairs in the order to take them (best first, as the caller
    sorts them, ties its own way) -> {b: a}, each `a` and each `b` taken at most once. The tracks <- detections step
    of every tracker here (vision's, the face tracker, the person tracker) and vision's colour memory."""
    taken: set[int] = set()
    matched: dict[int, int] = {}
    for _, a, b in pairs:
        if a not in taken and b not in matched:
            taken.add(a)
            matched[b] = a
    return matched
