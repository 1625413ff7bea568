"""Where an object is, in metres, from an aligned depth image and the camera's K — pure numpy, no Zenoh.

A detector's box holds the object and whatever is behind or beside it (the wall, the table). The object's own
pixels are taken as the nearest depth mode in the box that holds a real share of its valid pixels: the depths
in the box are binned (1 cm, or 1 % of the depth farther away), the smoothed histogram's peaks are tried from
the nearest, and the first whose cluster (the peak and its flanks down to 15 % of its height) holds at least
15 % of the box's valid pixels is the object. A stray near pixel or a thin thing in front does not make a
mode; the wall behind a bottle does, but farther away. Those pixels are back-projected with K
(x = (u − cx)·z / fx, y = (v − cy)·z / fy, z = depth) and

* position = the per-axis median of the points: the middle of the object's visible surface (its front, not its
  centre of mass: a grasp planner adds its own depth offset);
* extent = the 5th–95th percentile spread of the points per axis (the visible surface's size, robust to
  stray pixels);
* depth support = the share of the box's pixels with a valid depth (holes: black, shiny, transparent or too
  near objects, shadows of the projector).

A box with fewer than MIN_POINTS valid depths has no position (absent, never zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import msgspec
import numpy as np

from common.depth import depth_units
from common.schema import CameraInfo, DepthFrame, DetectedObject

MAX_SAMPLES = 1024  # points sampled per box (a regular grid): a median needs no more, and 30 boxes stay cheap
MIN_POINTS = 12  # fewer valid depths in a box than this: no position
BIN_M = 0.01  # histogram bin: 1 cm …
BIN_SHARE = 0.01  # … or 1 % of the depth, whichever is larger (sensor noise grows with distance)
FLANK = 0.15  # a mode's cluster reaches down to this share of its peak's height
MIN_MODE_SHARE = 0.15  # a mode must hold this share of the box's valid depths to be an object


class DepthImage(NamedTuple):
    """An aligned depth image as it came (uint16 or float32 units: converted per sampled pixel, not per frame)."""

    units: np.ndarray
    depth_scale: float  # metres per unit
    camera_info: CameraInfo

    @classmethod
    def from_frame(cls, frame: DepthFrame) -> "DepthImage":
        """Raises common.depth.UndecodableDepth."""
        return cls(depth_units(frame), frame.depth_scale, frame.camera_info)


@dataclass(frozen=True)
class ObjectDepth:
    position: tuple[float, float, float]  # m, optical frame (x right, y down, z forward)
    extent: tuple[float, float, float]  # m
    support: float  # share of the box's pixels with a valid depth
    points: int  # foreground points used


def box_samples(
    depth: np.ndarray, bbox: tuple[float, float, float, float], max_samples: int = MAX_SAMPLES, depth_scale: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(u, v, z metres) of the valid pixels of a regular grid over the box (at most about `max_samples`), and
    how many grid pixels there were in all."""
    h, w = depth.shape
    x, y, bw, bh = bbox
    x0, y0 = max(0, int(math.floor(x))), max(0, int(math.floor(y)))
    x1, y1 = min(w, int(math.ceil(x + bw))), min(h, int(math.ceil(y + bh)))
    if x1 <= x0 or y1 <= y0:
        empty = np.zeros(0)
        return empty, empty, empty, 0
    step = max(1, int(math.ceil(math.sqrt((x1 - x0) * (y1 - y0) / max_samples))))
    # centred grid: the samples sit symmetrically in the box (a mirrored box samples the mirrored pixels)
    ox, oy = ((x1 - x0 - 1) % step) // 2, ((y1 - y0 - 1) % step) // 2
    grid = depth[y0 + oy : y1 : step, x0 + ox : x1 : step]
    if grid.dtype.kind == "u" and depth_scale > 0:  # integer units: only 0 is no depth, read before scaling
        index = np.flatnonzero(grid)
        z = grid.ravel()[index].astype(np.float64) * depth_scale
    else:
        z = grid.ravel().astype(np.float64) * depth_scale
        with np.errstate(invalid="ignore"):
            index = np.flatnonzero((z > 0) & (z < np.inf))  # NaN compares False: 0, NaN and inf are no depth
        z = z[index]
    rows, cols = np.divmod(index, grid.shape[1])
    return (x0 + ox + cols * step).astype(np.float64), (y0 + oy + rows * step).astype(np.float64), z, grid.size


