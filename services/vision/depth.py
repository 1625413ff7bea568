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

import msgspec
import numpy as np

from common.schema import CameraInfo, DepthFrame, DetectedObject

MAX_SAMPLES = 4096      # points sampled per box (a regular grid): the median needs no more, and it stays cheap
MIN_POINTS = 12         # fewer valid depths in a box than this: no position
BIN_M = 0.01            # histogram bin: 1 cm …
BIN_SHARE = 0.01        # … or 1 % of the depth, whichever is larger (sensor noise grows with distance)
FLANK = 0.15            # a mode's cluster reaches down to this share of its peak's height
MIN_MODE_SHARE = 0.15   # a mode must hold this share of the box's valid depths to be an object


@dataclass(frozen=True)
class ObjectDepth:
    position: tuple[float, float, float]  # m, optical frame (x right, y down, z forward)
    extent: tuple[float, float, float]    # m
    support: float                        # share of the box's pixels with a valid depth
    points: int                           # foreground points used


def box_samples(depth_m: np.ndarray, bbox: tuple[float, float, float, float], max_samples: int = MAX_SAMPLES
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u, v, z) of a regular grid of the box's pixels (z NaN = no depth), at most about `max_samples`."""
    h, w = depth_m.shape
    x, y, bw, bh = bbox
    x0, y0 = max(0, int(math.floor(x))), max(0, int(math.floor(y)))
    x1, y1 = min(w, int(math.ceil(x + bw))), min(h, int(math.ceil(y + bh)))
    if x1 <= x0 or y1 <= y0:
        empty = np.zeros(0, np.float32)
        return empty, empty, empty
    step = max(1, int(math.ceil(math.sqrt((x1 - x0) * (y1 - y0) / max_samples))))
    # centred grid: the samples sit symmetrically in the box (a mirrored box samples the mirrored pixels)
    ox, oy = ((x1 - x0 - 1) % step) // 2, ((y1 - y0 - 1) % step) // 2
    z = depth_m[y0 + oy:y1:step, x0 + ox:x1:step]
    vs, us = np.mgrid[y0 + oy:y1:step, x0 + ox:x1:step]
    return us.ravel().astype(np.float32), vs.ravel().astype(np.float32), z.ravel()


def foreground(z: np.ndarray) -> np.ndarray:
    """Boolean mask over the valid depths `z` (metres, all finite): the nearest mode holding a real share."""
    if z.size == 0:
        return np.zeros(0, bool)
    lo, hi = float(z.min()), float(z.max())
    width = max(BIN_M, BIN_SHARE * float(np.median(z)))
    if hi - lo <= 3 * width:
        return np.ones(z.size, bool)  # one surface: all of it
    n_bins = int(math.ceil((hi - lo) / width)) + 1
    counts = np.bincount(((z - lo) / width).astype(np.int64), minlength=n_bins).astype(np.float64)
    smooth = np.convolve(np.pad(counts, 1), [0.25, 0.5, 0.25], mode="valid")
    padded = np.pad(smooth, 1, constant_values=-1.0)
    peaks = np.flatnonzero((smooth >= padded[:-2]) & (smooth > padded[2:]) & (smooth > 0))
    best: tuple[int, int] | None = None
    best_mass = -1.0
    for peak in peaks:  # nearest first
        floor = FLANK * smooth[peak]
        a = peak
        while a > 0 and smooth[a - 1] >= floor and smooth[a - 1] <= smooth[a] * 1.5:
            a -= 1
        b = peak
        while b < n_bins - 1 and smooth[b + 1] >= floor and smooth[b + 1] <= smooth[b] * 1.5:
            b += 1
        mass = counts[a:b + 1].sum()
        if mass >= MIN_MODE_SHARE * z.size:
            best = (a, b)
            break
        if mass > best_mass:
            best, best_mass = (a, b), mass
    assert best is not None
    a, b = best
    bins = ((z - lo) / width).astype(np.int64)
    return (bins >= a) & (bins <= b)


def back_project(u: np.ndarray, v: np.ndarray, z: np.ndarray, info: CameraInfo) -> np.ndarray:
    """N×3 points (metres, optical frame) of pixels (u, v) at depths z, through K (and the plumb_bob
    distortion when it has non-zero coefficients)."""
    fx, skew, cx, _, fy, cy = info.k[:6]
    if info.distortion_model == "plumb_bob" and any(info.distortion):
        import cv2
        k = np.array(info.k, np.float64).reshape(3, 3)
        pts = cv2.undistortPoints(np.stack([u, v], 1).astype(np.float64).reshape(-1, 1, 2), k,
                                  np.array(info.distortion, np.float64)).reshape(-1, 2)
        xn, yn = pts[:, 0], pts[:, 1]
    else:
        yn = (v - cy) / fy
        xn = (u - cx - skew * yn) / fx
    return np.stack([xn * z, yn * z, z], 1)


def object_depth(depth_m: np.ndarray, info: CameraInfo, bbox: tuple[float, float, float, float],
                 max_samples: int = MAX_SAMPLES) -> ObjectDepth | None:
    """Position, extent and depth support of the object in `bbox` ([x, y, w, h] px) from a float32 depth image
    in metres (NaN = no measurement) aligned to the image K belongs to; None without enough valid depth."""
    u, v, z = box_samples(depth_m, bbox, max_samples)
    if z.size == 0:
        return None
    valid = np.isfinite(z) & (z > 0)
    n_valid = int(valid.sum())
    if n_valid < MIN_POINTS:
        return None
    u, v, z = u[valid], v[valid], z[valid].astype(np.float64)
    own = foreground(z)
    if own.sum() < MIN_POINTS:
        return None
    pts = back_project(u[own], v[own], z[own], info)
    position = np.median(pts, axis=0)
    p5, p95 = np.percentile(pts, [5, 95], axis=0)
    return ObjectDepth(position=tuple(float(c) for c in position), extent=tuple(float(c) for c in p95 - p5),
                       support=n_valid / valid.size, points=int(own.sum()))


def with_depth(obj: DetectedObject, depth_m: np.ndarray, info: CameraInfo) -> DetectedObject:
    """The object with its position, extent and depth support from the depth image (unchanged without depth)."""
    measured = object_depth(depth_m, info, tuple(obj.bbox))
    if measured is None or measured.position[2] <= 0:
        return obj
    return msgspec.structs.replace(obj, position=[round(c, 4) for c in measured.position],
                                   extent=[round(c, 4) for c in measured.extent],
                                   depth_support=round(measured.support, 3))


class DepthMatcher:
    """The few latest depth frames per camera, and the one that belongs to a colour frame (same seq and stamp).
    Not thread-safe: the service's one worker calls it."""

    def __init__(self, keep: int = 4):
        self.keep = keep
        self.frames: dict[str, list[DepthFrame]] = {}

    def add(self, frame: DepthFrame) -> None:
        kept = self.frames.setdefault(frame.cam, [])
        kept.append(frame)
        del kept[:-self.keep]

    def match(self, cam: str, seq: int, stamp: float) -> DepthFrame | None:
        for frame in reversed(self.frames.get(cam, [])):
            if frame.seq == seq and abs(frame.stamp - stamp) < 1e-6:
                return frame
        return None
