"""Grounding in metres, when the camera has depth: pointing rays (`Ray.ray3d`) against object positions
(`DetectedObject.position`), "the nearest / farthest" by distance from the camera, and "there" as the point where the
ray meets the floor or table (`Ray3D.hit`, fitted by the gesture service). Pure; ground.py calls in here only when
both sides of a comparison have 3-D data, so without depth everything stays as it was, in pixels.

Frame: the camera's optical frame (x right, y down, z forward, metres), named by `frame_id` on both the ray and the
objects (a ray and an object in different frames are compared in 2-D).
"""

from __future__ import annotations

import collections
import math
import re
from dataclasses import dataclass
from typing import Sequence

from common.schema import Location, Ray3D

# The angular noise of a pointing ray as fusion gets it, in 2-D and 3-D alike: THE one definition (ground.py reads it).
# People aim to within about 3 deg (Bangerter & Oppenheimer 2006, "Accuracy in detecting referents of pointing
# gestures unaccompanied by language", Gesture 6(1)); the rest is the ray's estimate from landmarks (and depth),
# whose error on real photos is larger still (docs/gesture.md). 8 deg is a standard deviation, not a cut-off.
POINTING_NOISE_DEG = 8.0
DEFAULT_RADIUS = 0.03  # m: an object's core radius when its extent is unknown
DEPTH_SCALE = 0.05  # m: how much nearer an object must be for "the nearest" to prefer it clearly (about e^-1)
# Distance from the ray's origin to the pointing fingertip (m), per method: an object within TOUCH of the ray's
# line near there is under the fingertip (touched or almost).
FINGERTIP_REACH = {
    "eye_fingertip": 0.75,
    "world_landmarks": 0.75,
    "shoulder_wrist": 0.75,
    "forearm": 0.45,
    "index_finger": 0.1,
}
TOUCH = 0.1  # m beyond the object's radius, along and across the ray
# Near the hand the tolerance does not shrink below this (m): where the fingertip and the eye are measured is itself
# uncertain by centimetres, as for touch.
NEAR_TOLERANCE_M = TOUCH


@dataclass(frozen=True)
class Ray3:
    """A 3-D pointing ray as fusion uses it (the average of a pointing gesture's observations)."""

    origin: tuple[float, float, float]
    direction: tuple[float, float, float]
    method: str
    frame_id: str
    hit: tuple[float, float, float] | None = None


def vec2(v: Sequence[float]) -> tuple[float, float]:
    """A wire Point (its length fixed by the schema) as a tuple."""
    return (v[0], v[1])


def vec3(v: Sequence[float]) -> tuple[float, float, float]:
    """A wire Point3 (or any 3 numbers) as a tuple."""
    return (v[0], v[1], v[2])


def box4(v: Sequence[float]) -> tuple[float, float, float, float]:
    """A wire Box as a tuple."""
    return (v[0], v[1], v[2], v[3])


def from_wire(ray: Ray3D | None) -> Ray3 | None:
    if ray is None:
        return None
    return Ray3(
        vec3(ray.origin),
        vec3(ray.direction),
        ray.method,
        ray.frame_id,
        vec3(ray.hit) if ray.hit is not None else None,
    )


def _sub(a, b) -> tuple[float, float, float]:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(a) -> float:
    return math.sqrt(_dot(a, a))


def mean_ray(observed: list[tuple[Ray3 | None, float]]) -> Ray3 | None:
    """The weighted average of one gesture's 3-D rays (origins, directions and hits; the most frequent method)."""
    rays = [(r, max(w, 1e-6)) for r, w in observed if r is not None]
    if not rays:
        return None
    frame = rays[-1][0].frame_id
    rays = [(r, w) for r, w in rays if r.frame_id == frame]
    total = sum(w for _, w in rays)
    origin = vec3([sum(r.origin[i] * w for r, w in rays) / total for i in range(3)])
    d = vec3([sum(r.direction[i] * w for r, w in rays) for i in range(3)])
    n = _norm(d)
    if n < 1e-9:
        return None
    hits = [(r.hit, w) for r, w in rays if r.hit is not None]
    hit = None
    if hits and len(hits) * 2 >= len(rays):  # most observations saw a surface there
        hw = sum(w for _, w in hits)
        hit = vec3([sum(h[i] * w for h, w in hits) / hw for i in range(3)])
    methods = sorted({r.method for r, _ in rays}, key=lambda m: (-sum(w for r, w in rays if r.method == m), m))
    return Ray3(origin, vec3([c / n for c in d]), methods[0], frame, hit)


