"""Functional core: contract samples -> the Foxglove messages `hri record` writes and `hri foxglove` serves.

One sample on key K becomes (the topics a viewer lists; every one has a schema Foxglove decodes):
- `/K`: the sample itself — Frame: `foxglove.CompressedImage` (jpeg/png) or `foxglove.RawImage` (bgr8);
  DepthFrame: `foxglove.RawImage` (16UC1 / 32FC1, units of `depth_scale` metres); AudioChunk: `foxglove.RawAudio`;
  every other contract type: JSON, with its JSON Schema generated from common/schema.py (bytes as base64);
- `/K/annotations` (`foxglove.ImageAnnotations`, pixel coordinates of the camera image): objects' boxes and
  labels in their colour, hands' landmarks and pointing rays, body skeletons, faces, persons (the speaker marked);
- `/K/scene` (`foxglove.SceneUpdate`, metres, in the camera's optical frame), with depth: objects as cubes at
  their position and size, pointing rays as arrows and their floor/table hit as a sphere, persons as a sphere
  and their skeleton lifted with the latest depth image;
- `/<prefix>/tf` (`foxglove.FrameTransform`): `world` (z up) -> the camera's optical frame, with every frame;
- `/<prefix>/log` (`foxglove.Log`): one line per transcript, gesture event, command and question;
- `/<prefix>/services` (JSON `ServicesState`): the latest Stats of every service instance, one table.

Pure: no zenoh, no I/O. foxglove-sdk (the `foxglove` extra) encodes the protobuf messages without the protobuf
runtime, so the project's protobuf<5 pin (MediaPipe) is untouched.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from typing import Any, Iterable

import msgspec
import numpy as np

from common.keys import Keys
from common.schema import (
    AudioChunk,
    Bodies,
    Clarification,
    DepthFrame,
    Detections,
    Faces,
    Frame,
    FusedCommand,
    GestureEvent,
    Hands,
    Persons,
    Ray,
    Sample,
    Stats,
    Transcript,
)

WORLD = "world"  # the fixed frame of the 3-D scene: z up, the camera looking along +x
VIEWER_METADATA = "hri.viewer"  # channel metadata marking a viewer channel (replay reads only the raw ones)
JSON_ENCODING = "json"
PROTOBUF = "protobuf"

# optical (x right, y down, z forward) -> world (x forward, y left, z up): the usual camera body rotation
OPTICAL_IN_WORLD = (-0.5, 0.5, -0.5, 0.5)  # quaternion x, y, z, w
CAMERA_HEIGHT_M = 0.0  # the camera is the origin of `world`; a robot's own transform tree places it properly

# RGBA 0..1 of the basic colour names vision reports; anything else is drawn in BOX_RGBA
COLOUR_RGBA: dict[str, tuple[float, float, float, float]] = {
    "red": (0.9, 0.1, 0.1, 1.0),
    "orange": (1.0, 0.55, 0.0, 1.0),
    "yellow": (1.0, 0.9, 0.1, 1.0),
    "green": (0.1, 0.75, 0.2, 1.0),
    "blue": (0.15, 0.35, 1.0, 1.0),
    "purple": (0.6, 0.2, 0.8, 1.0),
    "pink": (1.0, 0.45, 0.7, 1.0),
    "brown": (0.55, 0.3, 0.1, 1.0),
    "black": (0.1, 0.1, 0.1, 1.0),
    "white": (0.95, 0.95, 0.95, 1.0),
    "grey": (0.55, 0.55, 0.55, 1.0),
    "gray": (0.55, 0.55, 0.55, 1.0),
}
BOX_RGBA = (0.0, 0.86, 0.31, 1.0)
HAND_RGBA = (0.0, 1.0, 1.0, 1.0)
RAY_RGBA = (1.0, 1.0, 0.0, 1.0)
BODY_RGBA = (1.0, 0.6, 0.2, 1.0)
FACE_RGBA = (0.7, 0.7, 1.0, 1.0)
PERSON_RGBA = (0.4, 0.8, 1.0, 1.0)
SPEAKER_RGBA = (1.0, 0.0, 1.0, 1.0)  # magenta, the same as the target in `hri view`
TEXT_BG_RGBA = (0.0, 0.0, 0.0, 0.6)

HAND_CONNECTIONS = (
    (0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (5, 9), (9, 10), (10, 11), (11, 12),
    (9, 13), (13, 14), (14, 15), (15, 16), (13, 17), (17, 18), (18, 19), (19, 20), (0, 17),
)  # fmt: skip
# MediaPipe Pose: face outline left out, the limbs and torso kept
BODY_CONNECTIONS = (
    (11, 12), (11, 13), (13, 15), (12, 14), (14, 16), (11, 23), (12, 24), (23, 24),
    (23, 25), (25, 27), (24, 26), (26, 28), (15, 19), (16, 20), (0, 11), (0, 12),
)  # fmt: skip
VISIBLE = 0.5  # MediaPipe visibility below which a body point is a guess (not drawn)
RAY_LENGTH_PX = 200.0  # how long a 2-D pointing ray is drawn
RAY_LENGTH_M = 1.5  # a 3-D ray without a hit


@functools.cache
def _fox() -> Any:
    try:
        import foxglove.messages as fm
    except ImportError:
        raise SystemExit(
            "the Foxglove channels need foxglove-sdk: pip install 'hri-fusion[foxglove]' "
            "(or -c constraints.txt 'foxglove-sdk==0.30.3')"
        ) from None
    return fm


def available() -> bool:
    """Whether foxglove-sdk is installed (the viewer channels are written only then)."""
    try:
        import foxglove.messages  # noqa: F401
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class ViewerSchema:
    name: str
    encoding: str  # "protobuf" (data: a FileDescriptorSet) or "jsonschema"
    data: bytes


@dataclass(frozen=True)
class ViewerMessage:
    topic: str
    schema: ViewerSchema
    message_encoding: str  # "protobuf" or "json"
    data: bytes
    stamp_ns: int  # the sample's source time


@functools.cache
def protobuf_schema(name: str) -> ViewerSchema:
    s = getattr(_fox(), name).get_schema()
    return ViewerSchema(s.name, s.encoding, bytes(s.data))


@functools.cache
def json_schema_of(cls: type[msgspec.Struct]) -> ViewerSchema:
    from hri.wiredoc import json_schema

    return ViewerSchema(cls.__name__, "jsonschema", json.dumps(json_schema(cls), separators=(",", ":")).encode())


def _ns(stamp: float) -> int:
    return int(round(stamp * 1e9))


def _time(stamp: float) -> Any:
    ns = _ns(stamp)
    return _fox().Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


@functools.cache
def _colour(rgba: tuple[float, float, float, float]) -> Any:
    return _fox().Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _pt2(p: list[float]) -> Any:
    return _fox().Point2(x=float(p[0]), y=float(p[1]))


def _pt3(p: list[float] | np.ndarray) -> Any:
    return _fox().Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _pose(position: list[float] | np.ndarray, orientation: tuple[float, float, float, float] = (0, 0, 0, 1)) -> Any:
    fm = _fox()
    x, y, z, w = orientation
    return fm.Pose(
        position=fm.Vector3(x=float(position[0]), y=float(position[1]), z=float(position[2])),
        orientation=fm.Quaternion(x=x, y=y, z=z, w=w),
    )


def _message(topic: str, name: str, msg: Any, stamp: float) -> ViewerMessage:
    return ViewerMessage(topic, protobuf_schema(name), PROTOBUF, msg.encode(), _ns(stamp))


# ---------------------------------------------------------------------------
# 2-D annotations (pixels)
# ---------------------------------------------------------------------------
@dataclass
class Annotations:
    """What one sample draws on its camera's image: foxglove PointsAnnotation / TextAnnotation lists."""

    stamp: float
    points: list[Any] = field(default_factory=list)
    texts: list[Any] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.time = _time(self.stamp)  # one Timestamp for every annotation of the sample

    def box(self, bbox: list[float], rgba: tuple[float, float, float, float], thickness: float = 2.0) -> None:
        x, y, w, h = bbox
        corners = [[x, y], [x + w, y], [x + w, y + h], [x, y + h]]
        self.polyline(corners, rgba, "LineLoop", thickness)

    def polyline(
        self, pts: list[list[float]], rgba: tuple[float, float, float, float], kind: str, thickness: float = 2.0
    ) -> None:
        fm = _fox()
        self.points.append(
            fm.PointsAnnotation(
                timestamp=self.time,
                type=getattr(fm.PointsAnnotationType, kind),
                points=[_pt2(p) for p in pts],
                outline_color=_colour(rgba),
                thickness=thickness,
            )
        )

    def text(self, at: list[float], text: str, rgba: tuple[float, float, float, float]) -> None:
        fm = _fox()
        self.texts.append(
            fm.TextAnnotation(
                timestamp=self.time,
                position=_pt2(at),
                text=text,
                font_size=14.0,
                text_color=_colour(rgba),
                background_color=_colour(TEXT_BG_RGBA),
            )
        )

    def ray(self, ray: Ray) -> None:
        (ox, oy), (dx, dy) = ray.origin, ray.direction
        self.polyline([[ox, oy], [ox + dx * RAY_LENGTH_PX, oy + dy * RAY_LENGTH_PX]], RAY_RGBA, "LineStrip", 3.0)

    def message(self, topic: str) -> ViewerMessage:
        msg = _fox().ImageAnnotations(points=self.points, texts=self.texts)
        return _message(topic, "ImageAnnotations", msg, self.stamp)