def foreground(z: np.ndarray) -> np.ndarray:
    """Boolean mask over the valid depths `z` (metres, all finite): the nearest mode holding a real share."""
    if z.size == 0:
        return np.zeros(0, bool)
    lo, hi = float(z.min()), float(z.max())
    width = max(BIN_M, BIN_SHARE * float(z.mean()))
    if hi - lo <= 3 * width:
        return np.ones(z.size, bool)  # one surface: all of it
    n_bins = int(math.ceil((hi - lo) / width)) + 1
    bins = ((z - lo) / width).astype(np.int64)
    counts = np.bincount(bins, minlength=n_bins).astype(np.float64)
    smooth = np.convolve(counts, [0.25, 0.5, 0.25])[1:-1]  # same length, zeros beyond the ends
    padded = np.concatenate(([-1.0], smooth, [-1.0]))
    peaks = np.flatnonzero((smooth >= padded[:-2]) & (smooth > padded[2:]) & (smooth > 0))
    best: tuple[int, int] | None = None
    best_mass = -1.0
    smooth = smooth.tolist()  # the walk below reads single bins: Python floats are faster than numpy scalars
    for peak in peaks.tolist():  # nearest first
        floor = FLANK * smooth[peak]
        a = peak
        while a > 0 and smooth[a - 1] >= floor and smooth[a - 1] <= smooth[a] * 1.5:
            a -= 1
        b = peak
        while b < n_bins - 1 and smooth[b + 1] >= floor and smooth[b + 1] <= smooth[b] * 1.5:
            b += 1
        mass = float(counts[a : b + 1].sum())
        if mass >= MIN_MODE_SHARE * z.size:
            best = (a, b)
            break
        if mass > best_mass:
            best, best_mass = (a, b), mass
    assert best is not None
    a, b = best
    return (bins >= a) & (bins <= b)


def back_project(u: np.ndarray, v: np.ndarray, z: np.ndarray, info: CameraInfo) -> np.ndarray:
    """N×3 points (metres, optical frame) of pixels (u, v) at depths z, through K (and the plumb_bob
    distortion when it has non-zero coefficients)."""
    fx, skew, cx, _, fy, cy = info.k[:6]
    if info.distortion_model == "plumb_bob" and any(info.distortion):
        import cv2

        k = np.array(info.k, np.float64).reshape(3, 3)
        pts = cv2.undistortPoints(
            np.stack([u, v], 1).astype(np.float64).reshape(-1, 1, 2), k, np.array(info.distortion, np.float64)
        ).reshape(-1, 2)
        xn, yn = pts[:, 0], pts[:, 1]
    else:
        yn = (v - cy) / fy
        xn = (u - cx - skew * yn) / fx
    return np.stack([xn * z, yn * z, z], 1)


def object_depth(
    depth: np.ndarray,
    info: CameraInfo,
    bbox: tuple[float, float, float, float],
    max_samples: int = MAX_SAMPLES,
    depth_scale: float = 1.0,
) -> ObjectDepth | None:
    """Position, extent and depth support of the object in `bbox` ([x, y, w, h] px) from a depth image aligned
    to the image K belongs to (units × `depth_scale` = metres; 0 or NaN = no measurement); None without enough
    valid depth."""
    u, v, z, total = box_samples(depth, bbox, max_samples, depth_scale)
    if z.size < MIN_POINTS:
        return None
    own = foreground(z)
    n_own = int(own.sum())
    if n_own < MIN_POINTS:
        return None
    p5, position, p95 = _quantiles(back_project(u[own], v[own], z[own], info), n_own).tolist()
    return ObjectDepth(
        position=tuple(position),
        extent=(p95[0] - p5[0], p95[1] - p5[1], p95[2] - p5[2]),
        support=z.size / total,
        points=n_own,
    )


QUANTILES = np.array([0.05, 0.5, 0.95])
PARTITION_FROM = 256  # rows: from here, putting only the quantiles' ranks in order beats a full sort (~3x at 1000)


def _quantiles(rows: np.ndarray, n: int) -> np.ndarray:
    """The 5th, 50th and 95th percentiles (rows) of each column of `rows` (n of them), interpolated linearly as
    numpy's default."""
    at = QUANTILES * (n - 1)
    lo = at.astype(np.int64)
    hi = np.minimum(lo + 1, n - 1)
    if n >= PARTITION_FROM:  # the values at the ranks asked for are those a sort gives
        ranked = np.partition(rows, np.unique(np.concatenate([lo, hi])), axis=0)
    else:
        ranked = np.sort(rows, axis=0)
    return ranked[lo] + (at - lo)[:, None] * (ranked[hi] - ranked[lo])