def same_frame(ray: Ray3, frame_id: str | None) -> bool:
    return frame_id is None or frame_id == ray.frame_id


def radius(extent) -> float:
    """The object's core: half of half its diagonal across the ray (as in 2-D), from [width, height, depth] m."""
    if extent is None:
        return DEFAULT_RADIUS
    return max(0.25 * math.hypot(extent[0], extent[1]), 0.01)


def tolerance(along: float, sigma_deg: float = POINTING_NOISE_DEG) -> float:
    """How far (m) from the ray's line an object `along` m away may lie and still be "pointed at" by one standard
    deviation: max(r0, d tan(N)), N = the pointing noise (at least POINTING_NOISE_DEG), r0 = NEAR_TOLERANCE_M.
    Pointing is coarse far away: 1 m off the ray at 7 m is as good as 0.14 m off at 1 m."""
    return max(NEAR_TOLERANCE_M, along * math.tan(math.radians(max(sigma_deg, POINTING_NOISE_DEG))))


def pointing_score(ray: Ray3, position, extent, sigma_deg: float = POINTING_NOISE_DEG) -> tuple[float, float, float]:
    """(G, angle in degrees, distance from the ray in m) of an object at `position` (m): its 3-D distance from the
    ray's line, less its core radius, against the `tolerance` at its distance along the ray:
    G = exp(-1/2 (off / tolerance)^2); 0 behind the origin."""
    along, across = along_across(ray, position)
    dist = _norm(_sub(position, ray.origin))
    if dist < 1e-6:
        return 1.0, 0.0, 0.0
    angle = math.degrees(math.acos(max(-1.0, min(1.0, along / dist))))
    if along <= 0:
        return 0.0, angle, across
    off = max(0.0, across - radius(extent))
    return math.exp(-0.5 * (off / tolerance(along, sigma_deg)) ** 2), angle, across


def along_across(ray: Ray3, point) -> tuple[float, float]:
    """(distance along the ray from its origin, distance from the ray's line) of a point, metres."""
    v = _sub(point, ray.origin)
    t = _dot(v, ray.direction)
    return t, _norm(_sub(v, tuple(t * c for c in ray.direction)))


def under_fingertip(ray: Ray3, position, extent) -> bool:
    """Does the finger (nearly) touch the object? Its centre within its radius + `TOUCH` of the ray's line, and no
    farther along the ray than the fingertip plus that."""
    t, off = along_across(ray, position)
    reach = radius(extent) * 2 + TOUCH
    return t > 0 and off <= reach and t <= FINGERTIP_REACH.get(ray.method, 0.75) + reach


def distance_preferences(word: str, positions: dict) -> dict:
    """ "nearest" / "farthest" by distance from the camera (m): 1 for the best, e^(-gap / DEPTH_SCALE) for others."""
    dist = {k: _norm(p) for k, p in positions.items()}
    if word == "nearest":
        best = min(dist.values())
        return {k: math.exp(-(d - best) / DEPTH_SCALE) for k, d in dist.items()}
    best = max(dist.values())
    return {k: math.exp(-(best - d) / DEPTH_SCALE) for k, d in dist.items()}


def before_hit(ray: Ray3, position, extent) -> bool:
    """Does the ray reach the object before the surface it meets (or meet no surface)? A bottle far behind the spot
    on the floor someone points at is not "there"."""
    if ray.hit is None:
        return True
    t_obj, _ = along_across(ray, position)
    t_hit, _ = along_across(ray, ray.hit)
    return t_obj <= t_hit + 2 * radius(extent)