def object_rgba(color: str | None) -> tuple[float, float, float, float]:
    return COLOUR_RGBA.get((color or "").split()[-1] if color else "", BOX_RGBA)


def object_label(label: str, color: str | None, score: float, position: list[float] | None) -> str:
    words = f"{color} {label}" if color else label
    where = f" @ {position[2]:.2f} m" if position else ""
    return f"{words} {score:.2f}{where}"


def detections_annotations(d: Detections) -> Annotations:
    a = Annotations(d.stamp)
    for o in d.objects:
        rgba = object_rgba(o.color)
        a.box(o.bbox, rgba)
        a.text([o.bbox[0], o.bbox[1] - 4], f"{o.id} {object_label(o.label, o.color, o.score, o.position)}", rgba)
    return a


def hands_annotations(h: Hands) -> Annotations:
    a = Annotations(h.stamp)
    for hand in h.hands:
        a.polyline(
            [p for c in HAND_CONNECTIONS for p in (hand.landmarks[c[0]], hand.landmarks[c[1]])], HAND_RGBA, "LineList"
        )
        a.polyline(hand.landmarks, HAND_RGBA, "Points", 4.0)
        who = f" ({hand.person})" if hand.person else ""
        a.text(hand.landmarks[0], f"{hand.hand} {hand.gesture or ''}{who}".strip(), HAND_RGBA)
        if hand.ray is not None:
            a.ray(hand.ray)
    return a


