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
from dataclasses import dataclass, field
from itertools import chain
from typing import Literal, NamedTuple

import numpy as np

from common.language import canonical_label, label_matches
from common.schema import (
    GESTURE,
    SPEECH,
    ClarificationReason,
    DetectedObject,
    Detections,
    Location,
    Target,
    Weights,
)
from services.fusion import space
from services.fusion.color import colour_factors
from services.fusion.evidence import Pointing, image_quality
from services.fusion.parse import ObjectPhrase, Relation
from services.fusion.relations import BETWEEN_MAX_ANCHORS, between_matrix, fit_matrix
from services.fusion.touch import fingertip, touched

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
    position: tuple[float, float, float] | None = None  # metres in `frame_id` (camera optical frame), with depth
    extent: tuple[float, float, float] | None = None
    frame_id: str | None = None
    lab: tuple[float, float, float] | None = None  # measured colour (CIELAB), when vision's colour model sent one
    colors: tuple[tuple[str, float], ...] = ()  # likeliest colour names with probabilities
    # (cam, id): read tens of times per object and decision, so made once (not a property: 1000 objects, #34)
    key: tuple[str, str] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "key", (self.cam, self.id))

    def to_target(self) -> Target:
        return Target(
            id=self.id,
            label=self.raw_label,
            color=self.color,
            bbox=list(self.bbox),
            center=list(self.center),
            score=self.score,
            cam=self.cam,
            position=list(self.position) if self.position else None,
            extent=list(self.extent) if self.extent else None,
            frame_id=self.frame_id if self.position else None,
        )

    def name(self) -> str:
        return f"{self.color + ' ' if self.color else ''}{self.label}"


def _scene_object(det: Detections, o: DetectedObject, label: str, quality: float) -> SceneObject:
    """One wire object as a SceneObject, its fields set in one `__dict__` update: a frozen dataclass's `__init__` sets
    each of its 18 fields by `object.__setattr__`, half the time of building 1000 objects (issue #34). The same
    fields and values as `SceneObject(...)` (tests/test_fusion_ground.py checks it)."""
    obj = object.__new__(SceneObject)
    obj.__dict__.update(
        id=o.id,
        label=label,
        raw_label=o.label,
        color=o.color,
        bbox=tuple(o.bbox),
        center=tuple(o.center),
        score=o.score,
        cam=det.cam,
        width=det.width,
        height=det.height,
        stamp=det.stamp,
        quality=quality,
        position=space.vec3(o.position) if o.position else None,
        extent=space.vec3(o.extent) if o.extent else None,
        frame_id=det.frame_id,
        lab=None if o.lab is None else space.vec3(o.lab),
        colors=tuple([(c.name, c.p) for c in o.colors]) if o.colors else (),
        key=(det.cam, o.id),
    )
    return obj


def scene_objects(detections: list[Detections]) -> list[SceneObject]:
    out = []
    labels: dict[str, str] = {}  # canonical_label once per label, not once per object (1000 objects: issue #34)
    for det in detections:
        q = image_quality(det.quality)
        for o in det.objects:
            label = labels.get(o.label)
            if label is None:
                label = labels[o.label] = canonical_label(o.label)
            out.append(_scene_object(det, o, label, q))
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
    rule: str | None = None  # how pointing scored it (`Deictic.rule`): touch, under the fingertip, along the ray
    off_m: float | None = None  # metres from the 3-D ray, when compared in metres

    @property
    def evidence(self) -> float:
        """Support above chance from either side."""
        return max(abs(self.speech - 0.5) * 2 if self.match >= 0.5 else 0.0, self.gesture or 0.0)


def _attribute_match(phrase: ObjectPhrase, o: SceneObject) -> float:
    m = 1.0
    if not label_matches(phrase.label, o.label):  # "fruit" names the banana; "the banana" only the banana
        m = 0.0
    return m