def fit_projection(objects) -> tuple[float, float, float] | None:
    """(f, cx, cy) of the pinhole that shows the objects' 3-D positions at their pixel centres, or None without an
    object off the image's middle. Fusion does not receive the intrinsics (they travel with frames), so they are read
    back from vision's objects: the principal point is taken at the image centre (within a few % on real cameras)
    and f is the median of each object's own estimate (f = (u - cx) z / x, and the same in y, from the objects at
    least 5 % of the focal length off the axis), so that one odd object (a table whose median point is not its box
    centre) does not move it."""
    estimates = []
    cx = cy = 0.0
    for o in objects:
        cx, cy = o.width / 2.0, o.height / 2.0
        x, y, z = o.position
        for offset, pixel, centre in ((x / z, o.center[0], cx), (y / z, o.center[1], cy)):
            if abs(offset) >= 0.05:
                f = (pixel - centre) / offset
                if f > 0:
                    estimates.append(f)
    if not estimates:
        return None
    estimates.sort()
    mid = len(estimates) // 2
    f = estimates[mid] if len(estimates) % 2 else (estimates[mid - 1] + estimates[mid]) / 2
    return f, cx, cy


def project(point, projection: tuple[float, float, float]) -> tuple[float, float] | None:
    f, cx, cy = projection
    if point[2] <= 1e-6:
        return None
    return f * point[0] / point[2] + cx, f * point[1] / point[2] + cy


def hit_location(ray: Ray3, objects, cam: str, fallback_px: tuple[float, float]) -> Location:
    """ "There" in metres: where the ray meets the floor or table (`ray.hit`). Its pixel is the hit projected with the
    pinhole fitted to the objects in view (`fit_projection`), else `fallback_px` (the 2-D ray's point)."""
    if ray.hit is None:
        raise ValueError("hit_location needs a ray that met a surface (ray.hit)")
    projection = fit_projection([o for o in objects if o.position is not None and same_frame(ray, o.frame_id)])
    px = project(ray.hit, projection) if projection is not None else None
    x, y = px if px is not None else fallback_px
    return Location(
        x=round(float(x), 1),
        y=round(float(y), 1),
        cam=cam,
        position=[round(c, 4) for c in ray.hit],
        frame_id=ray.frame_id,
    )


def metres_words(position, frame_id: str | None, extent=None) -> str:
    """ ", at (x, y, z) m in <frame>" for a planner prompt; "" without a position."""
    if position is None:
        return ""
    where = f", at ({position[0]:.2f}, {position[1]:.2f}, {position[2]:.2f}) m in {frame_id or 'the camera frame'}"
    if extent is not None:
        where += f", {extent[0]:.2f}x{extent[1]:.2f}x{extent[2]:.2f} m"
    return where + " (x right, y down, z forward)"


def ray_words(ray: Ray3 | None) -> str:
    """ "; 3-D ray (method) from (x, y, z) m along (dx, dy, dz)[, meeting a surface at (…) m]" for a planner prompt."""
    if ray is None:
        return ""
    o, d = ray.origin, ray.direction
    words = (
        f"; 3-D ray ({ray.method}) from ({o[0]:.2f}, {o[1]:.2f}, {o[2]:.2f}) m along "
        f"({d[0]:.2f}, {d[1]:.2f}, {d[2]:.2f}) in {ray.frame_id}"
    )
    if ray.hit is not None:
        words += f", meeting a surface at ({ray.hit[0]:.2f}, {ray.hit[1]:.2f}, {ray.hit[2]:.2f}) m"
    return words


# ---------------------------------------------------------------------------
# "On my left": the speaker's side
# ---------------------------------------------------------------------------
_MINE = re.compile(r"\b(?:my|mine)\s+(left|right)\b|\b(left|right)\s+of\s+me\b", re.IGNORECASE)
LEFT_SHOULDER, RIGHT_SHOULDER = 11, 12
MIN_VISIBILITY = 0.5
PROFILE = 0.25  # shoulders closer than this x their length to the hips (in x): seen side-on, facing unknown
FACING_MAX_AGE = 3.0  # s between the body seen and the words