def bodies_annotations(b: Bodies) -> Annotations:
    a = Annotations(b.stamp)
    for body in b.bodies:
        seen = [body.visibility[i] >= VISIBLE and body.visibility[j] >= VISIBLE for i, j in BODY_CONNECTIONS]
        lines = [p for (i, j), ok in zip(BODY_CONNECTIONS, seen) if ok for p in (body.landmarks[i], body.landmarks[j])]
        if lines:
            a.polyline(lines, BODY_RGBA, "LineList", 3.0)
        for ray in (body.left_ray, body.right_ray):
            if ray is not None:
                a.ray(ray)
    return a


def faces_annotations(f: Faces) -> Annotations:
    a = Annotations(f.stamp)
    for face in f.faces:
        a.box(face.bbox, FACE_RGBA, 1.5)
        mouth = f" mouth {face.mouth_open:.2f}" if face.mouth_open is not None else ""
        a.text([face.bbox[0], face.bbox[1] + face.bbox[3] + 14], f"{face.id}{mouth}", FACE_RGBA)
    return a


def persons_annotations(p: Persons) -> Annotations:
    """Persons' boxes; the one most likely speaking (speaking >= 0.5) in magenta, marked 'speaking'."""
    a = Annotations(p.stamp)
    speaker = speaking_person(p)
    for person in p.persons:
        is_speaker = person.id == speaker
        rgba = SPEAKER_RGBA if is_speaker else PERSON_RGBA
        a.box(person.bbox, rgba, 3.0 if is_speaker else 2.0)
        a.text([person.bbox[0], person.bbox[1] - 4], person.id + (" — speaking" if is_speaker else ""), rgba)
    return a


