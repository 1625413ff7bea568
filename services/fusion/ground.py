"""Grounding: which detected object (or which point) an utterance and a gesture refer to. Pure.

Every candidate gets two pieces of evidence:
- speech S in [0, 1]: how well the said attributes (colour, class, spatial words) match what
  vision reports. In adaptive mode it is pulled towards 0.5 ("don't know") by how little vision
  can be trusted for that object (detection score x image quality x recency): in a dark frame
  "red" says little about which object is red.
- gesture G in [0, 1]: agreement with the pointing ray (angle between the ray and the direction
  from the ray origin to the object, less the angle the object itself covers; 0 behind the hand).
  The ray is the hand's (index finger) or the body's (eyes or forearm through the fingertip): both alike.
  An object *under the fingertip* (the ray enters its box within half its diagonal of the fingertip, as when
  someone points down at a cube on a table) gets G = 1, and every other object's G is halved: what the finger
  nearly touches wins over what lies further along the same ray.
The total is their weighted mean with the normalised modality weights. The winner must lead the
runner-up by `margin`, otherwise the caller asks (ambiguous, or conflict when speech and gesture
each back a different object).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from common.language import canonical_label, label_matches
from common.schema import Detections, Location, Target, Weights
from services.fusion.colour import colour_factors
from services.fusion.evidence import Pointing, image_quality
from services.fusion.parse import ObjectPhrase

POINTING_SIGMA_DEG = 8.0  # angular noise of a pointing ray from hand landmarks
SPATIAL_SCALE = 0.08  # fraction of the image size over which a spatial word's preference halves (roughly)
RECENCY_S = 2.0
DEFAULT_MARGIN = 0.1
MIN_EVIDENCE = 0.15  # below this the winner is a guess: confirm first
LOCATION_REACH = 0.35  # fraction of the image diagonal along the ray when no object is on it
MAX_CANDIDATES = 5
ON_RAY = 0.7  # gesture score from which "there" means the object on the ray
GESTURE_ONLY = Weights(speech=0.0, vision=0.0, gesture=1.0)
UNDER_TIP_GAP = 0.5  # an object is under the fingertip when the ray enters its box within this x its diagonal
FARTHER_ALONG = 0.5  # the gesture evidence of the other objects when one is under the fingertip


@dataclass(frozen=True)
class SceneObject:
    """A detected object with the context of the sample it came from."""
    id: str
    label: str  # the detector's label in the language's spelling (common.language.canonical_label)
    raw_label: str
    color: str | None
    bbox: tuple[float, float, float, float]
    center: tuple[float, float]
    score: float
    cam: str
    width: int
    height: int
    stamp: float
    quality: float  # image quality in [0, 1]
    lab: tuple[float, float, float] | None = None  # measured colour (CIELAB), when vision's colour model sent one
    colors: tuple[tuple[str, float], ...] = ()      # likeliest colour names with probabilities

    def to_target(self) -> Target:
        return Target(id=self.id, label=self.raw_label, color=self.color, bbox=list(self.bbox),
                      center=list(self.center), score=self.score, cam=self.cam)

    @property
    def key(self) -> tuple[str, str]:
        return self.cam, self.id

    def name(self) -> str:
        return f"{self.color + ' ' if self.color else ''}{self.label}"


def scene_objects(detections: list[Detections]) -> list[SceneObject]:
    out = []
    for det in detections:
        q = image_quality(det.quality)
        for o in det.objects:
            out.append(SceneObject(id=o.id, label=canonical_label(o.label), raw_label=o.label, color=o.color,
                                   bbox=tuple(o.bbox), center=tuple(o.center), score=o.score, cam=det.cam,
                                   width=det.width, height=det.height, stamp=det.stamp, quality=q,
                                   lab=None if o.lab is None else tuple(o.lab),
                                   colors=tuple((c.name, c.p) for c in o.colors)))
    return out


@dataclass(frozen=True)
class Scored:
    obj: SceneObject
    match: float  # how well the words fit, taking vision's labels at face value
    trust: float  # how far vision's labels for this object can be trusted
    speech: float
    gesture: float | None
    angle: float | None  # degrees off the ray
    total: float

    @property
    def evidence(self) -> float:
        """Support above chance from either side."""
        return max(abs(self.speech - 0.5) * 2 if self.match >= 0.5 else 0.0, self.gesture or 0.0)


def _attribute_match(phrase: ObjectPhrase, o: SceneObject) -> float:
    m = 1.0
    if not label_matches(phrase.label, o.label):  # "fruit" names the banana; "the banana" only the banana
        m = 0.0
    return m


def _spatial_scores(word: str, group: list[SceneObject]) -> dict[tuple[str, str], float]:
    """Preference in [0, 1] for each object of `group` (1 for the best fit)."""
    def expo(gap: float, size: float) -> float:
        return math.exp(-max(gap, 0.0) / (SPATIAL_SCALE * size))
    xs = {o.key: o.center[0] for o in group}
    ys = {o.key: o.center[1] for o in group}
    bottoms = {o.key: o.bbox[1] + o.bbox[3] for o in group}
    areas = {o.key: max(o.bbox[2] * o.bbox[3], 1e-6) for o in group}
    w = max(o.width for o in group)
    h = max(o.height for o in group)
    if word == "left":
        return {i: expo(x - min(xs.values()), w) for i, x in xs.items()}
    if word == "right":
        return {i: expo(max(xs.values()) - x, w) for i, x in xs.items()}
    if word == "top":
        return {i: expo(y - min(ys.values()), h) for i, y in ys.items()}
    if word == "bottom":
        return {i: expo(max(ys.values()) - y, h) for i, y in ys.items()}
    if word == "middle":
        mid = (min(xs.values()) + max(xs.values())) / 2
        return {i: expo(abs(x - mid), w) for i, x in xs.items()}
    if word == "nearest":  # no depth: nearer to the camera = lower in the image
        return {i: expo(max(bottoms.values()) - b, h) for i, b in bottoms.items()}
    if word == "farthest":
        return {i: expo(b - min(bottoms.values()), h) for i, b in bottoms.items()}
    if word == "biggest":
        return {i: (a / max(areas.values())) ** 2 for i, a in areas.items()}
    if word == "smallest":
        return {i: (min(areas.values()) / a) ** 2 for i, a in areas.items()}
    return {i: 1.0 for i in xs}


def pointing_score(p: Pointing, o: SceneObject) -> tuple[float, float | None]:
    """(G, angle in degrees). Objects in another camera, behind the hand, or on the pointing hand itself (a
    skin-coloured blob of the finger lies right on the ray) score 0."""
    if o.cam != p.cam:
        return 0.0, None
    if p.hand_box is not None:
        x0, y0, x1, y1 = p.hand_box
        if x0 <= o.center[0] <= x1 and y0 <= o.center[1] <= y1:
            return 0.0, None
    vx, vy = o.center[0] - p.origin[0], o.center[1] - p.origin[1]
    dist = math.hypot(vx, vy)
    radius = 0.5 * math.hypot(o.bbox[2], o.bbox[3]) * 0.5  # half of the half-diagonal: the object's core
    if dist <= 1e-6:
        return 1.0, 0.0
    cos = (vx * p.direction[0] + vy * p.direction[1]) / dist
    angle = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
    if cos <= 0:
        return 0.0, angle
    covered = math.degrees(math.atan2(radius, dist))
    sigma = max(POINTING_SIGMA_DEG, p.spread_deg)
    effective = max(0.0, angle - covered)
    return math.exp(-0.5 * (effective / sigma) ** 2), angle


def ray_gap(p: Pointing, o: SceneObject) -> float | None:
    """Distance (px) along the ray from its origin to where it enters the object's box (0 when the origin is
    inside it), None when the ray misses the box."""
    x, y, w, h = o.bbox
    t_near, t_far = 0.0, math.inf
    for origin, d, lo, hi in ((p.origin[0], p.direction[0], x, x + w), (p.origin[1], p.direction[1], y, y + h)):
        if abs(d) < 1e-9:
            if not lo <= origin <= hi:
                return None
            continue
        t0, t1 = sorted(((lo - origin) / d, (hi - origin) / d))
        t_near, t_far = max(t_near, t0), min(t_far, t1)
    return t_near if t_near <= t_far else None


def under_fingertip(p: Pointing, o: SceneObject) -> bool:
    """Does the finger (nearly) touch this object? The ray enters its box within half its diagonal of the
    fingertip; for a hand ray (origin at the index knuckle) the finger's own length is added (half the hand box)."""
    if o.cam != p.cam:
        return False
    gap = ray_gap(p, o)
    if gap is None:
        return False
    reach = UNDER_TIP_GAP * math.hypot(o.bbox[2], o.bbox[3])
    if p.hand_box is not None:
        reach += 0.5 * math.hypot(p.hand_box[2] - p.hand_box[0], p.hand_box[3] - p.hand_box[1])
    return gap <= reach