def with_depth(obj: DetectedObject, depth: DepthImage) -> DetectedObject:
    """The object with its position, extent and depth support from the depth image (unchanged without depth)."""
    x, y, w, h = obj.bbox  # a wire Box: four numbers
    measured = object_depth(depth.units, depth.camera_info, (x, y, w, h), depth_scale=depth.depth_scale)
    if measured is None or measured.position[2] <= 0:
        return obj
    return msgspec.structs.replace(
        obj,
        position=[round(c, 4) for c in measured.position],
        extent=[round(c, 4) for c in measured.extent],
        depth_support=round(measured.support, 3),
    )


EXPECT_DEPTH_S = 1.0  # a camera that sent depth this recently (source time) is expected to send it again
DEPTH_MISSES = 3  # ... and so is one whose depth came since its last this many colour frames without a depth


class DepthMatcher:
    """Pairs colour frames with the depth frame of the same capture (same cam, seq and stamp). Not thread-safe:
    the service's one worker calls it.

    Depth and colour arrive on two latest-only keys, so the colour frame can be served before its depth. A
    colour frame without its depth therefore waits (one per camera) when the camera is sending depth and no newer
    depth is already in: its depth is then usually next in line. It is released when the depth comes, or dropped
    when a newer colour frame of the camera arrives first (counted by the caller as skipped: latest-only).

    "Sending depth": its newest depth is within EXPECT_DEPTH_S (source time) of the frame, or a depth came since
    fewer than DEPTH_MISSES colour frames asked (`expects`) in vain. Time alone judged it wrongly on a loaded
    machine: the newest depth the worker had served was then a whole vision cycle (over 1 s) older than the colour
    frame, and every colour frame served before its depth went out without positions (issue #41). A camera
    whose depth stopped is waited for until both run out; a camera without depth never makes a frame wait.

    A colour frame whose depth a newer capture's depth already replaced (`overtaken`) is skipped too: published
    without positions it would turn a depth camera's objects 2-D for a frame, so that "the nearest" meant the
    lowest box (issue #41); the newer capture's colour frame comes next with its depth.
    """

    def __init__(self, keep: int = 4, expect_s: float = EXPECT_DEPTH_S, misses: int = DEPTH_MISSES):
        self.keep = keep
        self.expect_s = expect_s
        self.misses = misses
        self.frames: dict[str, list[DepthFrame]] = {}
        self.waiting: dict[str, tuple[Any, Any]] = {}  # cam -> (colour frame, its decoded image)
        self.missed: dict[str, int] = {}  # cam -> colour frames that asked for a depth since its newest came

    def add(self, frame: DepthFrame) -> tuple[Any, Any] | None:
        """Keep a depth frame; returns the waiting (colour frame, image) it belongs to, if any."""
        kept = self.frames.setdefault(frame.cam, [])
        kept.append(frame)
        del kept[: -self.keep]
        self.missed[frame.cam] = 0
        waiting = self.waiting.get(frame.cam)
        if waiting is not None and self._same(frame, waiting[0].seq, waiting[0].stamp):
            return self.waiting.pop(frame.cam)
        return None

    @staticmethod
    def _same(depth: DepthFrame, seq: int, stamp: float) -> bool:
        return depth.seq == seq and abs(depth.stamp - stamp) < 1e-6

    def match(self, cam: str, seq: int, stamp: float) -> DepthFrame | None:
        for frame in reversed(self.frames.get(cam, [])):
            if self._same(frame, seq, stamp):
                return frame
        return None

    def expects(self, cam: str, seq: int, stamp: float) -> bool:
        """True if the depth of this capture is probably still on its way (asked once per colour frame that has
        no depth in yet)."""
        kept = self.frames.get(cam)
        if not kept:
            return False
        self.missed[cam] = missed = self.missed.get(cam, 0) + 1
        newest = kept[-1]
        return newest.stamp < stamp and (stamp - newest.stamp <= self.expect_s or missed <= self.misses)

    def overtaken(self, cam: str, stamp: float) -> bool:
        """True if a newer capture's depth is already in (within EXPECT_DEPTH_S): this colour frame's own depth was
        replaced in its latest-only slot, and the newer capture's colour frame is next with its depth."""
        kept = self.frames.get(cam)
        return kept is not None and len(kept) > 0 and 0 < kept[-1].stamp - stamp <= self.expect_s

    def wait(self, frame: Any, image: Any) -> tuple[Any, Any] | None:
        """Park a colour frame for its depth; returns the one it replaces (its depth never came), if any."""
        replaced = self.waiting.pop(frame.cam, None)
        self.waiting[frame.cam] = (frame, image)
        return replaced

    def take_waiting(self, cam: str) -> tuple[Any, Any] | None:
        return self.waiting.pop(cam, None)