def speaking_person(p: Persons, threshold: float = 0.5) -> str | None:
    """The id of the person most likely speaking, if anyone's `speaking` reaches `threshold`."""
    scored = [(person.speaking, person.id) for person in p.persons if person.speaking is not None]
    best = max(scored, default=None)
    return best[1] if best is not None and best[0] >= threshold else None


# ---------------------------------------------------------------------------
# 3-D scene (metres, the camera's optical frame)
# ---------------------------------------------------------------------------
@dataclass
class Scene:
    stamp: float
    frame_id: str
    entities: list[Any] = field(default_factory=list)

    def entity(self, entity_id: str, **primitives: list[Any]) -> None:
        fm = _fox()
        self.entities.append(
            fm.SceneEntity(
                timestamp=_time(self.stamp),
                frame_id=self.frame_id,
                id=entity_id,
                lifetime=fm.Duration(sec=1, nsec=0),  # a lost track disappears after a second
                frame_locked=True,
                **primitives,
            )
        )

    def label(self, at: list[float], text: str, rgba: tuple[float, float, float, float]) -> Any:
        return _fox().TextPrimitive(
            pose=_pose(at), billboard=True, font_size=14.0, scale_invariant=True, color=_colour(rgba), text=text
        )

    def sphere(self, at: list[float], size: float, rgba: tuple[float, float, float, float]) -> Any:
        fm = _fox()
        return fm.SpherePrimitive(pose=_pose(at), size=fm.Vector3(x=size, y=size, z=size), color=_colour(rgba))

    def arrow(self, origin: list[float], direction: list[float], length: float) -> Any:
        return _fox().ArrowPrimitive(
            pose=_pose(origin, rotation_from_x(direction)),
            shaft_length=max(length - 0.06, 0.01),
            shaft_diameter=0.015,
            head_length=0.06,
            head_diameter=0.04,
            color=_colour(RAY_RGBA),
        )

    def ray3d(self, entity_id: str, ray: Ray) -> None:
        r = ray.ray3d
        if r is None:
            return
        length = math.dist(r.origin, r.hit) if r.hit is not None else RAY_LENGTH_M
        spheres = [self.sphere(r.hit, 0.06, RAY_RGBA)] if r.hit is not None else []
        self.entity(entity_id, arrows=[self.arrow(r.origin, r.direction, length)], spheres=spheres)

    def message(self, topic: str) -> ViewerMessage:
        return _message(topic, "SceneUpdate", _fox().SceneUpdate(entities=self.entities), self.stamp)