def _attribute_matches(phrase: ObjectPhrase, objects: list[SceneObject]) -> dict[tuple[str, str], float]:
    """`_attribute_match` of every object, once per label (a thousand objects are a few labels: issue #34)."""
    by_label: dict[str, float] = {}
    out = {}
    for o in objects:
        m = by_label.get(o.label)
        if m is None:
            m = by_label[o.label] = _attribute_match(phrase, o)
        out[o.key] = m
    return out


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
    if word in ("nearest", "farthest") and all(o.position is not None for o in group):  # by depth, in metres
        return space.distance_preferences(word, {o.key: o.position for o in group})
    if word == "nearest":  # no depth: nearer to the camera = lower in the image
        return {i: expo(max(bottoms.values()) - b, h) for i, b in bottoms.items()}
    if word == "farthest":
        return {i: expo(b - min(bottoms.values()), h) for i, b in bottoms.items()}
    if word == "biggest":
        return {i: (a / max(areas.values())) ** 2 for i, a in areas.items()}
    if word == "smallest":
        return {i: (min(areas.values()) / a) ** 2 for i, a in areas.items()}
    return {i: 1.0 for i in xs}


def in_3d(p: Pointing, o: SceneObject) -> bool:
    """Are the ray and this object both in metres, in one frame? Then they are compared in 3-D."""
    return p.ray3d is not None and o.position is not None and space.same_frame(p.ray3d, o.frame_id)


class Deictic(NamedTuple):
    """What pointing says about one object."""

    gesture: float  # G in [0, 1]
    angle: float | None  # degrees off the ray (None: another camera, or on the pointing hand)
    rule: str | None = None  # "touch", "under the fingertip", "along the 3-D ray", "along the image ray"
    off_m: float | None = None  # metres from the 3-D ray's line, when compared in metres


def ray_score(p: Pointing, o: SceneObject) -> Deictic:
    """G by the ray alone. Objects in another camera, behind the hand, or on the pointing hand itself (a
    skin-coloured blob of the finger lies right on the ray) score 0. In metres (`space.pointing_score`): the
    distance from the ray against a tolerance that grows with the distance; in pixels: the angle."""
    if o.cam != p.cam or on_the_hand(p, o):
        return Deictic(0.0, None)
    if p.ray3d is not None and in_3d(p, o):  # (in_3d checks the ray too; said here for the type checker)
        g3, angle3, off = space.pointing_score(p.ray3d, o.position, o.extent, p.spread_deg)
        return Deictic(g3, angle3, "along the 3-D ray", off)
    vx, vy = o.center[0] - p.origin[0], o.center[1] - p.origin[1]
    dist = math.hypot(vx, vy)
    radius = 0.5 * math.hypot(o.bbox[2], o.bbox[3]) * 0.5  # half of the half-diagonal: the object's core
    if dist <= 1e-6:
        return Deictic(1.0, 0.0, "along the image ray")
    cos = (vx * p.direction[0] + vy * p.direction[1]) / dist
    angle = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
    if cos <= 0:
        return Deictic(0.0, angle, "along the image ray")
    covered = math.degrees(math.atan2(radius, dist))
    sigma = max(space.POINTING_NOISE_DEG, p.spread_deg)
    effective = max(0.0, angle - covered)
    return Deictic(math.exp(-0.5 * (effective / sigma) ** 2), angle, "along the image ray")


def pointing_score(p: Pointing, o: SceneObject) -> tuple[float, float | None]:
    """(G, angle in degrees) by the ray alone (`ray_score`)."""
    d = ray_score(p, o)
    return d.gesture, d.angle


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
    if p.ray3d is not None and in_3d(p, o):
        return space.under_fingertip(p.ray3d, o.position, o.extent)
    gap = ray_gap(p, o)
    if gap is None:
        return False
    reach = UNDER_TIP_GAP * math.hypot(o.bbox[2], o.bbox[3])
    if p.hand_box is not None:
        reach += 0.5 * math.hypot(p.hand_box[2] - p.hand_box[0], p.hand_box[3] - p.hand_box[1])
    return gap <= reach


def on_the_hand(p: Pointing, o: SceneObject) -> bool:
    """The object's centre lies on the pointing hand (a skin-coloured blob of the finger): never its target."""
    if p.hand_box is None:
        return False
    x0, y0, x1, y1 = p.hand_box
    return x0 <= o.center[0] <= x1 and y0 <= o.center[1] <= y1


def _boxes(objects: list[SceneObject]) -> tuple[np.ndarray, np.ndarray]:
    """Every object's box (n x 4) and centre (n x 2) as arrays, made once for all the steps that need them."""
    n = len(objects)  # fromiter over the flattened numbers: half the time of np.array over a list of tuples
    return (
        np.fromiter(chain.from_iterable([o.bbox for o in objects]), float, 4 * n).reshape(-1, 4),
        np.fromiter(chain.from_iterable([o.center for o in objects]), float, 2 * n).reshape(-1, 2),
    )