def deictic_scores(p: Pointing, objects: list[SceneObject]) -> dict[tuple[str, str], tuple[float, float | None]]:
    """(G, angle) per object: `pointing_score`, then what lies under the fingertip wins over what lies further
    along the ray."""
    out = {o.key: pointing_score(p, o) for o in objects}
    under = {o.key for o in objects if out[o.key][1] is not None and out[o.key][0] > 0 and under_fingertip(p, o)}
    if under:
        out = {k: ((1.0, a) if k in under else (g * FARTHER_ALONG, a)) for k, (g, a) in out.items()}
    return out


def score(phrase: ObjectPhrase, objects: list[SceneObject], pointing: Pointing | None, weights: Weights,
          *, adaptive: bool = True, ref: float | None = None) -> list[Scored]:
    """All objects scored and ranked (best first; ties broken by camera and id for determinism)."""
    if not objects:
        return []
    match = {o.key: _attribute_match(phrase, o) for o in objects}
    if phrase.color:  # by similarity, relative to the objects the other words fit (services/fusion/colour.py)
        factors = colour_factors(phrase.color, [o for o in objects if match[o.key] > 0])
        match = {k: m * factors.get(k, 0.0) for k, m in match.items()}
    fitting = [o for o in objects if match[o.key] >= 0.5] or list(objects)
    for word in phrase.spatial:  # spatial words choose among the objects that fit the other words
        prefs = _spatial_scores(word, fitting)
        for o in objects:
            match[o.key] *= prefs.get(o.key, 1.0)
    use_gesture = pointing is not None and weights.gesture > 0
    ws, wg = weights.speech, (weights.gesture if use_gesture else 0.0)
    if ws + wg <= 0:
        ws = 1.0
    deictic = deictic_scores(pointing, objects) if use_gesture else {}
    scored = []
    for o in objects:
        m = match[o.key]
        if adaptive:
            recency = math.exp(-abs(o.stamp - ref) / RECENCY_S) if ref is not None else 1.0
            trust = o.score * o.quality * recency
        else:
            trust = 1.0
        s = 0.5 + (m - 0.5) * trust
        g, angle = deictic[o.key] if use_gesture else (None, None)
        total = (ws * s + wg * (g or 0.0)) / (ws + wg)
        scored.append(Scored(o, m, trust, s, g, angle, total))
    scored.sort(key=lambda c: (-round(c.total, 9), c.obj.cam, c.obj.id))
    return scored


