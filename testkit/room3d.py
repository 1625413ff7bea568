"""A room seen by a pinhole camera (f 600 px, 640x480, frame `cam0_optical`) for fusion's 3-D tests: objects as vision
reports them with depth, and a person's pointing hand whose 2-D ray is the image of the eye -> fingertip line and
whose 3-D ray is that line in metres (what the gesture service publishes with depth)."""

from __future__ import annotations

from typing import Callable, Sequence, Union

import numpy as np

from common.schema import DetectedObject, Detections, Hand, Hands, ImageQuality, Ray, Ray3D, Sample
from testkit.scenarios import BASE_STAMP, KEYS, Step, landmarks_at

F, CX, CY, W, H = 600.0, 320.0, 240.0, 640, 480
FRAME = "cam0_optical"
EYES = np.array([0.45, -0.55, 3.2])  # a person 3.2 m from the camera, facing it, eyes 0.55 m above its axis
ARM_M = 0.7  # eyes to fingertip
Vec = Union[Sequence[float], np.ndarray]


def project(p: Vec) -> np.ndarray:
    return np.array([p[0] * F / p[2] + CX, p[1] * F / p[2] + CY])


def unit(v: Vec) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    return a / np.linalg.norm(a)


def thing(
    oid: str, label: str, position: Vec, size: Vec = (0.08, 0.22, 0.08), color: str | None = None
) -> DetectedObject:
    """A detected object at `position` (m) as vision would report it with depth: its box is its projection."""
    c = project(position)
    w, h = size[0] * F / position[2], size[1] * F / position[2]
    return DetectedObject(
        id=oid,
        label=label,
        color=color,
        score=0.9,
        bbox=[float(c[0] - w / 2), float(c[1] - h / 2), float(w), float(h)],
        center=[float(c[0]), float(c[1])],
        position=[float(v) for v in position],
        extent=[float(v) for v in size],
        depth_support=0.8,
    )


def flat(o: DetectedObject) -> DetectedObject:
    """The same detection without depth."""
    return DetectedObject(id=o.id, label=o.label, color=o.color, score=o.score, bbox=o.bbox, center=o.center)


def detections(objects: list[DetectedObject], stamp: float = BASE_STAMP, depth: bool = True) -> Detections:
    return Detections(
        stamp=stamp,
        source="vision/cam0",
        seq=1,
        cam="cam0",
        width=W,
        height=H,
        objects=[o if depth else flat(o) for o in objects],
        quality=ImageQuality(brightness=0.5, contrast=0.5, sharpness=0.6),
        frame_id=FRAME if depth else None,
    )


def pointing_hand(target: Vec, eyes: Vec = EYES, hit: Vec | None = None, with_3d: bool = True) -> Hand:
    """A hand at arm's length from the eyes towards `target` (m), its 2-D ray the image of eye -> tip; `hit`: where
    the 3-D ray met a surface."""
    e = np.asarray(eyes, dtype=float)
    d = unit(np.asarray(target, dtype=float) - e)
    tip_px = project(e + ARM_M * d)
    d2 = unit(tip_px - project(e))
    ray3d = (
        Ray3D(
            origin=[float(v) for v in e],
            direction=[float(v) for v in d],
            method="eye_fingertip",
            frame_id=FRAME,
            hit=None if hit is None else [float(v) for v in hit],
        )
        if with_3d
        else None
    )
    return Hand(
        hand="right",
        score=0.95,
        landmarks=landmarks_at(float(tip_px[0]), float(tip_px[1])),
        gesture="point",
        ray=Ray(
            origin=[float(v) for v in tip_px],
            direction=[float(v) for v in d2],
            confidence=0.9,
            source="body",
            ray3d=ray3d,
        ),
    )


def hands(hand: Hand, stamp: float = BASE_STAMP) -> Hands:
    return Hands(stamp=stamp, source="gesture/cam0", seq=1, cam="cam0", width=W, height=H, hands=[hand])


def step(t: float, make: Callable[[float], Sample]) -> Step:
    """A scenario step publishing `make(stamp)` on its camera's key (Detections on objects, else hands)."""

    def build(base: float) -> tuple[str, Sample]:
        sample = make(base + t)
        key = KEYS.objects("cam0") if isinstance(sample, Detections) else KEYS.hands("cam0")
        return key, sample

    return Step(t, build)