def _flat_mask(p: Pointing, objects: list[SceneObject], c: np.ndarray) -> np.ndarray:
    """Which objects are judged in the image plane: in the ray's camera, not on the hand (`on_the_hand`, the same
    comparisons over all centres `c` at once), not in metres."""
    mask = np.fromiter((o.cam == p.cam for o in objects), bool, len(objects))
    if p.hand_box is not None:
        x0, y0, x1, y1 = p.hand_box
        mask &= ~((x0 <= c[:, 0]) & (c[:, 0] <= x1) & (y0 <= c[:, 1]) & (c[:, 1] <= y1))
    if p.ray3d is not None:
        mask &= ~np.fromiter((in_3d(p, o) for o in objects), bool, len(objects))
    return mask


@dataclass(frozen=True)
class RayGeometry:
    """`ray_score` and `under_fingertip` of many image-plane objects at once (numpy), the same formulas as the
    one-object functions: G, the angle, and whether the ray enters the box within reach of the fingertip."""

    g: np.ndarray
    angle: np.ndarray  # degrees
    under_tip: np.ndarray

    @staticmethod
    def of(p: Pointing, objects: list[SceneObject]) -> "RayGeometry":
        return RayGeometry.of_boxes(p, *_boxes(objects))

    @staticmethod
    def of_boxes(p: Pointing, b: np.ndarray, c: np.ndarray) -> "RayGeometry":
        """The same from the boxes (n x 4) and centres (n x 2) as arrays."""
        vx, vy = c[:, 0] - p.origin[0], c[:, 1] - p.origin[1]
        dist = np.hypot(vx, vy)
        radius = 0.5 * np.hypot(b[:, 2], b[:, 3]) * 0.5
        at_origin = dist <= 1e-6
        safe = np.where(at_origin, 1.0, dist)
        cos = (vx * p.direction[0] + vy * p.direction[1]) / safe
        angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        covered = np.degrees(np.arctan2(radius, safe))
        effective = np.maximum(0.0, angle - covered)
        sigma = max(space.POINTING_NOISE_DEG, p.spread_deg)
        g = np.where(cos <= 0, 0.0, np.exp(-0.5 * (effective / sigma) ** 2))
        g = np.where(at_origin, 1.0, g)
        angle = np.where(at_origin, 0.0, angle)
        return RayGeometry(g, angle, _enters_within_reach(p, b))


def _enters_within_reach(p: Pointing, b: np.ndarray) -> np.ndarray:
    """`under_fingertip` for image-plane boxes: the ray enters the box (slab test, as `ray_gap`) within reach."""
    t_near = np.zeros(len(b))
    t_far = np.full(len(b), np.inf)
    hit = np.ones(len(b), dtype=bool)
    for axis in (0, 1):
        o, d = p.origin[axis], p.direction[axis]
        lo, hi = b[:, axis], b[:, axis] + b[:, axis + 2]
        if abs(d) < 1e-9:
            hit &= (lo <= o) & (o <= hi)
            continue
        t0, t1 = (lo - o) / d, (hi - o) / d
        t_near, t_far = np.maximum(t_near, np.minimum(t0, t1)), np.minimum(t_far, np.maximum(t0, t1))
    reach = UNDER_TIP_GAP * np.hypot(b[:, 2], b[:, 3])
    if p.hand_box is not None:
        reach = reach + 0.5 * math.hypot(p.hand_box[2] - p.hand_box[0], p.hand_box[3] - p.hand_box[1])
    return hit & (t_near <= t_far) & (t_near <= reach)


