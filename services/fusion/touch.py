"""Touch: a fingertip inside or on an object's box refers to that object. Pure geometry on boxes.

The fingertip is the ray's origin for a body ray (it starts at the index fingertip) and, for a hand ray (origin at
the index knuckle), the point where the ray leaves the hand's own landmark box (the tip is the hand's extremity in
the pointing direction). A box contains the tip when the tip lies inside it or within `EDGE_TOLERANCE` of its
diagonal (at least `EDGE_MIN_PX`) of its edge: a finger resting on a rim. When several boxes contain the tip, the
smallest is what is touched; a box that holds it (the table under the laptop, the tray under the cup) is what it
rests on, not what is meant. Boxes side by side that both contain the tip are both touched (the caller asks).
"""

from __future__ import annotations

import math

import numpy as np

Box = tuple[float, float, float, float]  # x, y, w, h
EDGE_TOLERANCE = 0.03  # of the box's diagonal
EDGE_MIN_PX = 3.0
NESTED = 0.8  # the smaller box lies this much inside the bigger one: the bigger one is its support


def fingertip(
    origin: tuple[float, float], direction: tuple[float, float], hand_box: tuple[float, float, float, float] | None
) -> tuple[float, float]:
    """The fingertip in the image. `hand_box`: x0, y0, x1, y1 of the pointing hand's landmarks for a hand ray (its
    origin is the index knuckle); None for a body ray (its origin is the fingertip)."""
    if hand_box is None:
        return origin
    x0, y0, x1, y1 = hand_box
    t_exit = math.inf
    for o, d, lo, hi in ((origin[0], direction[0], x0, x1), (origin[1], direction[1], y0, y1)):
        if abs(d) > 1e-9:
            t_exit = min(t_exit, max((lo - o) / d, (hi - o) / d))
    if not math.isfinite(t_exit) or t_exit < 0:
        return origin
    return origin[0] + t_exit * direction[0], origin[1] + t_exit * direction[1]


def contains(box: Box, point: tuple[float, float]) -> bool:
    x, y, w, h = box
    tol = max(EDGE_MIN_PX, EDGE_TOLERANCE * math.hypot(w, h))
    return x - tol <= point[0] <= x + w + tol and y - tol <= point[1] <= y + h + tol


def _inside_share(small: Box, big: Box) -> float:
    ix = max(0.0, min(small[0] + small[2], big[0] + big[2]) - max(small[0], big[0]))
    iy = max(0.0, min(small[1] + small[3], big[1] + big[3]) - max(small[1], big[1]))
    return ix * iy / max(small[2] * small[3], 1e-6)


def touched(point: tuple[float, float], boxes: list[Box] | np.ndarray) -> tuple[list[int], list[int]]:
    """(touched, supports): indices of the boxes (a list, or an n x 4 array) the fingertip touches (the smallest
    containing box, and any other containing box that does not hold it), and of the containing boxes that hold a
    touched one (what it rests on)."""
    if len(boxes) == 0:
        return [], []
    b = np.asarray(boxes, dtype=float).reshape(-1, 4)  # vectorised: a scene of 1000 boxes in microseconds
    tol = np.maximum(EDGE_MIN_PX, EDGE_TOLERANCE * np.hypot(b[:, 2], b[:, 3]))
    mask = (
        (b[:, 0] - tol <= point[0])
        & (point[0] <= b[:, 0] + b[:, 2] + tol)
        & (b[:, 1] - tol <= point[1])
        & (point[1] <= b[:, 1] + b[:, 3] + tol)
    )
    found = b[mask].tolist()  # the few containing boxes, as Python numbers
    order = sorted(range(len(found)), key=lambda k: found[k][2] * found[k][3])
    index = np.flatnonzero(mask).tolist()
    inside = [index[k] for k in order]
    box = dict(zip(index, found))
    hit: list[int] = []
    supports: list[int] = []
    for i in inside:
        if any(_inside_share(box[j], box[i]) >= NESTED for j in hit):
            supports.append(i)
        else:
            hit.append(i)
    return hit, supports