@dataclass(frozen=True)
class Choice:
    kind: str  # "target", "ambiguous", "conflict", "not_found", "low_confidence"
    winner: Scored | None
    candidates: tuple[Scored, ...]
    speech_best: Scored | None = None
    gesture_best: Scored | None = None
    overruled: str | None = None  # "speech" or "gesture" when the other side won a disagreement
    runner_up: Scored | None = None


def choose(phrase: ObjectPhrase, scored: list[Scored], *, margin: float = DEFAULT_MARGIN,
           check_evidence: bool = True) -> Choice:
    """Decide from a ranked list (as `score` returns it). Linear in the number of candidates."""
    if not scored:
        return Choice("not_found", None, ())
    pointing = scored[0].gesture is not None
    # argmax keeps the first (best ranked) on ties: max() over (value, -rank)
    speech_best = scored[max(range(len(scored)), key=lambda i: (scored[i].speech, -i))] if phrase.specific else None
    gesture_best = scored[max(range(len(scored)), key=lambda i: (scored[i].gesture or 0.0, -i))] if pointing else None
    pointed = gesture_best is not None and (gesture_best.gesture or 0.0) >= 0.5
    if phrase.specific and max(c.match for c in scored) < 0.5 and not pointed:
        return Choice("not_found", None, (), speech_best, gesture_best)
    winner = scored[0]
    runner_up = scored[1] if len(scored) > 1 else None
    disagree = (speech_best is not None and gesture_best is not None and pointed
                and speech_best is not gesture_best and speech_best.match >= 0.5)
    # Without pointing, two objects the words fit equally well ("the fruit": an apple and an orange) are a
    # question, whatever their detection scores: a more confident detector is not what the person meant.
    tie_in_words = (runner_up is not None and not pointing and winner.match >= 0.5
                    and abs(winner.match - runner_up.match) < 1e-6)
    if runner_up is not None and (winner.total - runner_up.total < margin or tie_in_words):
        if disagree and {id(winner), id(runner_up)} == {id(speech_best), id(gesture_best)}:
            return Choice("conflict", None, (speech_best, gesture_best), speech_best, gesture_best,
                          runner_up=runner_up)
        close = []
        for c in scored:  # ranked: stop at the first that is clearly behind
            if (winner.total - c.total >= margin and not (tie_in_words and abs(c.match - winner.match) < 1e-6)) \
                    or len(close) == MAX_CANDIDATES:
                break
            close.append(c)
        return Choice("ambiguous", None, tuple(close), speech_best, gesture_best, runner_up=runner_up)
    if check_evidence and winner.evidence < MIN_EVIDENCE:
        return Choice("low_confidence", winner, (winner,), speech_best, gesture_best, runner_up=runner_up)
    overruled = None
    if disagree:
        overruled = "speech" if winner is gesture_best else "gesture"
    return Choice("target", winner, (winner,), speech_best, gesture_best, overruled, runner_up)