@dataclass(frozen=True)
class _RayPass:
    """`ray_score` of many objects: the image-plane ones in one numpy pass (`RayGeometry`), the others (another
    camera, on the hand, in metres) one by one; and which lie under the fingertip with G > 0 (`under_fingertip`)."""

    flat: np.ndarray  # bool: judged in the image plane
    boxes: np.ndarray  # every object's box, n x 4
    g: np.ndarray
    angle: np.ndarray  # degrees; NaN where `ray_score` says None
    under: np.ndarray  # bool
    others: dict[int, Deictic]  # the `ray_score` of each object not in the image plane, by index

    @staticmethod
    def of(p: Pointing, objects: list[SceneObject]) -> "_RayPass":
        n = len(objects)
        b, c = _boxes(objects)
        flat = _flat_mask(p, objects, c)
        g, angle, under = np.zeros(n), np.full(n, np.nan), np.zeros(n, dtype=bool)
        idx = np.flatnonzero(flat)
        if len(idx):
            geo = RayGeometry.of_boxes(p, b[idx], c[idx])
            g[idx], angle[idx], under[idx] = geo.g, geo.angle, (geo.g > 0) & geo.under_tip
        others: dict[int, Deictic] = {}
        for i in np.flatnonzero(~flat).tolist():
            d = others[i] = ray_score(p, objects[i])
            g[i] = d.gesture
            angle[i] = np.nan if d.angle is None else d.angle
            under[i] = d.angle is not None and d.gesture > 0 and under_fingertip(p, objects[i])
        return _RayPass(flat, b, g, angle, under, others)

    def at(self, i: int) -> Deictic:
        d = self.others.get(i)
        return d if d is not None else Deictic(float(self.g[i]), float(self.angle[i]), "along the image ray")


def ray_scores(p: Pointing, objects: list[SceneObject]) -> tuple[dict[tuple[str, str], Deictic], set[tuple[str, str]]]:
    """`ray_score` of every object, and the keys of those under the fingertip with G > 0 (`under_fingertip`); the
    image-plane ones (all of them, but for depth) in one numpy pass: 1000 objects in about a millisecond."""
    rays = _RayPass.of(p, objects)
    out = {o.key: rays.at(i) for i, o in enumerate(objects)}
    return out, {objects[i].key for i in np.flatnonzero(rays.under).tolist()}


def _people(objects: list[SceneObject]) -> np.ndarray:
    return np.fromiter((o.label == "person" for o in objects), bool, len(objects))


@dataclass(frozen=True)
class Deictics:
    """What pointing says about many objects (`deictic_scores`' rules): G of each as one array, for ranking, and
    each one's whole `Deictic` on demand (`at`), the same values, without building 1000 of them (issue #34)."""

    rays: _RayPass
    near: np.ndarray  # bool: touched, or (nothing touched) under the fingertip
    rule: str | None  # the near objects' rule; None: none is near, every object keeps its ray score
    gesture: np.ndarray  # G after the rule

    @staticmethod
    def of(p: Pointing, objects: list[SceneObject]) -> "Deictics":
        rays = _RayPass.of(p, objects)
        people = _people(objects)
        near = np.zeros(len(objects), dtype=bool)
        # touched (services/fusion/touch.py): the smallest box holding the fingertip wins over the box it rests on;
        # never a person (the pointing person's own box holds the fingertip) nor a blob on the hand; objects in metres
        # go by the 3-D rule (`under_fingertip`): a box around the fingertip's pixel may lie far behind it
        mine = np.flatnonzero(rays.flat & ~people)
        hit, _ = touched(fingertip(p.origin, p.direction, p.hand_box), rays.boxes[mine])
        rule: str | None = "touch"
        if hit:
            near[mine[hit]] = True
        else:
            near = rays.under & ~people
            rule = "under the fingertip" if near.any() else None
        gesture = rays.g if rule is None else np.where(near, 1.0, rays.g * FARTHER_ALONG)
        return Deictics(rays, near, rule, gesture)

    def at(self, i: int) -> Deictic:
        d = self.rays.at(i)
        if self.rule is None:
            return d
        if self.near[i]:
            return Deictic(1.0, d.angle if d.angle is not None else 0.0, self.rule, d.off_m)
        return d._replace(gesture=d.gesture * FARTHER_ALONG)


def deictic_scores(p: Pointing, objects: list[SceneObject]) -> dict[tuple[str, str], Deictic]:
    """`Deictic` per object: `ray_score`; then an object the fingertip touches gets G = 1 (even when its centre lies
    behind the tip: a finger on a laptop's keyboard), else what lies under the fingertip wins over what lies further
    along the ray. People never win by touch or by being under the fingertip: the pointing person's own box holds
    the fingertip (issue #31); another person is scored by the ray alone."""
    d = Deictics.of(p, objects)
    return {o.key: d.at(i) for i, o in enumerate(objects)}


RELATION_FLOOR = 0.05  # below this fit nobody is in that relation to the anchor: the words are not matched


ANCHOR_WEIGHTS = Weights(speech=1.0, vision=0.0, gesture=0.0)


