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

import numpy as np

Box = tuple[float, float, float, float]  # x, y, w, h

RELATIONS = ("next_to", "behind", "in_front_of", "left_of", "right_of", "on", "in", "under", "above", "between")
SOFT = 0.1  # fraction of the objects' size over which a "which side" test goes from doubt to certainty
BETWEEN_MAX_ANCHORS = 16  # "between the two bottles" looks at pairs of the best-fitting 16 bottles at most

# The rules work on arrays: `o` holds candidates as columns x, y, w, h of shape (n, 1), `a` anchors of shape (1, m);
# each rule returns the (n, m) matrix of fits. The scalar functions below wrap them for single boxes.


def _cols(boxes) -> tuple[np.ndarray, ...]:
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)
    return b[:, 0], b[:, 1], b[:, 2], b[:, 3]


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(x, -50.0, 50.0)))


class _Pair:
    """Candidates (rows) against anchors (columns): the quantities every rule needs."""

    def __init__(self, objects, anchors):
        ox, oy, ow, oh = (v[:, None] for v in _cols(objects))
        ax, ay, aw, ah = (v[None, :] for v in _cols(anchors))
        self.o, self.a = (ox, oy, ow, oh), (ax, ay, aw, ah)
        self.size = np.maximum(1.0, np.sqrt(0.5 * (ow * oh + aw * ah)))
        self.gx = np.maximum(0.0, np.maximum(ox - (ax + aw), ax - (ox + ow)))
        self.gy = np.maximum(0.0, np.maximum(oy - (ay + ah), ay - (oy + oh)))
        self.ix = np.maximum(0.0, np.minimum(ox + ow, ax + aw) - np.maximum(ox, ax))  # horizontal overlap
        self.iy = np.maximum(0.0, np.minimum(oy + oh, ay + ah) - np.maximum(oy, ay))
        self.smaller = np.where(ow * oh < aw * ah, 1.0, 0.2)  # what rests on or in something is smaller than it


def _next_to(p: _Pair) -> np.ndarray:
    return np.exp(-np.hypot(p.gx, p.gy) / p.size)


def _further_back(p: _Pair, sign: float) -> np.ndarray:
    """sign +1: o is further from the camera than a (its bottom edge higher in the image); -1: nearer."""
    (_, oy, _, oh), (_, ay, _, ah) = p.o, p.a
    ref = np.maximum(1.0, 0.5 * (oh + ah))
    return _sigmoid(sign * ((ay + ah) - (oy + oh)) / (SOFT * ref)) * np.exp(-p.gx / p.size)


def _side(p: _Pair, sign: float) -> np.ndarray:
    """sign -1: o left of a; +1: right of a. Nearer objects on that side fit better."""
    (ox, _, ow, _), (ax, _, aw, _) = p.o, p.a
    side = _sigmoid(sign * ((ox + ow / 2) - (ax + aw / 2)) / (SOFT * p.size))
    return side * np.exp(-0.5 * np.hypot(p.gx, p.gy) / p.size)


def _on(p: _Pair) -> np.ndarray:
    """o rests on a: o's bottom edge within a's box (a little above its top allowed), over it horizontally."""
    (_, oy, ow, oh), (_, ay, _, ah) = p.o, p.a
    bottom = oy + oh
    tol = 0.1 * ah
    inside = (bottom >= ay - tol) & (bottom <= ay + ah + tol)
    off = np.minimum(np.abs(bottom - ay), np.abs(bottom - ay - ah))
    vertical = np.where(inside, 1.0, np.exp(-off / np.maximum(1.0, 0.2 * ah)))
    return vertical * (p.ix / np.maximum(ow, 1e-6)) * p.smaller


def _in(p: _Pair) -> np.ndarray:
    (_, _, ow, oh), _ = p.o, p.a
    return p.ix * p.iy / np.maximum(ow * oh, 1e-6) * p.smaller


def _under(p: _Pair, sign: float) -> np.ndarray:
    """sign +1: o below a (under); -1: o above a. They overlap horizontally."""
    (_, oy, ow, oh), (_, ay, aw, ah) = p.o, p.a
    share = p.ix / np.maximum(np.minimum(ow, aw), 1e-6)
    return _sigmoid(sign * ((oy + oh / 2) - (ay + ah / 2)) / (SOFT * p.size)) * share


RULES = {
    "next_to": _next_to,
    "behind": lambda p: _further_back(p, 1.0),
    "in_front_of": lambda p: _further_back(p, -1.0),
    "left_of": lambda p: _side(p, -1.0),
    "right_of": lambda p: _side(p, 1.0),
    "on": _on,
    "in": _in,
    "under": lambda p: _under(p, 1.0),
    "above": lambda p: _under(p, -1.0),
}
PAIRWISE = tuple(RULES)


def fit_matrix(kind: str, objects, anchors) -> np.ndarray:
    """(n, m): how well each of n boxes stands in relation `kind` to each of m anchor boxes."""
    return RULES[kind](_Pair(objects, anchors))


def between_matrix(objects, first, second) -> np.ndarray:
    """(n, m, k): how well each box lies between anchor i of `first` and anchor j of `second`: its centre projects
    inside the segment between their centres and lies near it (within about its own size)."""
    ox, oy, ow, oh = (v[:, None, None] for v in _cols(objects))
    ax, ay, aw, ah = (v[None, :, None] for v in _cols(first))
    bx, by, bw, bh = (v[None, None, :] for v in _cols(second))
    cx, cy = ox + ow / 2, oy + oh / 2
    acx, acy, bcx, bcy = ax + aw / 2, ay + ah / 2, bx + bw / 2, by + bh / 2
    dx, dy = bcx - acx, bcy - acy
    length2 = dx * dx + dy * dy
    safe = np.maximum(length2, 1e-6)
    t = ((cx - acx) * dx + (cy - acy) * dy) / safe
    off = np.abs((cx - acx) * dy - (cy - acy) * dx) / np.sqrt(safe)
    fit = _sigmoid(t / SOFT) * _sigmoid((1 - t) / SOFT) * np.exp(-off / np.maximum(1.0, np.sqrt(ow * oh)))
    return np.where(length2 < 1e-6, 0.0, fit)


# -- single boxes (the rules above, one pair at a time) --------------------------------------------------------------
def relation(kind: str, o: Box, a: Box) -> float:
    return float(fit_matrix(kind, [o], [a])[0, 0])


def next_to(o: Box, a: Box) -> float:
    return relation("next_to", o, a)


def behind(o: Box, a: Box) -> float:
    return relation("behind", o, a)


def in_front_of(o: Box, a: Box) -> float:
    return relation("in_front_of", o, a)


def left_of(o: Box, a: Box) -> float:
    return relation("left_of", o, a)


def right_of(o: Box, a: Box) -> float:
    return relation("right_of", o, a)


def on(o: Box, a: Box) -> float:
    return relation("on", o, a)


def in_(o: Box, a: Box) -> float:
    return relation("in", o, a)


def under(o: Box, a: Box) -> float:
    return relation("under", o, a)


def above(o: Box, a: Box) -> float:
    return relation("above", o, a)


def between(o: Box, a: Box, b: Box) -> float:
    return float(between_matrix([o], [a], [b])[0, 0, 0])


def relation_fit(kind: str, o: Box, anchors: list[Box]) -> float:
    """The best fit of o to `kind` over the anchors (pairs of anchors for "between"); 0 without anchors."""
    if not anchors:
        return 0.0
    if kind == "between":
        m = between_matrix([o], anchors, anchors)[0]
        np.fill_diagonal(m, 0.0)
        return float(m.max())
    return float(fit_matrix(kind, [o], anchors).max())