def ray_point(p: Pointing, reach: float = LOCATION_REACH) -> tuple[float, float]:
    """The image point the ray indicates when no object lies on it: `reach` of the image diagonal
    along the ray, stopped at the image border."""
    ox, oy = p.origin
    dx, dy = p.direction
    limits = []
    for o, d, size in ((ox, dx, p.width), (oy, dy, p.height)):
        if d > 1e-9:
            limits.append((size - 1 - o) / d)
        elif d < -1e-9:
            limits.append(-o / d)
    t = min([reach * math.hypot(p.width, p.height), *[lim for lim in limits if lim >= 0]])
    x = min(max(ox + t * dx, 0.0), p.width - 1)
    y = min(max(oy + t * dy, 0.0), p.height - 1)
    return round(x, 1), round(y, 1)


def best_pointed(p: Pointing, objects: list[SceneObject]) -> Scored | None:
    """The object the ray points at best, by the gesture alone (None: no objects)."""
    ranked = score(ObjectPhrase(), objects, p, GESTURE_ONLY)
    return ranked[0] if ranked else None


def pointed_location(p: Pointing, objects: list[SceneObject]) -> Location:
    """Where "there" is: the centre of the object on the ray (G >= `ON_RAY`), else `ray_point`."""
    best = best_pointed(p, [o for o in objects if o.cam == p.cam])
    if best is not None and (best.gesture or 0.0) >= ON_RAY:
        x, y = best.obj.center
    else:
        x, y = ray_point(p)
    return Location(x=float(x), y=float(y), cam=p.cam)