def _anchor_fits(anchor: ObjectPhrase, scene: list[SceneObject]) -> list[tuple[SceneObject, float]]:
    """The objects the anchor's words fit (>= 0.5), with how well: scored like any phrase, by the words alone, so
    the anchor's colour and spatial words count exactly as they would for the object itself."""
    if anchor.unknown_nouns or (anchor.label is None and not anchor.color):
        return []
    # pruned by the words first: an object whose label does not fit has match 0 whatever the other words say, and
    # the colour, spatial and ordinal steps look only at the objects that fit (the same result, 1000 objects fast)
    fits = _attribute_matches(anchor, scene)
    named = [o for o in scene if fits[o.key] > 0]
    if not named:
        return []
    # `score`'s matches in `score`'s order (its totals, to the bit: `_Evidence.arrays`), without a Scored each
    ev = _evidence(anchor, named, None, ANCHOR_WEIGHTS, False, None, scene)
    totals = ev.arrays()[2].tolist()
    ranked = sorted(range(len(named)), key=lambda i: (-round(totals[i], 9), named[i].cam, named[i].id))
    return [(named[i], ev.match[named[i].key]) for i in ranked if ev.match[named[i].key] >= 0.5]


def _relation_scores(
    relation: Relation, group: list[SceneObject], scene: list[SceneObject]
) -> dict[tuple[str, str], float]:
    """Preference in [0, 1] for each object of `group` (1 for the best fit; 0 for all when no anchor is seen or
    nothing is in that relation to one). An object is never its own anchor; anchors in another camera do not count.
    Vectorised over candidates x anchors (services/fusion/relations.py): 1000 objects stay within milliseconds."""
    if not group:
        return {}
    anchor_sets = [_anchor_fits(a, scene) for a in relation.anchors]
    ids: dict[tuple[str, str], int] = {}
    cams: dict[str, int] = {}

    def index(objs: list[SceneObject]) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.array([ids.setdefault(o.key, len(ids)) for o in objs]),
            np.array([cams.setdefault(o.cam, len(cams)) for o in objs]),
        )

    cand_id, cand_cam = index(group)
    boxes = [o.bbox for o in group]
    if relation.kind == "between":
        first = sorted(anchor_sets[0], key=lambda f: -f[1])[:BETWEEN_MAX_ANCHORS]
        second = sorted(anchor_sets[1], key=lambda f: -f[1])[:BETWEEN_MAX_ANCHORS] if len(anchor_sets) > 1 else first
        if not first or not second:
            return {o.key: 0.0 for o in group}
        a_id, a_cam = index([a for a, _ in first])
        b_id, b_cam = index([b for b, _ in second])
        m = between_matrix(boxes, [a.bbox for a, _ in first], [b.bbox for b, _ in second])
        m = m * np.array([w for _, w in first])[None, :, None] * np.array([w for _, w in second])[None, None, :]
        ok = (
            (cand_id[:, None, None] != a_id[None, :, None])
            & (cand_id[:, None, None] != b_id[None, None, :])
            & (a_id[None, :, None] != b_id[None, None, :])
            & (cand_cam[:, None, None] == a_cam[None, :, None])
            & (cand_cam[:, None, None] == b_cam[None, None, :])
        )
        raw = np.where(ok, m, 0.0).reshape(len(group), -1).max(axis=1)
    else:
        best: dict[tuple[str, str], tuple[SceneObject, float]] = {}
        for anchors in anchor_sets:
            for a, w in anchors:
                if a.key not in best or best[a.key][1] < w:
                    best[a.key] = (a, w)
        if not best:
            return {o.key: 0.0 for o in group}
        chosen = list(best.values())
        a_id, a_cam = index([a for a, _ in chosen])
        m = fit_matrix(relation.kind, boxes, [a.bbox for a, _ in chosen]) * np.array([w for _, w in chosen])[None]
        ok = (cand_id[:, None] != a_id[None, :]) & (cand_cam[:, None] == a_cam[None, :])
        raw = np.where(ok, m, 0.0).max(axis=1)
    top = float(raw.max())
    if top < RELATION_FLOOR:
        return {o.key: 0.0 for o in group}
    return {o.key: float(v) / top for o, v in zip(group, raw)}


ORDINAL_OTHERS = 0.2  # preference of the objects that are not in the said place of the order


