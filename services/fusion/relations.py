"""Relations between objects as people say them, on boxes in one image. Pure geometry, no fusion types.

Every function takes boxes (x, y, w, h in pixels) and returns a degree of fit in [0, 1]; fusion compares the fits of
the candidates with each other (the best one need not be perfect, it must be clearly better than the rest).

The 2-D rules (a single image has no depth; a depth-based rule can replace `further_back` alone):
- next to / beside / by / near: the gap between the two boxes (0 when they touch or overlap), relative to the
  objects' size (the square root of the mean box area): exp(-gap / size).
- behind / in front of: "further back" is higher up in the image: the bottom edge (where an object stands) is
  higher than the anchor's bottom edge, and the two are side by side (horizontal gap small against their size).
- left of / right of: the centre is left (right) of the anchor's centre, and nearer ones fit better.
- on (support): the object's bottom edge lies within the anchor's box and the object is over it horizontally;
  the object is smaller than what it rests on.
- in / inside: the share of the object's box inside the anchor's box (the object is smaller).
- under / below, above / over: the centre is below (above) the anchor's and they overlap horizontally.
- between A and B: the centre projects inside the segment between the anchors' centres, and lies near it.
"""

from __future__ import annotations

import math

Box = tuple[float, float, float, float]  # x, y, w, h

RELATIONS = ("next_to", "behind", "in_front_of", "left_of", "right_of", "on", "in", "under", "above", "between")
SOFT = 0.1  # fraction of the objects' size over which a "which side" test goes from doubt to certainty


def _size(a: Box, b: Box) -> float:
    return max(1.0, math.sqrt(0.5 * (a[2] * a[3] + b[2] * b[3])))


def _sigmoid(x: float) -> float:
    return 1.0 / (1.0 + math.exp(-max(-50.0, min(50.0, x))))


def box_gap(a: Box, b: Box) -> tuple[float, float]:
    """(horizontal, vertical) gap between two boxes in pixels, 0 where they overlap."""
    gx = max(0.0, max(a[0] - (b[0] + b[2]), b[0] - (a[0] + a[2])))
    gy = max(0.0, max(a[1] - (b[1] + b[3]), b[1] - (a[1] + a[3])))
    return gx, gy


def inside_share(o: Box, a: Box) -> float:
    """How much of o's box lies inside a's box (0..1)."""
    ix = max(0.0, min(o[0] + o[2], a[0] + a[2]) - max(o[0], a[0]))
    iy = max(0.0, min(o[1] + o[3], a[1] + a[3]) - max(o[1], a[1]))
    return ix * iy / max(o[2] * o[3], 1e-6)


def next_to(o: Box, a: Box) -> float:
    gx, gy = box_gap(o, a)
    return math.exp(-math.hypot(gx, gy) / _size(o, a))


def further_back(o: Box, a: Box) -> float:
    """Degree to which o stands further from the camera than a (2-D: its bottom edge is higher in the image)."""
    ref = max(1.0, 0.5 * (o[3] + a[3]))
    return _sigmoid(((a[1] + a[3]) - (o[1] + o[3])) / (SOFT * ref))


def behind(o: Box, a: Box) -> float:
    gx, _ = box_gap(o, a)
    return further_back(o, a) * math.exp(-gx / _size(o, a))


def in_front_of(o: Box, a: Box) -> float:
    gx, _ = box_gap(o, a)
    return further_back(a, o) * math.exp(-gx / _size(o, a))


def _side(o: Box, a: Box, sign: float) -> float:
    """sign -1: o left of a; +1: right of a. Nearer objects on that side fit better."""
    side = _sigmoid(sign * ((o[0] + o[2] / 2) - (a[0] + a[2] / 2)) / (SOFT * _size(o, a)))
    return side * math.exp(-0.5 * math.hypot(*box_gap(o, a)) / _size(o, a))


def left_of(o: Box, a: Box) -> float:
    return _side(o, a, -1.0)


def right_of(o: Box, a: Box) -> float:
    return _side(o, a, 1.0)


def _smaller(o: Box, a: Box) -> float:
    return 1.0 if o[2] * o[3] < a[2] * a[3] else 0.2


def on(o: Box, a: Box) -> float:
    """o rests on a: o's bottom edge within a's box (a little above its top allowed), over it horizontally."""
    bottom = o[1] + o[3]
    tol = 0.1 * a[3]
    vertical = 1.0 if a[1] - tol <= bottom <= a[1] + a[3] + tol else math.exp(
        -min(abs(bottom - a[1]), abs(bottom - a[1] - a[3])) / max(1.0, 0.2 * a[3]))
    ox = max(0.0, min(o[0] + o[2], a[0] + a[2]) - max(o[0], a[0])) / max(o[2], 1e-6)
    return vertical * ox * _smaller(o, a)


def in_(o: Box, a: Box) -> float:
    return inside_share(o, a) * _smaller(o, a)


def under(o: Box, a: Box) -> float:
    ox = max(0.0, min(o[0] + o[2], a[0] + a[2]) - max(o[0], a[0])) / max(min(o[2], a[2]), 1e-6)
    return _sigmoid(((o[1] + o[3] / 2) - (a[1] + a[3] / 2)) / (SOFT * _size(o, a))) * ox


def above(o: Box, a: Box) -> float:
    return under(a, o)


def between(o: Box, a: Box, b: Box) -> float:
    """o's centre projects inside the segment between a's and b's centres and lies near it."""
    ox, oy = o[0] + o[2] / 2, o[1] + o[3] / 2
    ax, ay = a[0] + a[2] / 2, a[1] + a[3] / 2
    bx, by = b[0] + b[2] / 2, b[1] + b[3] / 2
    dx, dy = bx - ax, by - ay
    length2 = dx * dx + dy * dy
    if length2 < 1e-6:
        return 0.0
    t = ((ox - ax) * dx + (oy - ay) * dy) / length2
    inside = _sigmoid(t / SOFT) * _sigmoid((1 - t) / SOFT)
    off = abs((ox - ax) * dy - (oy - ay) * dx) / math.sqrt(length2)
    return inside * math.exp(-off / _size(o, o))


PAIRWISE = {"next_to": next_to, "behind": behind, "in_front_of": in_front_of, "left_of": left_of,
            "right_of": right_of, "on": on, "in": in_, "under": under, "above": above}


def relation_fit(kind: str, o: Box, anchors: list[Box]) -> float:
    """The best fit of o to `kind` over the anchors (pairs of anchors for "between"); 0 without anchors."""
    if kind == "between":
        return max((between(o, anchors[i], anchors[j]) for i in range(len(anchors))
                    for j in range(i + 1, len(anchors))), default=0.0)
    rule = PAIRWISE[kind]
    return max((rule(o, a) for a in anchors), default=0.0)
