"""Pointing in metres: 2-D landmarks lifted with an aligned depth image into a 3-D ray, and where that ray meets
the surface it points at (a plane fitted to the depth). Pure numpy; the process shell feeds it DepthFrames.

Frame: the camera's optical frame (x right, y down, z forward, metres); the depth is aligned to the colour image,
so the colour intrinsics K back-project a landmark pixel (u, v) at depth z to ((u-cx) z/fx, (v-cy) z/fy, z).

A landmark's depth is the **median of the valid depth in a small window** around it (zeros and NaN ignored).
The 3-D ray, best method first (`Ray3D.method`; docs/gesture.md):
- `eye_fingertip`: from the midpoint of the eyes through the index fingertip (the "virtual touch line");
- `forearm`: elbow -> wrist, when the eyes or the fingertip have no depth;
- `shoulder_wrist`: shoulder -> wrist, when the elbow has none either;
- `world_landmarks`: MediaPipe's metric skeleton (metres, hip-centred, axes along the camera's) placed at the
  depth of the torso, when the fingertip's depth is missing (eyes -> index, else shoulder -> wrist);
- `index_finger`: the hand alone (no body stage): index knuckle -> fingertip.
A lifted segment must have an arm's length (`SEGMENTS`): a fingertip whose window sees the wall behind it gives a
segment metres long, and the next method is tried instead.

`lift_pose` lifts the whole skeleton (NaN where there is no depth) for the arm rules of body.py, which judge an arm
in 3-D when it has depth. `surface_meeting` gives the ray's meeting point with the floor or table even when it lies
outside the image (`Meeting.in_view` false): the up-facing plane seen in the image, extended.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from common.depth import depth_metres
from common.schema import DepthFrame, Ray3D, Ray3DMethod

WINDOW = 7  # px, side of the window whose median depth lifts a landmark
MIN_VALID = 3  # valid depth pixels needed in that window
# Pose landmarks (MediaPipe Pose order), per person's side: shoulder, elbow, wrist, index, hip
POSE = {"left": (11, 13, 15, 19, 23), "right": (12, 14, 16, 20, 24)}
EYES = (2, 5)
TORSO = (11, 12, 23, 24)
MIN_VISIBILITY = 0.5
HAND_INDEX_MCP, HAND_INDEX_DIP, HAND_INDEX_TIP = 5, 7, 8
# Plausible 3-D lengths (m) of each method's segment: adult arms with a wide margin (depth noise, children).
SEGMENTS = {
    "eye_fingertip": (0.15, 1.2),
    "forearm": (0.1, 0.6),
    "shoulder_wrist": (0.2, 0.95),
    "index_finger": (0.02, 0.2),
    "world_landmarks": (0.15, 1.2),
}

# Plane fit (RANSAC) near the ray
CLOUD_POINTS = 20000  # about this many back-projected depth samples per frame (every 4th px of 640x480)
CONE_DEG = 12.0  # points within this angle of the ray (plus CONE_BASE) are candidates for its surface
CONE_BASE = 0.1  # m
RANSAC_ITERATIONS = 150
RANSAC_SUBSET = 1000  # points each hypothesis is counted on (the winner's inliers are then taken among all)
MIN_PLANE_POINTS = 150
MAX_PLANES = 3  # the first supported plane along the ray among the largest few (a box top before the table)
SUPPORT_RADIUS = 0.06  # m: a hit needs plane points this close to it (the plane is seen there)
MIN_SUPPORT = 5
# Out of view: a floor or table top faces up: its normal within this of "up", which is the seen person's torso axis
# (hips -> shoulders, lifted) or else the camera's -y (an upright camera pitched less than ~60 deg); a wall's normal
# is ~90 deg from up.
UP_FACING_DEG = 60.0
CAMERA_UP = np.array([0.0, -1.0, 0.0])


def inlier_tolerance(z: np.ndarray) -> np.ndarray:
    """Distance (m) from a plane that still counts as on it: structured-light / stereo noise grows with z²."""
    return 0.01 + 0.004 * z * z


@dataclass(frozen=True)
class DepthView:
    """An aligned depth image in metres (0 = no measurement) with the intrinsics that belong to it."""

    metres: np.ndarray  # H x W float32
    fx: float
    fy: float
    cx: float
    cy: float
    frame_id: str

    @property
    def width(self) -> int:
        return int(self.metres.shape[1])

    @property
    def height(self) -> int:
        return int(self.metres.shape[0])

    def depth_at(self, x: float, y: float, window: int = WINDOW) -> float | None:
        """Median valid depth (m) of the `window` x `window` pixels around (x, y); None when too few are valid."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        col, row, half = int(round(x)), int(round(y)), window // 2
        if not (0 <= col < self.width and 0 <= row < self.height):
            return None
        patch = self.metres[max(0, row - half) : row + half + 1, max(0, col - half) : col + half + 1]
        valid = patch[patch > 0]
        return float(np.median(valid)) if valid.size >= MIN_VALID else None

    def back_project(self, x: float, y: float, z: float) -> np.ndarray:
        return np.array([(x - self.cx) * z / self.fx, (y - self.cy) * z / self.fy, z])

    def lift(self, x: float, y: float, depth_from: tuple[float, float] | None = None) -> np.ndarray | None:
        """The 3-D point of pixel (x, y), its depth read at `depth_from` (default: the pixel itself)."""
        z = self.depth_at(*(depth_from or (x, y)))
        return None if z is None else self.back_project(x, y, z)

    def project(self, p: np.ndarray | list) -> tuple[float, float]:
        return (float(p[0] * self.fx / p[2] + self.cx), float(p[1] * self.fy / p[2] + self.cy))

    def cloud(self, step: int | None = None) -> np.ndarray:
        """N x 3 points of every `step`-th valid pixel (default: about `CLOUD_POINTS` points whatever the size)."""
        step = step or max(1, int(round(math.sqrt(self.width * self.height / CLOUD_POINTS))))
        sub = self.metres[::step, ::step]
        rows, cols = np.nonzero(sub > 0)
        z = sub[rows, cols].astype(float)
        u, v = cols * step, rows * step
        return np.column_stack([(u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z])


def depth_view(msg: DepthFrame) -> DepthView:
    """A validated DepthFrame as metres, 0 = no measurement (common/depth.py decodes; raises UndecodableDepth)."""
    metres = np.nan_to_num(depth_metres(msg), nan=0.0, posinf=0.0, neginf=0.0)
    k = msg.camera_info
    return DepthView(metres, k.fx, k.fy, k.cx, k.cy, k.frame_id)


@dataclass(frozen=True)
class Lifted:
    """A 3-D pointing ray before it goes on the wire."""

    origin: np.ndarray
    direction: np.ndarray  # unit
    method: Ray3DMethod
    reach: float  # m from the origin to the pointing hand (fingertip or wrist): the surface is searched beyond it


def _segment(a: np.ndarray | None, b: np.ndarray | None, method: Ray3DMethod) -> Lifted | None:
    if a is None or b is None:
        return None
    v = b - a
    length = float(np.linalg.norm(v))
    lo, hi = SEGMENTS[method]
    if not lo <= length <= hi:
        return None  # one end's window saw something else (the wall behind a fingertip)
    return Lifted(a, v / length, method, length)


def _visible(pose: np.ndarray, *idx: int) -> bool:
    return bool((pose[list(idx), 2] >= MIN_VISIBILITY).all())


def _tip_pixels(pose: np.ndarray, side: str, hand: np.ndarray | None) -> tuple[tuple, tuple] | None:
    """(fingertip pixel, pixel where its depth is read): the hand's index tip, its depth read halfway back to the
    last joint (a window on the very tip is half background); else the pose's index point."""
    if hand is not None:
        tip = tuple(hand[HAND_INDEX_TIP, :2])
        return tip, tuple((hand[HAND_INDEX_TIP, :2] + hand[HAND_INDEX_DIP, :2]) / 2)
    index = POSE[side][3]
    if pose[index, 2] < MIN_VISIBILITY:
        return None
    return tuple(pose[index, :2]), tuple(pose[index, :2])


def arm_ray3d(
    view: DepthView, pose: np.ndarray, side: str, hand: np.ndarray | None = None, world: np.ndarray | None = None
) -> Lifted | None:
    """The 3-D ray of one arm of a 33x3 [x px, y px, visibility] skeleton (the person's own `side`), its hand's 21
    landmarks if the hand stage saw it, MediaPipe's 33x3 world landmarks (m) if known. Methods in the module's
    order; None when none has depth."""
    p = np.asarray(pose, dtype=float).reshape(33, 3)
    s, e, w, _, _ = POSE[side]
    tip = _tip_pixels(p, side, hand)
    tip3 = view.lift(tip[0][0], tip[0][1], depth_from=tip[1]) if tip is not None else None
    if _visible(p, *EYES) and tip3 is not None:
        eyes = p[list(EYES), :2].mean(axis=0)
        ray = _segment(view.lift(*eyes), tip3, "eye_fingertip")
        if ray is not None:
            return ray
    wrist3 = view.lift(*p[w, :2]) if _visible(p, w) else None
    arm_methods: tuple[tuple[int, Ray3DMethod], ...] = ((e, "forearm"), (s, "shoulder_wrist"))
    for a, method in arm_methods:
        if _visible(p, a) and wrist3 is not None:
            ray = _segment(view.lift(*p[a, :2]), wrist3, method)
            if ray is not None:
                return ray
    if world is not None:
        return world_ray3d(view, p, side, np.asarray(world, dtype=float).reshape(33, 3))
    return None


def torso_point(view: DepthView, pose: np.ndarray) -> np.ndarray | None:
    """The torso's centre in metres: the median depth inside the shoulder-hip quadrilateral, at its centroid."""
    if not _visible(pose, *TORSO):
        return None
    quad = pose[list(TORSO), :2]
    centre = quad.mean(axis=0)
    x0, y0 = np.floor(quad.min(axis=0)).astype(int)
    x1, y1 = np.ceil(quad.max(axis=0)).astype(int)
    x0, y0 = max(x0, 0), max(y0, 0)
    x1, y1 = min(x1, view.width - 1), min(y1, view.height - 1)
    if x1 <= x0 or y1 <= y0:
        return None
    # the middle half of the box: inside the torso whatever the person's lean
    cx0, cx1 = x0 + (x1 - x0) // 4, x1 - (x1 - x0) // 4
    cy0, cy1 = y0 + (y1 - y0) // 4, y1 - (y1 - y0) // 4
    patch = view.metres[cy0 : cy1 + 1, cx0 : cx1 + 1]
    valid = patch[patch > 0]
    if valid.size < MIN_VALID:
        return None
    return view.back_project(float(centre[0]), float(centre[1]), float(np.median(valid)))


def lift_pose(view: DepthView, pose: np.ndarray) -> np.ndarray:
    """The 33 pose landmarks in metres (33x3), each at the median depth of its window; NaN where the landmark is
    not visible, outside the image or without depth. The points are on the body's surface (its front)."""
    p = np.asarray(pose, dtype=float).reshape(33, 3)
    out = np.full((33, 3), np.nan)
    for k in range(33):
        if p[k, 2] >= MIN_VISIBILITY:
            lifted = view.lift(float(p[k, 0]), float(p[k, 1]))
            if lifted is not None:
                out[k] = lifted
    return out


def world_ray3d(view: DepthView, pose: np.ndarray, side: str, world: np.ndarray) -> Lifted | None:
    """MediaPipe's world skeleton (metres, origin between the hips, axes along the camera's) moved so that its
    torso centre sits at the torso's measured position; eyes -> index when those are visible, else shoulder ->
    wrist. The depth is of the body's front, the skeleton's joints are inside it: a few cm, in the origin only."""
    torso = torso_point(view, pose)
    if torso is None:
        return None
    placed = world + (torso - world[list(TORSO)].mean(axis=0))
    s, _, w, i, _ = POSE[side]
    if _visible(pose, *EYES, i):
        ray = _segment(placed[list(EYES)].mean(axis=0), placed[i], "world_landmarks")
        if ray is not None:
            return ray
    if _visible(pose, s, w):
        return _segment(placed[s], placed[w], "world_landmarks")
    return None


def hand_ray3d(view: DepthView, hand: np.ndarray) -> Lifted | None:
    """A hand seen without its body: index knuckle -> fingertip (the tip's depth read halfway back to its joint)."""
    q = np.asarray(hand, dtype=float).reshape(21, 2)
    tip_depth_at = tuple((q[HAND_INDEX_TIP] + q[HAND_INDEX_DIP]) / 2)
    return _segment(
        view.lift(*q[HAND_INDEX_MCP]),
        view.lift(q[HAND_INDEX_TIP][0], q[HAND_INDEX_TIP][1], depth_from=tip_depth_at),
        "index_finger",
    )


# ---------------------------------------------------------------------------
# The surface the ray points at
# ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Plane:
    normal: np.ndarray  # unit; points p on the plane satisfy normal @ p + offset = 0
    offset: float
    inliers: np.ndarray  # N x 3

    def distance(self, p: np.ndarray) -> np.ndarray:
        return np.abs(p @ self.normal + self.offset)


def fit_plane(points: np.ndarray, iterations: int = RANSAC_ITERATIONS, seed: int = 0) -> Plane | None:
    """The plane with most points within `inlier_tolerance` (RANSAC on 3 points, each hypothesis counted on a
    random subset of at most `RANSAC_SUBSET` points), refined by least squares on its inliers among all points.
    Deterministic (seeded). None with fewer than `MIN_PLANE_POINTS` points or inliers."""
    n = len(points)
    if n < MIN_PLANE_POINTS:
        return None
    rng = np.random.default_rng(seed)
    subset = points if n <= RANSAC_SUBSET else points[rng.choice(n, RANSAC_SUBSET, replace=False)]
    tolerance = inlier_tolerance(subset[:, 2])
    a, b, c = (subset[rng.integers(0, len(subset), size=iterations)] for _ in range(3))
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    normals, a = normals[ok] / norms[ok, None], a[ok]
    if not len(normals):
        return None
    # distances of every subset point to every hypothesis: iterations x subset
    counts = (np.abs(subset @ normals.T - np.sum(normals * a, axis=1)) <= tolerance[:, None]).sum(axis=0)
    k = int(np.argmax(counts))
    tolerance = inlier_tolerance(points[:, 2])
    best = np.abs((points - a[k]) @ normals[k]) <= tolerance
    if best.sum() < MIN_PLANE_POINTS:
        return None
    for _ in range(2):  # least squares on the inliers, then the inliers of that plane
        inliers = points[best]
        centroid = inliers.mean(axis=0)
        normal = np.linalg.svd(inliers - centroid, full_matrices=False)[2][2]
        offset = -float(normal @ centroid)
        best = np.abs(points @ normal + offset) <= tolerance
        if best.sum() < MIN_PLANE_POINTS:
            return None
    return Plane(normal, offset, points[best])


@dataclass(frozen=True)
class Meeting:
    """Where a ray meets the surface it points at."""

    point: np.ndarray
    in_view: bool  # False: outside the image (or behind the camera): the plane seen in the image, extended


def surface_hit(view: DepthView, ray: Lifted, cloud: np.ndarray | None = None) -> np.ndarray | None:
    """The ray's meeting point with the surface it points at, where that surface is seen (`surface_meeting`, in
    view only); None otherwise."""
    meeting = surface_meeting(view, ray, cloud)
    return meeting.point if meeting is not None and meeting.in_view else None


def surface_meeting(
    view: DepthView, ray: Lifted, cloud: np.ndarray | None = None, up: np.ndarray | None = None
) -> Meeting | None:
    """Where `ray` meets the surface it points at. Planes are fitted (largest first, up to `MAX_PLANES`) to the
    depth points in a cone around the ray beyond the hand, and the first one along the ray that is seen where the
    ray meets it wins (in view). When none is, the ray may leave the image: its meeting, outside the image, with
    the largest up-facing plane (`up_facing`: the floor or the table; `up` default the camera's -y) of the frame or,
    failing that, of the cone (out of view). A small box top is not extended beyond the image. None when the ray
    meets nothing (the sky, or no depth)."""
    pts = view.cloud() if cloud is None else cloud
    rel = pts - ray.origin
    along = rel @ ray.direction
    across = np.linalg.norm(rel - np.outer(along, ray.direction), axis=1)
    beyond = ray.reach + 0.05  # not the pointing arm itself
    near = (along > beyond) & (across <= CONE_BASE + along * math.tan(math.radians(CONE_DEG)))
    planes = fit_planes(pts[near])
    seen = [(t, hit) for t, hit, plane in _meetings(ray, planes, beyond) if _supported(plane, hit)]
    if seen:
        return Meeting(min(seen, key=lambda h: h[0])[1], True)
    facing = CAMERA_UP if up is None else up
    for candidates in (fit_planes(pts), planes):  # the frame's planes (best for extending far), else the cone's
        largest = max((p for p in candidates if up_facing(p, facing)), key=lambda p: len(p.inliers), default=None)
        outside = [
            hit for _, hit, _ in _meetings(ray, [largest] if largest else [], beyond) if not _in_image(view, hit)
        ]
        if outside:
            return Meeting(outside[0], False)
    return None


def fit_planes(points: np.ndarray, count: int = MAX_PLANES) -> list[Plane]:
    """Up to `count` planes, largest first, each fitted to the points the previous ones left."""
    planes: list[Plane] = []
    remaining = points
    for k in range(count):
        plane = fit_plane(remaining, seed=k)
        if plane is None:
            break
        planes.append(plane)
        remaining = remaining[plane.distance(remaining) > inlier_tolerance(remaining[:, 2])]
    return planes


def _meetings(ray: Lifted, planes: list[Plane], beyond: float) -> list[tuple[float, np.ndarray, Plane]]:
    """(distance along the ray, point, plane) where the ray meets each plane beyond the hand."""
    out = []
    for plane in planes:
        denom = float(plane.normal @ ray.direction)
        if abs(denom) > 1e-3:
            t = -(float(plane.normal @ ray.origin) + plane.offset) / denom
            if t > beyond:
                out.append((t, ray.origin + t * ray.direction, plane))
    return out


def _supported(plane: Plane, hit: np.ndarray) -> bool:
    return int((np.linalg.norm(plane.inliers - hit, axis=1) <= SUPPORT_RADIUS).sum()) >= MIN_SUPPORT


def up_facing(plane: Plane, up: np.ndarray = CAMERA_UP) -> bool:
    """A floor or a table top: the plane's normal (either sign) within `UP_FACING_DEG` of `up` (unit)."""
    return abs(float(plane.normal @ up)) >= math.cos(math.radians(UP_FACING_DEG))


def body_up(joints3d: np.ndarray | None) -> np.ndarray | None:
    """The person's up in the camera frame: mid-hips -> mid-shoulders of a lifted skeleton (upright, standing or
    seated), or None when those four have no depth."""
    if joints3d is None:
        return None
    j = np.asarray(joints3d, dtype=float).reshape(33, 3)
    if not np.isfinite(j[list(TORSO)]).all():
        return None
    axis = j[[11, 12]].mean(axis=0) - j[[23, 24]].mean(axis=0)
    norm = float(np.linalg.norm(axis))
    return axis / norm if norm > 0.2 else None  # shorter than a torso: the depth saw something else


def _in_image(view: DepthView, p: np.ndarray) -> bool:
    if p[2] <= 1e-6:
        return False  # behind the camera
    u, v = view.project(p)
    return 0 <= u < view.width and 0 <= v < view.height


def to_wire(ray: Lifted, frame_id: str, hit: Meeting | np.ndarray | None) -> Ray3D:
    direction = [float(c) for c in ray.direction]
    norm = math.sqrt(sum(c * c for c in direction))
    meeting = Meeting(hit, True) if isinstance(hit, np.ndarray) else hit
    return Ray3D(
        origin=[round(float(c), 4) for c in ray.origin],
        direction=[c / norm for c in direction],
        method=ray.method,
        frame_id=frame_id,
        hit=None if meeting is None else [round(float(c), 4) for c in meeting.point],
        hit_in_view=None if meeting is None else meeting.in_view,
    )


def side_of_hand(pose: np.ndarray | None, hand: np.ndarray) -> str | None:
    """The body side whose pose wrist is nearest this hand's wrist (within a forearm's length), or None."""
    if pose is None:
        return None
    p = np.asarray(pose, dtype=float).reshape(33, 3)
    q = np.asarray(hand, dtype=float).reshape(21, 2)
    best, best_d = None, math.inf
    for side, (_, e, w, _, _) in POSE.items():
        if p[w, 2] < MIN_VISIBILITY:
            continue
        d = float(np.linalg.norm(p[w, :2] - q[0]))
        if d <= max(float(np.linalg.norm(p[w, :2] - p[e, :2])), 1.0) and d < best_d:
            best, best_d = side, d
    return best


class FrameRays:
    """The 3-D rays of one frame, computed on demand and once each: the shell asks for the hands' and arms' rays.
    A DepthFrame is decoded only when a ray or the lifted joints are asked for (a body is seen); a frame that cannot be
    decoded gives no rays and leaves its reason in `error`."""

    def __init__(self, depth: DepthView | DepthFrame, pose: np.ndarray | None, world: np.ndarray | None):
        self._depth = depth
        self._view = depth if isinstance(depth, DepthView) else None
        self.pose, self.world = pose, world
        self.error: str | None = None
        self._cloud: np.ndarray | None = None
        self._done: dict = {}

    def joints(self) -> np.ndarray | None:
        """The skeleton lifted to metres (`lift_pose`; NaN where no depth), for judging arms in 3-D; None without a
        skeleton or a decodable depth."""
        if "joints" not in self._done:
            view = self.view
            self._done["joints"] = None if view is None or self.pose is None else lift_pose(view, self.pose)
        return self._done["joints"]

    @property
    def view(self) -> DepthView | None:
        if self._view is None and self.error is None and isinstance(self._depth, DepthFrame):  # (else it is the view)
            try:
                self._view = depth_view(self._depth)
            except ValueError as exc:  # UndecodableDepth: a broken PNG, a size that does not match
                self.error = str(exc)
        return self._view

    def _wire(self, key, make) -> Ray3D | None:
        if key not in self._done:
            view = self.view
            ray = make(view) if view is not None else None
            if ray is None or view is None:
                self._done[key] = None
            else:
                if self._cloud is None:
                    self._cloud = view.cloud()
                up = body_up(self.joints())
                self._done[key] = to_wire(ray, view.frame_id, surface_meeting(view, ray, self._cloud, up))
        return self._done[key]

    def arm(self, side: str, hand: np.ndarray | None = None) -> Ray3D | None:
        if self.pose is None:
            return None
        return self._wire(
            ("arm", side, hand is not None and hand.tobytes()),
            lambda view: arm_ray3d(view, self.pose, side, hand, self.world),
        )

    def hand(self, hand: np.ndarray, tip: bool = True) -> Ray3D | None:
        """A pointing hand: its arm's ray when the body stage sees that arm (through the hand's own index tip when
        `tip`: the 2-D ray came from the finger, not from the arm), else the index finger's."""
        side = side_of_hand(self.pose, hand)
        if side is not None:
            ray = self.arm(side, hand if tip else None)
            if ray is not None:
                return ray
        return self._wire(("hand", hand.tobytes()), lambda view: hand_ray3d(view, hand))