def _ordinal_scores(ordinal: int, counted_from: str | None, group: list[SceneObject]) -> dict[tuple[str, str], float]:
    """ "The second bottle from the left": 1 for the object in that place of the order, ORDINAL_OTHERS for the rest
    (all 0 when there are fewer objects than the ordinal)."""
    key = {
        "left": lambda o: o.center[0],
        "right": lambda o: -o.center[0],
        "top": lambda o: o.center[1],
        "bottom": lambda o: -o.center[1],
        "nearest": lambda o: -(o.bbox[1] + o.bbox[3]),
        "farthest": lambda o: o.bbox[1] + o.bbox[3],
    }[counted_from or "left"]
    order = sorted(group, key=lambda o: (o.cam, key(o), o.id))
    index = ordinal - 1 if ordinal > 0 else len(order) + ordinal
    if not 0 <= index < len(order):
        return {o.key: 0.0 for o in group}
    return {o.key: 1.0 if i == index else ORDINAL_OTHERS for i, o in enumerate(order)}


def _relations_and_order(
    phrase: ObjectPhrase, objects: list[SceneObject], match: dict[tuple[str, str], float], scene: list[SceneObject]
) -> None:
    """Relations ("next to the bowl"), then the ordinal ("the second … from the left"), each choosing among the
    objects the other words fit (match >= 0.5); `match` is updated in place."""
    for relation in phrase.relations:
        prefs = _relation_scores(relation, [o for o in objects if match[o.key] >= 0.5], scene)
        for o in objects:
            match[o.key] *= prefs.get(o.key, 0.0)
    if phrase.ordinal:
        fitting = [o for o in objects if match[o.key] >= 0.5] or list(objects)
        prefs = _ordinal_scores(phrase.ordinal, phrase.ordinal_from, fitting)
        for o in objects:
            match[o.key] *= prefs.get(o.key, 0.0)


@dataclass(frozen=True)
class _Evidence:
    """Everything `score` weighs, per object: `scored(i)` is one object's `Scored` (the formulas), `arrays` the same
    speech and total of all objects at once (numpy), for choosing which objects to build (`shortlist`)."""

    objects: list[SceneObject]
    match: dict[tuple[str, str], float]
    deictic: Deictics | None  # None: pointing not used
    ws: float
    wg: float
    adaptive: bool
    ref: float | None

    def scored(self, i: int) -> Scored:
        o = self.objects[i]
        m = self.match[o.key]
        if self.adaptive:
            recency = math.exp(-abs(o.stamp - self.ref) / RECENCY_S) if self.ref is not None else 1.0
            trust = o.score * o.quality * recency
        else:
            trust = 1.0
        s = 0.5 + (m - 0.5) * trust
        d = self.deictic.at(i) if self.deictic is not None else Deictic(0.0, None)
        g = d.gesture if self.deictic is not None else None
        total = (self.ws * s + self.wg * (g or 0.0)) / (self.ws + self.wg)
        return Scored(o, m, trust, s, g, d.angle, total, d.rule, d.off_m)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(match, speech, total) of every object by `scored`'s formulas over arrays, the same numbers to the bit:
        the same float operations in the same order, and the recency's `math.exp` once per stamp (one per sample)."""
        n = len(self.objects)
        m = np.fromiter((self.match[o.key] for o in self.objects), float, n)
        trust = np.ones(n)
        if self.adaptive:
            trust = np.fromiter((o.score * o.quality for o in self.objects), float, n)
            if self.ref is not None:
                ref = self.ref
                recency = {t: math.exp(-abs(t - ref) / RECENCY_S) for t in {o.stamp for o in self.objects}}
                trust = trust * np.fromiter((recency[o.stamp] for o in self.objects), float, n)
        s = 0.5 + (m - 0.5) * trust
        g = self.deictic.gesture if self.deictic is not None else np.zeros(n)
        return m, s, (self.ws * s + self.wg * g) / (self.ws + self.wg)