def said_from_speaker(text: str) -> set[str]:
    """The side words the speaker said from their own side: "on my left", "to my right", "left of me"."""
    return {(m.group(1) or m.group(2)).lower() for m in _MINE.finditer(text or "")}


def facing_camera(landmarks, visibility) -> bool | None:
    """Does the person face the camera? Their own left shoulder is on the image's right when they do (the camera
    is not mirrored: Body landmarks are the person's own sides). None when the shoulders are unseen or side-on."""
    if min(visibility[LEFT_SHOULDER], visibility[RIGHT_SHOULDER]) < MIN_VISIBILITY:
        return None
    (lx, ly), (rx, ry) = landmarks[LEFT_SHOULDER], landmarks[RIGHT_SHOULDER]
    width = abs(lx - rx)
    scale = max(abs(landmarks[23][1] - ly), abs(landmarks[24][1] - ry), width, 1e-6)
    if width < PROFILE * scale:
        return None
    return lx > rx


class Facing:
    """The latest few body orientations per camera, to turn "my left" into the camera's side."""

    def __init__(self, keep: int = 64):
        self.seen: collections.deque[tuple[float, str, bool]] = collections.deque(maxlen=keep)

    def add(self, bodies) -> None:
        for body in bodies.bodies[:1]:  # MediaPipe Pose finds one person: the speaker, when anyone
            facing = facing_camera(body.landmarks, body.visibility)
            if facing is not None:
                self.seen.append((bodies.stamp, bodies.cam, facing))

    def at(self, ref: float) -> bool | None:
        near = [(abs(s - ref), f) for s, _, f in self.seen if abs(s - ref) <= FACING_MAX_AGE]
        return min(near)[1] if near else None

    def camera_words(self, spatial: tuple[str, ...], text: str, ref: float) -> tuple[tuple[str, ...], str | None]:
        """`spatial` with the speaker's "left"/"right" turned into the camera's (and why), else unchanged.
        "On your left" and a plain "left" are the robot's (= the camera's) already. A person who is not seen is
        taken to face the robot, the usual way to speak to one."""
        mine = said_from_speaker(text) & set(spatial)
        if not mine:
            return spatial, None
        facing = self.at(ref)
        if facing is False:
            return spatial, "the speaker's back is to the camera: their left is the camera's left"
        swap = {"left": "right", "right": "left"}
        words = tuple(swap[w] if w in mine else w for w in spatial)
        why = (
            "the speaker faces the camera" if facing else "the speaker, not seen, is taken to face the robot"
        ) + f": their {'/'.join(sorted(mine))} is the camera's {'/'.join(sorted(swap[w] for w in mine))}"
        return words, why


def holds(position, extent, point, margin: float = 0.05) -> bool:
    """Is `point` inside the object's box (position ± extent / 2, plus `margin`)? A table holds the spot on it."""
    if extent is None:
        return False
    return all(abs(point[i] - position[i]) <= extent[i] / 2 + margin for i in range(3))


def there(
    ray: Ray3,
    objects,
    cam: str,
    fallback_px: tuple[float, float],
    on_ray: float = 0.7,
    sigma_deg: float = POINTING_NOISE_DEG,
) -> Location:
    """ "There" when the ray met a surface: the object the ray points at (G >= `on_ray`, in metres) if the ray
    reaches it before the surface and the surface's spot is not on that object (a table holds the spot: the spot
    is meant), else the spot itself (`hit_location`). Objects without a position cannot say they are before it."""
    best, best_g = None, on_ray
    for o in objects:
        if o.position is None or not same_frame(ray, o.frame_id):
            continue
        g, _, _ = pointing_score(ray, o.position, o.extent, sigma_deg)
        if g >= best_g and before_hit(ray, o.position, o.extent) and not holds(o.position, o.extent, ray.hit):
            best, best_g = o, g
    if best is not None:
        return Location(
            x=float(best.center[0]),
            y=float(best.center[1]),
            cam=cam,
            position=list(best.position),
            frame_id=best.frame_id or ray.frame_id,
        )
    return hit_location(ray, objects, cam, fallback_px)