def rotation_from_x(direction: list[float]) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) turning +x onto `direction` (a Foxglove arrow points along its pose's +x)."""
    d = np.asarray(direction, float)
    d = d / (np.linalg.norm(d) or 1.0)
    x = np.array([1.0, 0.0, 0.0])
    axis = np.cross(x, d)
    s = float(np.linalg.norm(axis))
    c = float(np.dot(x, d))
    if s < 1e-9:
        return (0.0, 0.0, 0.0, 1.0) if c > 0 else (0.0, 0.0, 1.0, 0.0)
    half = math.atan2(s, c) / 2
    ax = axis / s * math.sin(half)
    return (float(ax[0]), float(ax[1]), float(ax[2]), math.cos(half))


def detections_scene(d: Detections) -> Scene | None:
    placed = [o for o in d.objects if o.position is not None]
    if not placed or d.frame_id is None:
        return None
    fm = _fox()
    scene = Scene(d.stamp, d.frame_id)
    for o in placed:
        assert o.position is not None
        size = o.extent or [0.05, 0.05, 0.05]
        rgba = object_rgba(o.color)
        cube = fm.CubePrimitive(
            pose=_pose(o.position), size=fm.Vector3(x=size[0], y=size[1], z=size[2]), color=_colour(rgba[:3] + (0.7,))
        )
        above = [o.position[0], o.position[1] - size[1] / 2 - 0.03, o.position[2]]
        scene.entity(
            f"object/{o.id}", cubes=[cube], texts=[scene.label(above, f"{o.id} {o.color or ''} {o.label}", rgba)]
        )
    return scene


def rays_scene(stamp: float, rays: Iterable[tuple[str, Ray | None]]) -> Scene | None:
    with3d = [(name, r) for name, r in rays if r is not None and r.ray3d is not None]
    if not with3d:
        return None
    assert with3d[0][1].ray3d is not None
    scene = Scene(stamp, with3d[0][1].ray3d.frame_id)
    for name, r in with3d:
        scene.ray3d(name, r)
    return scene


# ---------------------------------------------------------------------------
# Depth: lifting body skeletons into the scene
# ---------------------------------------------------------------------------
@dataclass
class DepthView:
    """The latest depth image of a camera, decoded lazily (only when a skeleton needs it)."""

    frame: DepthFrame
    _metres: np.ndarray | None = None

    def metres(self) -> np.ndarray:
        if self._metres is None:
            from common.depth import depth_metres

            self._metres = depth_metres(self.frame)
        return self._metres

    def lift(self, points: list[list[float]]) -> list[np.ndarray | None]:
        """Each pixel point in metres (optical frame) through the depth at it; None where depth is missing."""
        m = self.metres()
        k = self.frame.camera_info.k
        fx, fy, cx, cy = k[0], k[4], k[2], k[5]
        out: list[np.ndarray | None] = []
        for x, y in points:
            u, v = int(round(x)), int(round(y))
            z = float(m[v, u]) if 0 <= v < m.shape[0] and 0 <= u < m.shape[1] else 0.0
            out.append(np.array([(x - cx) * z / fx, (y - cy) * z / fy, z]) if z > 0 and math.isfinite(z) else None)
        return out


def body_skeleton(depth: DepthView, body_landmarks: list[list[float]], visibility: list[float]) -> list[np.ndarray]:
    """Line-list points (pairs) of the visible bones with depth at both ends."""
    lifted = depth.lift(body_landmarks)
    pts: list[np.ndarray] = []
    for i, j in BODY_CONNECTIONS:
        a, b = lifted[i], lifted[j]
        if a is not None and b is not None and min(visibility[i], visibility[j]) >= VISIBLE:
            pts += [a, b]
    return pts


# ---------------------------------------------------------------------------
# Service state: the latest Stats of every service instance in one message
# ---------------------------------------------------------------------------
class ServiceState(msgspec.Struct, kw_only=True):
    """One service instance as its latest Stats describe it (a viewer table row)."""

    service: str
    instance: str
    stamp: float  # of its latest Stats
    uptime: float
    received: int
    published: int
    skipped: int
    rejected: int  # invalid samples, all reasons


class ServicesState(msgspec.Struct, kw_only=True):
    """Every service instance seen, on `/<prefix>/services` (a viewer's service-state panel)."""

    stamp: float
    services: list[ServiceState]


# ---------------------------------------------------------------------------
# The converter
# ---------------------------------------------------------------------------
class FoxgloveConverter:
    """Turns decoded contract samples into viewer messages; remembers each camera's latest depth image."""

    def __init__(self, keys: Keys):
        self.keys = keys
        self.tf_topic = f"/{keys.prefix}/tf"
        self.log_topic = f"/{keys.prefix}/log"
        self.services_topic = f"/{keys.prefix}/services"
        self.depth: dict[str, DepthView] = {}
        self.services: dict[tuple[str, str], ServiceState] = {}

    def convert(self, key: str, sample: Sample) -> list[ViewerMessage]:
        handler = getattr(self, "_" + type(sample).__name__, None)
        if handler is None:
            return [self.as_json(key, sample)]
        out: list[ViewerMessage] = handler(key, sample)
        return out

    @staticmethod
    def as_json(key: str, sample: Sample) -> ViewerMessage:
        return ViewerMessage(
            "/" + key, json_schema_of(type(sample)), JSON_ENCODING, msgspec.json.encode(sample), _ns(sample.stamp)
        )

    def transform(self, stamp: float, frame_id: str) -> ViewerMessage:
        fm = _fox()
        x, y, z, w = OPTICAL_IN_WORLD
        msg = fm.FrameTransform(
            timestamp=_time(stamp),
            parent_frame_id=WORLD,
            child_frame_id=frame_id,
            translation=fm.Vector3(x=0.0, y=0.0, z=CAMERA_HEIGHT_M),
            rotation=fm.Quaternion(x=x, y=y, z=z, w=w),
        )
        return _message(self.tf_topic, "FrameTransform", msg, stamp)

    def log(self, stamp: float, source: str, text: str, level: str = "Info") -> ViewerMessage:
        fm = _fox()
        msg = fm.Log(timestamp=_time(stamp), level=getattr(fm.LogLevel, level), message=text, name=source)
        return _message(self.log_topic, "Log", msg, stamp)

    # -- per type ------------------------------------------------------------------------------
    def _Frame(self, key: str, f: Frame) -> list[ViewerMessage]:
        fm = _fox()
        frame_id = f.camera_info.frame_id if f.camera_info else f"{f.cam}_optical"
        if f.encoding == "bgr8":
            msg = fm.RawImage(
                timestamp=_time(f.stamp), frame_id=frame_id, width=f.width, height=f.height,
                encoding="bgr8", step=f.width * 3, data=f.data,
            )  # fmt: skip
            image = _message("/" + key, "RawImage", msg, f.stamp)
        else:
            msg = fm.CompressedImage(timestamp=_time(f.stamp), frame_id=frame_id, data=f.data, format=f.encoding)
            image = _message("/" + key, "CompressedImage", msg, f.stamp)
        return [image, self.transform(f.stamp, frame_id)]

    def _DepthFrame(self, key: str, d: DepthFrame) -> list[ViewerMessage]:
        from common.depth import depth_units

        self.depth[d.cam] = DepthView(d)
        units = np.ascontiguousarray(depth_units(d))
        msg = _fox().RawImage(
            timestamp=_time(d.stamp), frame_id=d.camera_info.frame_id, width=d.width, height=d.height,
            encoding=d.encoding, step=d.width * units.itemsize, data=units.tobytes(),
        )  # fmt: skip
        return [_message("/" + key, "RawImage", msg, d.stamp), self.transform(d.stamp, d.camera_info.frame_id)]

    def _AudioChunk(self, key: str, a: AudioChunk) -> list[ViewerMessage]:
        msg = _fox().RawAudio(
            timestamp=_time(a.stamp), data=a.data, format="pcm-s16", sample_rate=a.rate, number_of_channels=a.channels
        )
        return [_message("/" + key, "RawAudio", msg, a.stamp)]

    def _Detections(self, key: str, d: Detections) -> list[ViewerMessage]:
        out = [self.as_json(key, d), detections_annotations(d).message(f"/{key}/annotations")]
        scene = detections_scene(d)
        return out + ([scene.message(f"/{key}/scene")] if scene else [])

    def _Hands(self, key: str, h: Hands) -> list[ViewerMessage]:
        out = [self.as_json(key, h), hands_annotations(h).message(f"/{key}/annotations")]
        scene = rays_scene(h.stamp, ((f"hand/{x.hand}", x.ray) for x in h.hands))
        return out + ([scene.message(f"/{key}/scene")] if scene else [])

    def _Bodies(self, key: str, b: Bodies) -> list[ViewerMessage]:
        out = [self.as_json(key, b), bodies_annotations(b).message(f"/{key}/annotations")]
        rays = [
            (f"body/{i}/{side}", r)
            for i, x in enumerate(b.bodies)
            for side, r in (("left", x.left_ray), ("right", x.right_ray))
        ]
        scene = rays_scene(b.stamp, rays)
        skeletons = self._skeleton_entities(b)
        if skeletons:
            scene = scene or Scene(b.stamp, self.depth[b.cam].frame.camera_info.frame_id)
            scene.entities += skeletons
        return out + ([scene.message(f"/{key}/scene")] if scene else [])

    def _skeleton_entities(self, b: Bodies) -> list[Any]:
        """The skeletons lifted with the camera's latest depth image (none without one of the same size)."""
        fm = _fox()
        depth = self.depth.get(b.cam)
        if depth is None or depth.frame.width != b.width or depth.frame.height != b.height:
            return []
        found = Scene(b.stamp, depth.frame.camera_info.frame_id)
        for i, body in enumerate(b.bodies):
            pts = body_skeleton(depth, body.landmarks, body.visibility)
            if pts:
                line = fm.LinePrimitive(
                    type=fm.LinePrimitiveLineType.LineList, pose=_pose([0, 0, 0]), thickness=0.02,
                    scale_invariant=False, points=[_pt3(p) for p in pts], color=_colour(BODY_RGBA),
                )  # fmt: skip
                found.entity(f"skeleton/{body.person or i}", lines=[line])
        return found.entities

    def _Faces(self, key: str, f: Faces) -> list[ViewerMessage]:
        return [self.as_json(key, f), faces_annotations(f).message(f"/{key}/annotations")]

    def _Persons(self, key: str, p: Persons) -> list[ViewerMessage]:
        out = [self.as_json(key, p), persons_annotations(p).message(f"/{key}/annotations")]
        placed = [x for x in p.persons if x.position is not None and x.frame_id]
        if placed:
            speaker = speaking_person(p)
            scene = Scene(p.stamp, placed[0].frame_id or "")
            for x in placed:
                assert x.position is not None
                rgba = SPEAKER_RGBA if x.id == speaker else PERSON_RGBA
                text = x.id + (" (speaking)" if x.id == speaker else "")
                above = [x.position[0], x.position[1] - 0.5, x.position[2]]
                scene.entity(
                    f"person/{x.id}",
                    spheres=[scene.sphere(x.position, 0.25, rgba)],
                    texts=[scene.label(above, text, rgba)],
                )
            out.append(scene.message(f"/{key}/scene"))
        return out

    def _GestureEvent(self, key: str, e: GestureEvent) -> list[ViewerMessage]:
        out = [
            self.as_json(key, e),
            self.log(e.stamp, e.source, f"gesture {e.gesture} {e.phase} ({e.hand} hand, {e.score:.2f})"),
        ]
        scene = rays_scene(e.stamp, [(f"event/{e.hand}", e.ray)])
        return out + ([scene.message(f"/{key}/scene")] if scene else [])

    def _Transcript(self, key: str, t: Transcript) -> list[ViewerMessage]:
        kind = "heard" if t.final else "hearing"
        return [self.as_json(key, t), self.log(t.stamp, t.source, f'{kind} "{t.text}" ({t.confidence:.2f}, {t.mic})')]

    def _FusedCommand(self, key: str, c: FusedCommand) -> list[ViewerMessage]:
        target = f" -> {c.target.id} {c.target.color or ''} {c.target.label}".replace("  ", " ") if c.target else ""
        who = f" [{c.speaker.person}]" if c.speaker and c.speaker.person else ""
        text = f"command {c.intent}{target} ({c.confidence:.2f}){who}: {c.explanation}"
        return [self.as_json(key, c), self.log(c.stamp, c.source, text)]

    def _Stats(self, key: str, st: Stats) -> list[ViewerMessage]:
        self.services[(st.service, st.instance)] = ServiceState(
            service=st.service, instance=st.instance, stamp=st.stamp, uptime=st.uptime, received=st.received,
            published=st.published, skipped=st.skipped, rejected=sum(st.rejected.values()),
        )  # fmt: skip
        state = ServicesState(stamp=st.stamp, services=[self.services[k] for k in sorted(self.services)])
        schema = json_schema_of(ServicesState)
        services = ViewerMessage(self.services_topic, schema, JSON_ENCODING, msgspec.json.encode(state), _ns(st.stamp))
        return [self.as_json(key, st), services]

    def _Clarification(self, key: str, q: Clarification) -> list[ViewerMessage]:
        text = f"question ({q.reason}): {q.question}"
        return [self.as_json(key, q), self.log(q.stamp, q.source, text, "Warning")]