def _evidence(
    phrase: ObjectPhrase,
    objects: list[SceneObject],
    pointing: Pointing | None,
    weights: Weights,
    adaptive: bool,
    ref: float | None,
    scene: list[SceneObject] | None,
) -> _Evidence:
    match = _attribute_matches(phrase, objects)
    if phrase.color:  # by similarity, relative to the objects the other words fit (services/fusion/color.py)
        factors = colour_factors(phrase.color, [o for o in objects if match[o.key] > 0])
        match = {k: m * factors.get(k, 0.0) for k, m in match.items()}
    fitting = [o for o in objects if match[o.key] >= 0.5] or list(objects)
    for word in phrase.spatial:  # spatial words choose among the objects that fit the other words
        prefs = _spatial_scores(word, fitting)
        for o in objects:
            match[o.key] *= prefs.get(o.key, 1.0)
    _relations_and_order(phrase, objects, match, scene if scene is not None else objects)
    use_gesture = pointing is not None and weights.gesture > 0
    ws, wg = weights.speech, (weights.gesture if use_gesture else 0.0)
    if ws + wg <= 0:
        ws = 1.0
    deictic = Deictics.of(pointing, objects) if pointing is not None and use_gesture else None
    return _Evidence(objects, match, deictic, ws, wg, adaptive, ref)


def _ranked(scored: list[Scored]) -> list[Scored]:
    scored.sort(key=lambda c: (-round(c.total, 9), c.obj.cam, c.obj.id))
    return scored


def score(
    phrase: ObjectPhrase,
    objects: list[SceneObject],
    pointing: Pointing | None,
    weights: Weights,
    *,
    adaptive: bool = True,
    ref: float | None = None,
    scene: list[SceneObject] | None = None,
) -> list[Scored]:
    """All objects scored and ranked (best first; ties broken by camera and id for determinism). `scene`: every
    object in view, where a relation's anchors are looked for (default: `objects`; the dialogue scores only the
    candidates of its question, but "the one next to the laptop" may name a laptop that is not one of them)."""
    if not objects:
        return []
    ev = _evidence(phrase, objects, pointing, weights, adaptive, ref, scene)
    return _ranked([ev.scored(i) for i in range(len(objects))])


RANK_SLACK = 1e-6  # covers the ranking's rounding of totals to 1e-9: a total this far below another may rank first


def _first_ranked(best: np.ndarray, total: np.ndarray) -> np.ndarray:
    """Of the objects `best` marks, those that may be ranked first among them (the ranking rounds totals)."""
    return best & (total >= total[best].max() - RANK_SLACK)


def _shortlisted(ev: _Evidence) -> list[int]:
    """The indices of what `choose` reads (see `shortlist`), from `_Evidence.arrays`: the first MAX_CANDIDATES + 1 of
    the ranking (all whose total may rank among them: more where totals tie), the first ranked of the best by the
    words and by the ray, one object with the best match."""
    n = len(ev.objects)
    top = MAX_CANDIDATES + 1  # `choose` reads the winner, the runner-up and at most MAX_CANDIDATES close ones
    if n <= 4 * top:
        return list(range(n))
    m, s, total = ev.arrays()
    keep = total >= np.partition(total, n - top)[n - top] - RANK_SLACK
    keep |= _first_ranked(s == s.max(), total)  # speech_best
    if ev.deictic is not None:
        g = ev.deictic.gesture
        keep |= _first_ranked(g == g.max(), total)  # gesture_best
    keep[int(np.argmax(m))] = True  # `choose` reads the best match
    return np.flatnonzero(keep).tolist()


def shortlist(
    phrase: ObjectPhrase,
    objects: list[SceneObject],
    pointing: Pointing | None,
    weights: Weights,
    *,
    adaptive: bool = True,
    ref: float | None = None,
    scene: list[SceneObject] | None = None,
) -> list[Scored]:
    """What `choose` reads of `score`'s ranking, in its order: the first MAX_CANDIDATES + 1, the best by the words
    (speech, and a best match) and by the ray. `choose` decides the same on it as on the whole ranking (it never
    reads more), and only those objects are built: a thousand objects in view, a handful of `Scored` (issue #34)."""
    if not objects:
        return []
    ev = _evidence(phrase, objects, pointing, weights, adaptive, ref, scene)
    return _ranked([ev.scored(i) for i in _shortlisted(ev)])


PART_OF = 0.9  # a box this much inside a bigger box of the same label is the detector boxing part of that object


def _inside(small: tuple[float, float, float, float], big: tuple[float, float, float, float]) -> float:
    ix = max(0.0, min(small[0] + small[2], big[0] + big[2]) - max(small[0], big[0]))
    iy = max(0.0, min(small[1] + small[3], big[1] + big[3]) - max(small[1], big[1]))
    return ix * iy / max(small[2] * small[3], 1e-6)


