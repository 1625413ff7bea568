"""Per-modality evidence and its reliability. Pure functions over contract samples.

Reliabilities are in [0, 1] and come from each modality's own evidence:
- speech: the recogniser's confidence (utterance and the content words), lowered for
  every word the parser had to correct fuzzily;
- vision: detection scores x image quality (a dark, flat or blurred frame is not trusted);
- gesture: hand landmark score x ray confidence x temporal stability of the ray.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from common.schema import (
    GESTURE,
    SPEECH,
    VISION,
    Detections,
    GestureEvent,
    Hands,
    ImageQuality,
    Modality,
    Transcript,
    Weights,
)
from services.fusion import space
from services.fusion.parse import Utterance, word_key

# Fixed weights used by `--weights fixed`: the comparison baseline that ignores evidence quality.
FIXED_WEIGHTS: dict[Modality, float] = {SPEECH: 0.4, VISION: 0.2, GESTURE: 0.4}
STABILITY_SPREAD_DEG = 15.0  # ray direction spread at which stability reaches 0
SINGLE_SAMPLE_STABILITY = 0.6  # one observation says nothing about stability: neither trust nor distrust
POINTING_CLUSTER_S = 0.5  # observations this close to the chosen one form the pointing gesture
FUZZY_PENALTY = 0.15  # per corrected word


def speech_reliability(transcript: Transcript, utterance: Utterance) -> float:
    content = {t for t in utterance.tokens}
    word_conf = [w.confidence for w in transcript.words if word_key(w.word) in content]
    rel = transcript.confidence
    if word_conf:
        rel = 0.5 * rel + 0.5 * min(word_conf)  # the weakest content word limits what we know
    rel *= max(0.0, 1.0 - FUZZY_PENALTY * len(utterance.corrections))
    return max(0.0, min(1.0, rel))


def image_quality(q: ImageQuality) -> float:
    """1 for a well exposed, contrasted, sharp frame; towards 0 for dark, flat or blurred ones.

    Bright is not bad in itself (a white table); a blown-out frame shows as low contrast (docs/vision.md)."""
    exposure = min(1.0, q.brightness / 0.25)
    contrast = 0.4 + 0.6 * min(1.0, q.contrast / 0.2)
    sharpness = 0.4 + 0.6 * min(1.0, q.sharpness / 0.2)
    return max(0.0, min(1.0, exposure * contrast * sharpness))


def vision_reliability(detections: list[Detections]) -> float:
    if not detections:
        return 0.0
    rels = []
    for det in detections:
        q = image_quality(det.quality)
        scores = sorted((o.score for o in det.objects), reverse=True)[:10]
        rels.append(q * (sum(scores) / len(scores) if scores else 0.5))
    return max(rels)


@dataclass(frozen=True)
class PointingObs:
    """One observation of a pointing ray (from a Hands frame or a point GestureEvent)."""

    stamp: float
    cam: str
    hand: str
    origin: tuple[float, float]
    direction: tuple[float, float]
    confidence: float  # ray confidence x hand score
    width: int
    height: int
    hand_box: tuple[float, float, float, float] | None = None  # x0, y0, x1, y1 of the hand's landmarks
    ray3d: space.Ray3 | None = None  # the same ray in metres, when the gesture service had depth
    person: str | None = None  # whose hand (`Hand.person`, `GestureEvent.person`), None = not known


@dataclass(frozen=True)
class Pointing:
    """The pointing gesture nearest the reference time, averaged over its cluster."""

    stamp: float
    cam: str
    hand: str
    origin: tuple[float, float]
    direction: tuple[float, float]
    confidence: float
    stability: float
    spread_deg: float
    n: int
    width: int
    height: int
    hand_box: tuple[float, float, float, float] | None = None  # the pointing hand itself: never its target
    ray3d: space.Ray3 | None = None  # the cluster's 3-D rays averaged (services/fusion/space.py)
    person: str | None = None  # whose pointing, None = not known

    @property
    def reliability(self) -> float:
        return max(0.0, min(1.0, self.confidence * self.stability))


def pointing_from_hands(hands: Hands) -> list[PointingObs]:
    out = []
    for h in hands.hands:
        if h.ray is None or h.gesture not in (None, "point"):
            continue
        xs, ys = [p[0] for p in h.landmarks], [p[1] for p in h.landmarks]
        out.append(
            PointingObs(
                hands.stamp,
                hands.cam,
                h.hand,
                space.vec2(h.ray.origin),
                space.vec2(h.ray.direction),
                h.ray.confidence * h.score,
                hands.width,
                hands.height,
                (min(xs), min(ys), max(xs), max(ys)),
                ray3d=space.from_wire(h.ray.ray3d),
                person=h.person,
            )
        )
    return out


def pointing_from_event(ev: GestureEvent) -> list[PointingObs]:
    if ev.gesture != "point" or ev.ray is None:
        return []
    return [
        PointingObs(
            ev.stamp,
            ev.cam,
            ev.hand,
            space.vec2(ev.ray.origin),
            space.vec2(ev.ray.direction),
            ev.ray.confidence * ev.score,
            ev.width,
            ev.height,
            ray3d=space.from_wire(ev.ray.ray3d),
            person=ev.person,
        )
    ]


def _angle_deg(a: tuple[float, float], b: tuple[float, float]) -> float:
    dot = max(-1.0, min(1.0, a[0] * b[0] + a[1] * b[1]))
    return math.degrees(math.acos(dot))


def select_pointing(observations: list[PointingObs], ref: float) -> Pointing | None:
    """The pointing nearest `ref` (ties: earlier, then camera/hand name), averaged with its neighbours."""
    if not observations:
        return None
    nearest = min(observations, key=lambda o: (abs(o.stamp - ref), o.stamp, o.cam, o.hand))
    cluster = sorted(
        (
            o
            for o in observations
            if o.cam == nearest.cam
            and o.hand == nearest.hand
            and o.person == nearest.person
            and abs(o.stamp - nearest.stamp) <= POINTING_CLUSTER_S
        ),
        key=lambda o: (o.stamp, o.origin, o.direction),
    )
    wsum = sum(max(o.confidence, 1e-6) for o in cluster)
    ox = sum(o.origin[0] * max(o.confidence, 1e-6) for o in cluster) / wsum
    oy = sum(o.origin[1] * max(o.confidence, 1e-6) for o in cluster) / wsum
    dx = sum(o.direction[0] * max(o.confidence, 1e-6) for o in cluster)
    dy = sum(o.direction[1] * max(o.confidence, 1e-6) for o in cluster)
    norm = math.hypot(dx, dy)
    direction = (dx / norm, dy / norm) if norm > 1e-9 else nearest.direction
    if len(cluster) > 1:
        spread = math.sqrt(sum(_angle_deg(o.direction, direction) ** 2 for o in cluster) / len(cluster))
        stability = max(0.0, 1.0 - spread / STABILITY_SPREAD_DEG)
    else:
        spread, stability = 0.0, SINGLE_SAMPLE_STABILITY
    confidence = sum(o.confidence for o in cluster) / len(cluster)
    boxes = [o.hand_box for o in cluster if o.hand_box is not None]
    hand_box = (
        (min(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes), max(b[3] for b in boxes))
        if boxes
        else None
    )
    return Pointing(
        stamp=nearest.stamp,
        cam=nearest.cam,
        hand=nearest.hand,
        origin=(ox, oy),
        direction=direction,
        confidence=confidence,
        stability=stability,
        spread_deg=spread,
        n=len(cluster),
        width=nearest.width,
        height=nearest.height,
        hand_box=hand_box,
        ray3d=space.mean_ray([(o.ray3d, o.confidence) for o in cluster]),
        person=nearest.person,
    )


def modality_weights(mode: str, reliabilities: dict[Modality, float | None]) -> Weights:
    """Normalised weights over the modalities present (None = missing, weight 0)."""
    raw = {}
    for m in (SPEECH, VISION, GESTURE):
        rel = reliabilities.get(m)
        if rel is None:
            raw[m] = 0.0
        elif mode == "fixed":
            raw[m] = FIXED_WEIGHTS[m]
        else:
            raw[m] = max(rel, 1e-3)  # present but useless still counts a little: never divide by zero
    total = sum(raw.values())
    if total <= 0:
        return Weights(speech=1.0, vision=0.0, gesture=0.0)
    return Weights(**{m: round(v / total, 4) for m, v in raw.items()})