def _whole_objects(candidates: list[Scored]) -> list[Scored]:
    """The candidates without those that are part of another candidate of the same label (a chair's upper half
    boxed again beside the whole chair, IoU under the detector's NMS threshold): asking "this chair or this
    chair's top?" helps nobody. Stacked objects of one kind fall under the rule too: the stack is taken whole."""
    out = []
    for c in candidates:
        o = c.obj
        if not any(
            d is not c
            and d.obj.label == o.label
            and d.obj.cam == o.cam
            and d.obj.bbox[2] * d.obj.bbox[3] > o.bbox[2] * o.bbox[3]
            and _inside(o.bbox, d.obj.bbox) >= PART_OF
            for d in candidates
        ):
            out.append(c)
    return out


# What grounding decided: a target, or the reason of the question to ask (the Clarification's `reason`)
ChoiceKind = Literal["target"] | ClarificationReason


@dataclass(frozen=True)
class Choice:
    kind: ChoiceKind
    winner: Scored | None
    candidates: tuple[Scored, ...]
    speech_best: Scored | None = None
    gesture_best: Scored | None = None
    overruled: Literal["speech", "gesture"] | None = None  # the side that lost a disagreement (the other won)
    runner_up: Scored | None = None


def choose(
    phrase: ObjectPhrase, scored: list[Scored], *, margin: float = DEFAULT_MARGIN, check_evidence: bool = True
) -> Choice:
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
    disagree = (
        speech_best is not None
        and gesture_best is not None
        and pointed
        and speech_best is not gesture_best
        and speech_best.match >= 0.5
    )
    # Without pointing, two objects the words fit equally well ("the fruit": an apple and an orange) are a
    # question, whatever their detection scores: a more confident detector is not what the person meant.
    tie_in_words = (
        runner_up is not None and not pointing and winner.match >= 0.5 and abs(winner.match - runner_up.match) < 1e-6
    )
    if runner_up is not None and (winner.total - runner_up.total < margin or tie_in_words):
        if (
            disagree
            and speech_best is not None  # (disagree says so; said for the type checker)
            and gesture_best is not None
            and {id(winner), id(runner_up)} == {id(speech_best), id(gesture_best)}
        ):
            return Choice("conflict", None, (speech_best, gesture_best), speech_best, gesture_best, runner_up=runner_up)
        close: list[Scored] = []
        for c in scored:  # ranked: stop at the first that is clearly behind
            if (winner.total - c.total >= margin and not (tie_in_words and abs(c.match - winner.match) < 1e-6)) or len(
                close
            ) == MAX_CANDIDATES:
                break
            close.append(c)
        whole = _whole_objects(close)
        if len(whole) == 1:  # one object boxed twice by the detector: it is the whole one
            if check_evidence and whole[0].evidence < MIN_EVIDENCE:
                return Choice("low_confidence", whole[0], (whole[0],), speech_best, gesture_best, runner_up=runner_up)
            return Choice("target", whole[0], (whole[0],), speech_best, gesture_best, None, runner_up)
        return Choice("ambiguous", None, tuple(whole), speech_best, gesture_best, runner_up=runner_up)
    if check_evidence and winner.evidence < MIN_EVIDENCE:
        return Choice("low_confidence", winner, (winner,), speech_best, gesture_best, runner_up=runner_up)
    overruled: Literal["speech", "gesture"] | None = None
    if disagree:
        overruled = SPEECH if winner is gesture_best else GESTURE
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
    ranked = shortlist(ObjectPhrase(), objects, p, GESTURE_ONLY)
    return ranked[0] if ranked else None


def pointed_location(p: Pointing, objects: list[SceneObject]) -> Location:
    """Where "there" is: the centre of the object on the ray (G >= `ON_RAY`), else `ray_point`; in metres when the
    ray met a surface (`space.there`)."""
    mine = [o for o in objects if o.cam == p.cam]
    if p.ray3d is not None and p.ray3d.hit is not None:
        return space.there(p.ray3d, mine, p.cam, ray_point(p), ON_RAY, p.spread_deg)
    best = best_pointed(p, mine)
    on_ray = best.obj if best is not None and (best.gesture or 0.0) >= ON_RAY else None
    if on_ray is not None:
        x, y = on_ray.center
    else:
        x, y = ray_point(p)
    return Location(x=float(x), y=float(y), cam=p.cam)
