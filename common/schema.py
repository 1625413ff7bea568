"""Wire contract v1: the typed samples every service publishes and consumes.

Each schema is a `msgspec.Struct`: its type hints, with `Annotated[..., Meta(...)]` constraints, *are* the
contract, and msgspec checks them in C while decoding MessagePack. Cross-field rules live in
`__post_init__`, which msgspec runs on construction and on every decode. The field tables of docs/wire.md
are generated from the descriptions here (`python -m hri.wiredoc`; a test fails when they drift).

msgspec's errors are mapped onto the contract's documented rejection reasons by `rejection()` (one table),
so `InvalidSample.reason` is the same counter key whichever check failed.
"""

from __future__ import annotations

import math
import re
from functools import lru_cache
from typing import Annotated, Any, ClassVar, Final, Literal, Optional, get_args

import msgspec
from msgspec import Meta

SCHEMA_VERSION = 1

KIB = 1024
MIB = 1024 * KIB

# Enumerations, each written once; the tuples are the same values for code that iterates over them.
GestureName = Literal["point", "open_palm", "wave", "fist", "thumbs_up"]
GesturePhase = Literal["start", "hold", "end"]
Handedness = Literal["left", "right"]
ClarificationReason = Literal["ambiguous", "conflict", "not_found", "low_confidence"]
ImageEncoding = Literal["jpeg", "png", "bgr8"]
RaySource = Literal["hand", "body"]
# v1 extension (3-D): how a pointing ray was lifted into metres, best first.
Ray3DMethod = Literal["eye_fingertip", "index_finger", "forearm", "shoulder_wrist", "world_landmarks"]
DepthEncoding = Literal["16UC1", "32FC1"]
DepthCompression = Literal["none", "png"]
MotionDirection = Literal["forward", "back", "left", "right", "around"]
# v1 extension (people, issue #33): how an utterance's speaker was found (REP-155's person <-> voice link).
SpeakerMethod = Literal["mouth_motion", "only_face", "unknown"]
# v1 extension (the robot, issue #43): what the robot is doing, and what fusion does with a command meanwhile.
RobotStatus = Literal["idle", "busy", "done", "failed"]
WhileBusy = Literal["ask", "queue"]
# v1 extension (issue #40): REP-155's engagement levels (hri_msgs/EngagementLevel, lower-case).
EngagementLevel = Literal["unknown", "disengaged", "engaging", "engaged", "disengaging"]
# The modalities fusion weighs (Weights' fields, the keys of FusedCommand.inputs), each named after the service
# that feeds it (common/stack.py; tests/test_stack_declaration.py checks they are among fusion's input services).
# Code names them by these constants, so a misspelt one fails the type check.
Modality = Literal["speech", "vision", "gesture"]
SPEECH: Final = "speech"
VISION: Final = "vision"
GESTURE: Final = "gesture"
MODALITY_NAMES: tuple[Modality, ...] = (SPEECH, VISION, GESTURE)
GESTURES: tuple[str, ...] = get_args(GestureName)
GESTURE_PHASES: tuple[str, ...] = get_args(GesturePhase)
CLARIFICATION_REASONS: tuple[str, ...] = get_args(ClarificationReason)
# What a FusedCommand asks the robot to do: the values its `intent` documents (the field stays a string on the wire)
Intent = Literal[
    "pick_up",
    "bring",
    "put_down",
    "go_to",
    "come_here",
    "stop",
    "look_at",
    "follow",
    "greet",
    "move",
    "turn",  # v1 extension: with FusedCommand.motion
]
INTENTS: tuple[Intent, ...] = get_args(Intent)


def as_intent(word: str) -> Intent:
    """`word` as an Intent; ValueError for one that is not (a language table out of step with the contract)."""
    for intent in INTENTS:
        if intent == word:
            return intent
    raise ValueError(f"{word!r} is not an intent of the contract ({', '.join(INTENTS)})")


# Number and string types of the contract. Every float is finite: a plain `float` would let NaN through,
# so even "any float" is bounded by the largest finite double.
_MAX_FLOAT = 1.7976931348623157e308
Finite = Annotated[float, Meta(ge=-_MAX_FLOAT, le=_MAX_FLOAT)]
UnitFloat = Annotated[float, Meta(ge=0.0, le=1.0)]
UnixTime = Annotated[float, Meta(gt=0.0, le=_MAX_FLOAT)]
NonEmpty = Annotated[str, Meta(min_length=1)]
Point = Annotated[list[Finite], Meta(min_length=2, max_length=2)]
Box = Annotated[list[Finite], Meta(min_length=4, max_length=4)]
Point3 = Annotated[list[Finite], Meta(min_length=3, max_length=3)]
Metres = Annotated[float, Meta(gt=0.0, le=_MAX_FLOAT)]


def described(description: str, **constraints: Any) -> Meta:
    """A field's description for docs/wire.md and the JSON Schemas (and optional extra constraints), written
    `Annotated[type, described("…")]`: an annotation type checkers read, unlike a call."""
    return Meta(description=description, **constraints)


class InvalidSample(ValueError):
    """A payload that breaks the contract. `reason` is a short counter key, `detail` says where."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


# The documented reasons (docs/wire.md). A cross-field rule raises InvalidSample with one of them; msgspec
# keeps its message, so the reason comes back out of the decode error unchanged.
REASONS = (
    "oversized",
    "not_msgpack",
    "not_a_map",
    "missing_field",
    "wrong_type",
    "not_finite",
    "out_of_range",
    "bad_value",
    "bad_version",
)

# msgspec's message -> reason, first match wins. `range` is resolved against the offending value:
# a bound broken by NaN or ±inf is `not_finite`, any other number `out_of_range`.
_ERROR_TABLE: tuple[tuple[re.Pattern[str], str], ...] = (
    (re.compile(r"^(%s): " % "|".join(REASONS)), "own"),
    (re.compile(r"^Object missing required field"), "missing_field"),
    (re.compile(r"^Expected `object`, got `\w+`$"), "not_a_map"),  # the top level only (no path)
    (re.compile(r"^Expected `[^`]+`, got `"), "wrong_type"),
    (re.compile(r"^Invalid enum value"), "bad_value"),
    (re.compile(r"^Expected `\w+` of length"), "bad_value"),
    (re.compile(r"^Expected `(float|int)` [<>]=?"), "range"),
)
_PATH = re.compile(r" - at `(.*)`$")


def _path_parts(path: str) -> list[str | int]:
    """`$.objects[0].bbox[2]` -> ["objects", 0, "bbox", 2]."""
    parts: list[str | int] = []
    for name, index in re.findall(r"\.([^.\[]+)|\[(\d+)\]", path.removeprefix("$")):
        parts.append(name if name else int(index))
    return parts


def _value_at(data: Any, parts: list[str | int]) -> Any:
    """The raw value at a path of a map that failed validation."""
    try:
        for part in parts:
            data = data[part]
        return data
    except (LookupError, TypeError):
        return None


def rejection(error: Exception, payload: bytes | None = None, data: Any = None) -> InvalidSample:
    """Map a msgspec error onto the contract's rejection reasons (the one table, tested). `payload` (what
    was decoded) or `data` (what was converted) lets a broken bound be told apart: NaN/inf vs out of range."""
    if isinstance(error, InvalidSample):
        return error
    if isinstance(error, RecursionError):
        return InvalidSample("not_msgpack", "nested too deeply")
    if not isinstance(error, msgspec.ValidationError):  # DecodeError: truncated, garbage, trailing bytes
        return InvalidSample("not_msgpack", str(error))
    if payload is not None:
        # msgspec validates while it parses: a map that is cut short or followed by garbage can fail a field
        # check first. Malformed MessagePack is reported as such, whatever else is wrong with it.
        import msgpack

        try:
            data = msgpack.unpackb(payload, raw=False, strict_map_key=False)
        except Exception as exc:
            return InvalidSample("not_msgpack", f"{type(exc).__name__}: {exc}")
    text = str(error)
    match = _PATH.search(text)
    path = match.group(1) if match else "$"
    message = text[: match.start()] if match else text
    where = path.removeprefix("$").removeprefix(".")
    for pattern, reason in _ERROR_TABLE:
        found = pattern.search(message)
        if not found:
            continue
        if reason == "own":
            reason, message = found.group(1), message[found.end() :]
        elif reason == "not_a_map" and where:
            reason = "wrong_type"
        elif reason == "range":
            value = _value_at(data, _path_parts(path))
            reason = "not_finite" if isinstance(value, float) and not math.isfinite(value) else "out_of_range"
        return InvalidSample(reason, f"{where}: {message}" if where else message)
    return InvalidSample("invalid", text)


# The one validation path: a sample is packed and decoded with its schema (types, ranges, cross-field rules in
# C and `__post_init__`). It lives here, beside the rules and `rejection()`, so that `Struct.to_dict` needs no
# import of the codec (the codec imports the contract, never the other way round).
_encoder = msgspec.msgpack.Encoder()


@lru_cache(maxsize=None)
def typed_decoder(schema: type) -> msgspec.msgpack.Decoder:
    return msgspec.msgpack.Decoder(schema)


def pack_sample(obj: Struct) -> bytes:
    """`obj` as MessagePack bytes, unchecked. Raises InvalidSample for a value MessagePack has no form for."""
    try:
        return _encoder.encode(obj)
    except (TypeError, OverflowError) as exc:  # np.float32, an int past 64 bits, …
        raise InvalidSample("wrong_type", f"{type(obj).__name__}: {exc}") from None


def unpack_sample(payload: bytes | bytearray | memoryview, schema: type) -> Any:
    """Bytes -> validated `schema` object. Raises InvalidSample, never anything else (no size cap: the codec's)."""
    try:
        return typed_decoder(schema).decode(payload)
    except (msgspec.DecodeError, InvalidSample, RecursionError) as exc:  # ValidationError is a DecodeError
        raise rejection(exc, bytes(payload)) from None
    except Exception as exc:  # a rule's bug must still not escape as a crash
        raise InvalidSample("invalid", f"{type(exc).__name__}: {exc}") from None


def validate(obj: Any) -> Any:
    """`obj` checked against its schema as a receiver would check it (types, ranges, cross-field rules)."""
    return unpack_sample(pack_sample(obj), type(obj))


class Struct(msgspec.Struct, kw_only=True):
    """Base of every wire map: keyword-only, compared by value, extra keys on the wire ignored."""

    @classmethod
    def from_dict(cls, data: Any) -> Any:
        """Validate a decoded msgpack map and build the typed object. Unknown keys are ignored."""
        if type(data) is not dict:
            raise InvalidSample("not_a_map", f"{cls.__name__}: expected a map, got {type(data).__name__}")
        try:
            return msgspec.convert(data, cls)
        except (msgspec.ValidationError, InvalidSample) as exc:
            raise rejection(exc, data=data) from None

    def to_dict(self) -> dict[str, Any]:
        """This object as a plain map (what goes on the wire); validated like a received sample."""
        return msgspec.to_builtins(validate(self), builtin_types=(bytes, bytearray, memoryview))

    @classmethod
    def required_fields(cls) -> tuple[str, ...]:
        return tuple(f.name for f in msgspec.structs.fields(cls) if f.required)


# ---------------------------------------------------------------------------
# Nested maps
# ---------------------------------------------------------------------------
class ColorShare(Struct, kw_only=True):
    """v1 extension: one colour name and how likely a person would call the object that."""

    name: Annotated[NonEmpty, described("a basic colour name (`red`, `brown`, `grey`, …; docs/vision.md lists them)")]
    p: Annotated[UnitFloat, described("probability; the shares of one object sum to at most 1")]


class DetectedObject(Struct, kw_only=True):
    id: Annotated[NonEmpty, described("stable while the object stays in view")]
    label: Annotated[NonEmpty, described("class name, through the command language (`cup`, `person`, …)")]
    color: Annotated[
        Optional[str],
        described(
            "the most likely colour name (`red orange yellow green blue purple white black "
            "grey`, and with the colour model also `brown pink`), or nil"
        ),
    ] = None
    score: Annotated[UnitFloat, described("detection confidence")]
    bbox: Annotated[Box, described("[x, y, w, h] px")]
    center: Annotated[Point, described("[x, y] px")]
    lab: Annotated[
        Optional[Point3],
        described(
            "**v1 extension**: CIELAB (D65) [L 0–100, a, b] of the object's own pixels, "
            "corrected for the scene's illuminant; nil = not measured"
        ),
    ] = None
    colors: Annotated[
        list[ColorShare],
        described("**v1 extension**: the likeliest colour names, best first (at most 5); `color` is the first"),
    ] = msgspec.field(default_factory=list)
    position: Annotated[
        Optional[Point3],
        described(
            "**v1 extension**: [x, y, z] metres in the camera's optical frame "
            "(x right, y down, z forward), from the depth of the object's own "
            "pixels; absent without depth, never zero"
        ),
    ] = None
    extent: Annotated[
        Optional[Point3],
        described("**v1 extension**: [width, height, depth] metres spanned by those pixels; absent without depth"),
    ] = None
    depth_support: Annotated[
        Optional[UnitFloat],
        described("**v1 extension**: share of the object's pixels with a valid depth behind `position`"),
    ] = None

    def check_measurements(self, where: str) -> None:
        """The v1-extension fields' cross-field rules (called by Detections, once per object that has them)."""
        if self.lab is not None:
            if not 0.0 <= self.lab[0] <= 100.0:
                raise InvalidSample("out_of_range", f"{where}.lab: L {self.lab[0]} is outside 0–100")
        if self.position is not None:
            if self.position[2] <= 0.0:
                raise InvalidSample(
                    "bad_value", f"{where}.position: z {self.position[2]} m is not in front of the camera"
                )
        if self.extent is not None:
            if min(self.extent) < 0.0:
                raise InvalidSample("bad_value", f"{where}.extent: a negative size")


class CameraInfo(Struct, kw_only=True):
    """v1 extension: the intrinsics of the image they travel with (Zenoh has no latching, so they come along)."""

    width: Annotated[int, Meta(gt=0), described("px, the resolution `k` belongs to")]
    height: Annotated[int, Meta(gt=0), described("px")]
    k: Annotated[
        list[Finite],
        Meta(min_length=9, max_length=9),
        described("K, 3×3 row-major: [fx, 0, cx, 0, fy, cy, 0, 0, 1] (px)"),
    ]
    distortion_model: Annotated[
        NonEmpty, described("`none`, `plumb_bob` (OpenCV k1 k2 p1 p2 k3), `rational_polynomial`, …")
    ] = "none"
    distortion: Annotated[list[Finite], described("the model's coefficients")] = msgspec.field(default_factory=list)
    frame_id: Annotated[NonEmpty, described("name of the camera's optical frame (x right, y down, z forward, metres)")]

    def __post_init__(self) -> None:
        k = self.k
        if k[0] <= 0.0 or k[4] <= 0.0:
            raise InvalidSample("bad_value", f"k: focal lengths must be > 0 (fx {k[0]}, fy {k[4]})")
        if k[3] != 0.0 or k[6:] != [0.0, 0.0, 1.0]:
            raise InvalidSample("bad_value", "k: not a camera matrix (rows 2 and 3 must be [0, fy, cy] and [0, 0, 1])")

    @property
    def fx(self) -> float:
        return self.k[0]

    @property
    def fy(self) -> float:
        return self.k[4]

    @property
    def cx(self) -> float:
        return self.k[2]

    @property
    def cy(self) -> float:
        return self.k[5]

    def check_size(self, width: int, height: int, what: str = "camera_info") -> None:
        """Intrinsics belong to one resolution: refuse them with an image of another size."""
        if (self.width, self.height) != (width, height):
            raise InvalidSample(
                "bad_value",
                f"{what}: intrinsics are for {self.width}x{self.height}, the image is {width}x{height} "
                f"(scale K with the image, or send the intrinsics of this resolution)",
            )


class ImageQuality(Struct, kw_only=True):
    brightness: Annotated[UnitFloat, described("mean luminance")]
    contrast: Annotated[UnitFloat, described("spread of luminance")]
    sharpness: Annotated[UnitFloat, described("focus / motion blur (1 = sharp)")]


class Ray3D(Struct, kw_only=True):
    """v1 extension: a pointing ray in metres, in a camera's optical frame."""

    origin: Annotated[
        Point3, described("[x, y, z] metres (the eyes for `eye_fingertip`, else the arm's proximal point)")
    ]
    direction: Annotated[Point3, described("unit vector")]
    method: Annotated[
        Ray3DMethod,
        described(
            "`eye_fingertip` (eyes through the index tip, the best cue), `index_finger`, "
            "`forearm` (elbow→wrist), `shoulder_wrist`, `world_landmarks` (MediaPipe's "
            "metric skeleton placed at the torso's depth)"
        ),
    ]
    frame_id: Annotated[NonEmpty, described("the optical frame (CameraInfo.frame_id)")]
    hit: Annotated[
        Optional[Point3],
        described(
            "where the ray meets the surface it points at (a plane fitted to the depth: "
            "floor or table), metres; nil = it meets none"
        ),
    ] = None
    hit_in_view: Annotated[
        Optional[bool],
        described(
            "v1 extension: true = `hit` is inside the image, where the surface is seen; false = outside the "
            "image (the floor or table seen in the image, extended); nil = no hit, or a sender from before"
        ),
    ] = None

    def __post_init__(self) -> None:
        norm = math.sqrt(sum(c * c for c in self.direction))
        if abs(norm - 1.0) > 1e-3:
            raise InvalidSample("bad_value", f"direction: not a unit vector (norm {norm:.4f})")


class Ray(Struct, kw_only=True):
    origin: Annotated[Point, described("[x, y] px")]
    direction: Annotated[Point, described("[dx, dy] unit vector, image axes (x right, y down)")]
    confidence: Annotated[UnitFloat, described("how steady the pointing is, independent of the hand's `score`")] = 1.0
    source: Annotated[
        Optional[RaySource],
        described(
            "**v1 extension**: `hand` = the index finger, `body` = the arm seen by the body stage; "
            "nil = a sender from before the extension (a hand ray)"
        ),
    ] = None
    ray3d: Annotated[Optional[Ray3D], described("**v1 extension**: the same ray in metres, when depth is known")] = None

    def __post_init__(self) -> None:
        norm = math.hypot(*self.direction)
        if not abs(norm - 1.0) <= 1e-3:
            raise InvalidSample("bad_value", f"direction: not a unit vector (norm {norm:.4f})")


class Hand(Struct, kw_only=True):
    hand: Annotated[Handedness, described("which hand, as the person sees it")]
    score: Annotated[UnitFloat, described("landmark confidence")]
    landmarks: Annotated[
        list[Point],
        Meta(min_length=21, max_length=21),
        described("21 × [x, y] px, MediaPipe order (0 wrist, 4 thumb tip, 8 index tip, …)"),
    ]
    gesture: Annotated[Optional[GestureName], described("this frame's raw class, or nil")] = None
    ray: Annotated[Optional[Ray], described("pointing ray, when the hand points")] = None
    person: Annotated[
        Optional[str], described("**v1 extension**: the id of the person whose hand it is (`Persons`), nil = unknown")
    ] = None


class Body(Struct, kw_only=True):
    """One person's MediaPipe Pose skeleton (v1 extension, `Bodies`)."""

    landmarks: Annotated[
        list[Point],
        Meta(min_length=33, max_length=33),
        described("33 × [x, y] px, MediaPipe Pose order (11/12 shoulders, 15/16 wrists, …)"),
    ]
    visibility: Annotated[
        list[UnitFloat],
        Meta(min_length=33, max_length=33),
        described("MediaPipe's visibility of each point; below 0.5 the point is a guess"),
    ]
    left_ray: Annotated[Optional[Ray], described("set when the person's own left arm points (`source` `body`)")] = None
    right_ray: Annotated[Optional[Ray], described("set when the right arm points")] = None
    person: Annotated[
        Optional[str], described("**v1 extension**: the id of the person this skeleton belongs to, nil = unknown")
    ] = None
    pose_age_ms: Annotated[
        Optional[Annotated[float, Meta(ge=0.0, le=_MAX_FLOAT)]],
        described(
            "**v1 extension**: ms of source time since the pose model found this skeleton: it was carried over the "
            "frames between the model's runs (the hands' ends moved with the tracked hands); nil = found on this frame"
        ),
    ] = None


class Face(Struct, kw_only=True):
    """One face in one frame (v1 extension, `Faces`): where it is, how open the mouth is, where it looks."""

    id: Annotated[NonEmpty, described("face track id, stable while the face stays in view (REP-155 face id)")]
    person: Annotated[Optional[str], described("the id of the person the face belongs to, nil = unknown")] = None
    bbox: Annotated[Box, described("[x, y, w, h] px")]
    score: Annotated[UnitFloat, described("face detection confidence")]
    mouth_open: Annotated[
        Optional[Annotated[float, Meta(ge=0.0, le=_MAX_FLOAT)]],
        described("inner-lip gap over mouth width (0 = closed, about 0.5 wide open); nil when the mouth is not seen"),
    ] = None
    yaw: Annotated[
        Optional[Finite], described("degrees, 0 = facing the camera, positive = turned to the image's right")
    ] = None
    pitch: Annotated[Optional[Finite], described("degrees, 0 = level, positive = looking up")] = None
    looking_at_camera: Annotated[
        Optional[bool], described("the face is turned to the camera (the robot), nil when not known")
    ] = None


class Person(Struct, kw_only=True):
    """One person in view (v1 extension, `Persons`), REP-155's person: body, face, hands and voice tied by `id`."""

    id: Annotated[NonEmpty, described("stable across frames while the person is tracked (a new person: a new id)")]
    bbox: Annotated[Box, described("[x, y, w, h] px, the person's whole extent in the image")]
    score: Annotated[UnitFloat, described("how sure the tracker is that this is a person")]
    face: Annotated[Optional[str], described("the id of the person's face (`Faces`), nil when none is seen")] = None
    has_body: Annotated[bool, described("a skeleton of this person is in the `Bodies` of the same frame")] = False
    hands: Annotated[
        list[Handedness], described("which of the person's hands are in the `Hands` of the same frame")
    ] = msgspec.field(default_factory=list)
    position: Annotated[
        Optional[Point3], described("[x, y, z] metres in `frame_id` (with depth): the torso's centre")
    ] = None
    frame_id: Annotated[Optional[str], described("the frame of `position`")] = None
    speaking: Annotated[
        Optional[UnitFloat], described("how likely the person is speaking now, from mouth motion (nil = not known)")
    ] = None
    engaged: Annotated[
        Optional[bool], described("facing the robot (REP-155 engagement: engaged / disengaged), nil when unknown")
    ] = None
    engagement: Annotated[
        Optional[EngagementLevel],
        described(
            '**v1 extension**: the REP-155 engagement level over the last seconds (docs/people.md "Engagement"); '
            "`engaged` is true at `engaged` and `disengaging`"
        ),
    ] = None


class Word(Struct, kw_only=True):
    word: Annotated[str, described("one word as recognised")]
    start: Annotated[Finite, described("source time")]
    end: Annotated[Finite, described("source time, inside the utterance")]
    confidence: UnitFloat
    # start <= end is checked by the Transcript that holds the word: one Python call per sample, not per word


class Target(Struct, kw_only=True):
    """The DetectedObject a command or question is about."""

    id: Annotated[NonEmpty, described("the object's id in its Detections")]
    label: NonEmpty
    color: Optional[str] = None
    bbox: Annotated[Box, described("[x, y, w, h] px")]
    center: Annotated[Point, described("[x, y] px")]
    score: UnitFloat
    cam: Annotated[NonEmpty, described("the camera that saw it")]
    position: Annotated[
        Optional[Point3], described("**v1 extension**: [x, y, z] metres in `frame_id` (camera optical frame)")
    ] = None
    extent: Annotated[Optional[Point3], described("**v1 extension**: [width, height, depth] metres")] = None
    frame_id: Annotated[Optional[str], described("**v1 extension**: the frame of `position`")] = None
    base: Annotated[
        Optional[Point3],
        described(
            "**v1 extension**: `position` in the robot's base frame `base_frame_id` (REP-103: x forward, y left, "
            "z up), from the robot profile's camera mount; nil when the profile places no camera of `frame_id`"
        ),
    ] = None
    base_frame_id: Annotated[
        Optional[str], described("**v1 extension**: the frame of `base` (the mount's `parent`, e.g. `base_link`)")
    ] = None


class Location(Struct, kw_only=True):
    x: Annotated[Finite, described("px")]
    y: Annotated[Finite, described("px")]
    cam: NonEmpty
    position: Annotated[
        Optional[Point3],
        described(
            '**v1 extension**: the place in metres in `frame_id` ("go there": '
            "where the pointing ray meets the floor or table)"
        ),
    ] = None
    frame_id: Annotated[Optional[str], described("**v1 extension**: the frame of `position`")] = None
    base: Annotated[
        Optional[Point3],
        described(
            "**v1 extension**: `position` in the robot's base frame `base_frame_id` (REP-103: x forward, y left, "
            "z up), from the robot profile's camera mount; nil when the profile places no camera of `frame_id`"
        ),
    ] = None
    base_frame_id: Annotated[
        Optional[str], described("**v1 extension**: the frame of `base` (the mount's `parent`, e.g. `base_link`)")
    ] = None


class Motion(Struct, kw_only=True):
    """The robot moving itself ("go forward ten meters", "turn left"): FusedCommand intents `move` and `turn`."""

    direction: Annotated[Optional[MotionDirection], described("the robot's own frame: forward = the way it faces")] = (
        None
    )
    distance: Annotated[
        Optional[Annotated[float, Meta(ge=0.0, le=_MAX_FLOAT)]],
        described("metres; nil = not said (a short move of the planner's choosing)"),
    ] = None
    angle: Annotated[
        Optional[Annotated[float, Meta(ge=0.0, le=_MAX_FLOAT)]],
        described('degrees, for `turn` ("turn left" = 90, "turn around" = 180)'),
    ] = None


class Weights(Struct, kw_only=True):
    """Normalised reliability of each modality for one decision."""

    speech: UnitFloat
    vision: UnitFloat
    gesture: UnitFloat


# ---------------------------------------------------------------------------
# Top-level samples: every one carries v, stamp and source.
# ---------------------------------------------------------------------------
class Sample(Struct, kw_only=True):
    MAX_BYTES: ClassVar[int] = 1 * MIB

    v: Annotated[int, described("schema version, `1`")] = SCHEMA_VERSION
    stamp: Annotated[
        UnixTime,
        described(
            "seconds since the UNIX epoch, **when the observed thing happened** (frame "
            "capture, first audio sample, utterance end)"
        ),
    ]
    source: Annotated[NonEmpty, described("the producing instance, `service/instance`")]

    def __post_init__(self) -> None:
        if self.v != SCHEMA_VERSION:
            raise InvalidSample("bad_version", f"v: v={self.v}, this build speaks v{SCHEMA_VERSION}")
        self._check_sample()

    def _check_sample(self) -> None:
        """Schema-specific cross-field rules (raise InvalidSample)."""


def _check_span(start: float, end: float) -> None:
    """The rule of the samples that span a time (GestureEvent, Transcript)."""
    if not start <= end:
        raise InvalidSample("bad_value", f"start: start {start} is after end {end}")


class Frame(Sample, kw_only=True):
    MAX_BYTES: ClassVar[int] = 64 * MIB
    seq: Annotated[int, Meta(ge=0), described("gap-free per camera process")]
    cam: Annotated[NonEmpty, described("camera id")]
    width: Annotated[int, Meta(gt=0), described("px")]
    height: Annotated[int, Meta(gt=0), described("px")]
    encoding: Annotated[ImageEncoding, described("`bgr8`: raw rows of B,G,R bytes, `width*height*3` bytes")]
    data: Annotated[bytes, described("the image")]
    camera_info: Annotated[
        Optional[CameraInfo], described("**v1 extension**: the colour camera's intrinsics, when known")
    ] = None

    def _check_sample(self) -> None:
        if self.encoding == "bgr8":
            if len(self.data) != self.width * self.height * 3:
                raise InvalidSample(
                    "bad_value", f"data: bgr8 needs {self.width * self.height * 3} bytes, got {len(self.data)}"
                )
        if self.camera_info is not None:
            self.camera_info.check_size(self.width, self.height)


class DepthFrame(Sample, kw_only=True):
    """v1 extension: a depth image aligned to the colour Frame of the same capture (same `stamp` and `seq`),
    so the colour intrinsics apply. 0 (16UC1) or 0/NaN (32FC1) = no measurement."""

    MAX_BYTES: ClassVar[int] = 64 * MIB
    seq: Annotated[int, Meta(ge=0), described("the `seq` of the colour Frame of the same capture")]
    cam: Annotated[NonEmpty, described("camera id (the colour camera it is aligned to)")]
    width: Annotated[int, Meta(gt=0), described("px, equal to the colour frame's")]
    height: Annotated[int, Meta(gt=0), described("px")]
    encoding: Annotated[
        DepthEncoding, described("`16UC1`: unsigned 16-bit little-endian units; `32FC1`: float32 little-endian units")
    ]
    compression: Annotated[
        DepthCompression, described("`none`: raw rows; `png`: a lossless 16-bit PNG (16UC1 only)")
    ] = "none"
    depth_scale: Annotated[
        float,
        Meta(gt=0.0, le=_MAX_FLOAT),
        described(
            "metres per unit, explicit even for 16UC1 (RealSense 0.001, YCB-Video 0.0001, TUM "
            "0.0002; 32FC1 in metres: 1.0)"
        ),
    ]
    camera_info: Annotated[CameraInfo, described("intrinsics of the aligned image (the colour camera's)")]
    data: Annotated[bytes, described("the depth image")]

    def _check_sample(self) -> None:
        self.camera_info.check_size(self.width, self.height)
        if self.compression == "none":
            need = self.width * self.height * (2 if self.encoding == "16UC1" else 4)
            if len(self.data) != need:
                raise InvalidSample(
                    "bad_value",
                    f"data: {self.encoding} {self.width}x{self.height} needs {need} bytes, got {len(self.data)}",
                )
        else:
            if self.encoding != "16UC1":
                raise InvalidSample("bad_value", "compression: png carries 16UC1 depth only")


class AudioChunk(Sample, kw_only=True):
    MAX_BYTES: ClassVar[int] = 4 * MIB
    mic: Annotated[NonEmpty, described("microphone id")]
    rate: Annotated[int, Meta(ge=1000, le=384000), described("Hz")]
    channels: Annotated[int, Meta(ge=1, le=32), described("interleaved")]
    format: Annotated[Literal["s16le"], described("signed 16-bit little endian")]
    data: Annotated[bytes, described("whole frames only")]

    def _check_sample(self) -> None:
        if len(self.data) % (2 * self.channels):
            raise InvalidSample("bad_value", f"data: {len(self.data)} bytes is not whole s16le frames")


class Detections(Sample, kw_only=True):
    MAX_BYTES: ClassVar[int] = 4 * MIB
    seq: Annotated[int, described("of the frame the detections come from")]
    cam: NonEmpty
    width: Annotated[int, described("px, of the frame")]
    height: Annotated[int, described("px, of the frame")]
    objects: Annotated[
        list[DetectedObject],
        described('may be empty: published for **every** processed frame, so "nothing seen" is known'),
    ]
    quality: Annotated[ImageQuality, described("how far to trust this frame (see docs/vision.md)")]
    frame_id: Annotated[
        Optional[str],
        described("**v1 extension**: the optical frame of the objects' `position`s (set when depth was used)"),
    ] = None

    def _check_sample(self) -> None:
        for i, o in enumerate(self.objects):
            if o.lab is not None or o.position is not None or o.extent is not None:
                o.check_measurements(f"objects[{i}]")


class Hands(Sample, kw_only=True):
    seq: Annotated[int, described("of the frame")]
    cam: NonEmpty
    width: Annotated[int, described("px, of the frame")]
    height: Annotated[int, described("px, of the frame")]
    hands: Annotated[list[Hand], described("may be empty; published for every processed frame")]


class Bodies(Sample, kw_only=True):
    """v1 extension: the body stage's skeletons for one frame (an empty list when nobody is seen)."""

    seq: Annotated[int, described("of the frame")]
    cam: NonEmpty
    width: Annotated[int, described("px, of the frame")]
    height: Annotated[int, described("px, of the frame")]
    bodies: Annotated[list[Body], described("may be empty (nobody seen); one per person found")]


class Faces(Sample, kw_only=True):
    """v1 extension: the face stage's faces for one frame (an empty list when none is seen)."""

    seq: Annotated[int, described("of the frame")]
    cam: NonEmpty
    width: Annotated[int, described("px, of the frame")]
    height: Annotated[int, described("px, of the frame")]
    faces: Annotated[list[Face], described("may be empty")]


class Persons(Sample, kw_only=True):
    """v1 extension: the people in view for one frame, each with a stable id (REP-155's tracked persons)."""

    seq: Annotated[int, described("of the frame")]
    cam: NonEmpty
    width: Annotated[int, described("px, of the frame")]
    height: Annotated[int, described("px, of the frame")]
    persons: Annotated[list[Person], described("may be empty (nobody in view)")]


class GestureEvent(Sample, kw_only=True):
    cam: NonEmpty
    width: Annotated[int, described("px, of the frame")]
    height: Annotated[int, described("px, of the frame")]
    gesture: GestureName
    phase: Annotated[GesturePhase, described("`hold` at most every 100 ms while the gesture lasts")]
    start: Annotated[Finite, described("stamp of the gesture's first frame")]
    end: Annotated[Finite, described("stamp of its latest frame (`start ≤ end`)")]
    score: UnitFloat
    hand: Annotated[Handedness, described("the hand that makes it")]
    ray: Annotated[Optional[Ray], described("for `point`")] = None
    person: Annotated[Optional[str], described("**v1 extension**: the id of the person making it, nil = unknown")] = (
        None
    )
    still: Annotated[
        Optional[Annotated[float, Meta(ge=0.0, le=_MAX_FLOAT)]],
        described(
            "**v1 extension**, `open_palm` and `wave`: seconds the hand has been held still with the fingers up and "
            "the palm to the camera, up to this event (0 = not now); nil = not measured"
        ),
    ] = None
    raised: Annotated[
        Optional[bool],
        described("**v1 extension**, `open_palm` and `wave`: the wrist is raised to the shoulder; nil = no skeleton"),
    ] = None

    def _check_sample(self) -> None:
        _check_span(self.start, self.end)


# Word times may stray this far outside their utterance (rounding of the recognisers' frame times).
WORD_TIME_SLACK = 0.05


class Loudness(Struct, kw_only=True):
    """v1 extension (issue #40): the utterance's sound level over time, for telling which visible mouth spoke."""

    start: Annotated[Finite, described("source time of the start of the first step")]
    step: Annotated[float, Meta(gt=0.0, le=0.1), described("seconds per value")]
    db: Annotated[
        list[Annotated[int, Meta(ge=-120, le=0)]],
        Meta(max_length=6000),
        described("RMS level of each step in dB full scale, rounded (-120 = silence)"),
    ]


class Transcript(Sample, kw_only=True):
    mic: Annotated[NonEmpty, described("microphone id")]
    start: Annotated[Finite, described("utterance start, source time (audio clock)")]
    end: Annotated[Finite, described("utterance end; `stamp` = `end`")]
    text: Annotated[str, described("the words as recognised")]
    confidence: Annotated[UnitFloat, described("how sure the recogniser is of the words")]
    words: Annotated[list[Word], described("empty when the backend has no word times")]
    final: Annotated[bool, described("false for a partial result while the person is still speaking")]
    backend: Annotated[NonEmpty, described("the recogniser that produced it")]
    loudness: Annotated[
        Optional[Loudness],
        described("**v1 extension**: the utterance's audio level every `step` s; absent or nil when not measured"),
    ] = None

    def _check_sample(self) -> None:
        _check_span(self.start, self.end)
        lo, hi = self.start - WORD_TIME_SLACK, self.end + WORD_TIME_SLACK
        for i, w in enumerate(self.words):
            if not lo <= w.start <= w.end <= hi:
                raise InvalidSample(
                    "bad_value",
                    f"words[{i}]: {w.word!r} at {w.start}–{w.end} is not a span inside "
                    f"the utterance {self.start}–{self.end}",
                )


class SpeechDecoding(Sample, kw_only=True):
    """v1 extension (issue #42): speech's recogniser started (`decoding` true) or finished (false) decoding an
    utterance; the video services ease their heavy stages meanwhile, so the decode that every word waits for gets
    the cores."""

    mic: Annotated[NonEmpty, described("microphone id")]
    decoding: Annotated[bool, described("true when a decode starts, false when it ends")]


def make_transcript(
    text: str, *, mic: str, end: float, confidence: float, source: str, seconds_per_word: float = 0.3
) -> Transcript:
    """A Transcript as a recogniser would make it, with evenly spaced word times ending at `end` (typed text:
    the speech service's `--backend text`, `hri say`, tests)."""
    tokens = text.split()
    start = end - seconds_per_word * max(len(tokens), 1)
    words = [
        Word(word=w, start=start + i * seconds_per_word, end=start + (i + 1) * seconds_per_word, confidence=confidence)
        for i, w in enumerate(tokens)
    ]
    return Transcript(
        stamp=end,
        source=source,
        mic=mic,
        start=start,
        end=end,
        text=text,
        confidence=confidence,
        words=words,
        final=True,
        backend="text",
    )


class Speaker(Struct, kw_only=True):
    """v1 extension: who said the utterance, and whether it was said to the robot."""

    person: Annotated[Optional[str], described("the speaking person's id (`Persons`), nil = unknown")] = None
    confidence: Annotated[UnitFloat, described("how sure the attribution is (0 when unknown)")]
    method: Annotated[
        SpeakerMethod,
        described("`mouth_motion`: the mouth that moved with the words; `only_face`: one face in view; `unknown`"),
    ]
    addressed: Annotated[
        Optional[bool], described("the speaker faced the robot while speaking; nil when not known")
    ] = None
    reason: Annotated[str, described('why, in words ("two mouths moved equally", …)')] = ""


class FusedCommand(Sample, kw_only=True):
    id: Annotated[NonEmpty, described("deterministic from the inputs: replaying the same samples gives the same id")]
    intent: Annotated[
        NonEmpty,
        described(
            "`pick_up bring put_down go_to come_here stop look_at follow greet move turn` "
            "(`move`, `turn`: v1 extension, with `motion`)"
        ),
    ]
    text: Annotated[Optional[str], described("the utterance (nil for gesture-only commands)")] = None
    target: Annotated[Optional[Target], described("the object meant")] = None
    location: Annotated[Optional[Location], described('a place in the image ("put it there" + pointing)')] = None
    place: Annotated[
        Optional[str], described('a named place ("go to the kitchen": `kitchen`), from `common/language.py`')
    ] = None
    gesture: Annotated[Optional[str], described("the gesture that took part")] = None
    confidence: UnitFloat
    weights: Annotated[Weights, described("normalised reliability of each modality for this decision")]
    inputs: Annotated[dict[str, Optional[Finite]], described("the stamp of each modality's sample used; nil = missing")]
    explanation: Annotated[str, described("why this target won")]
    prompt: Annotated[
        str,
        described(
            "a self-contained text for an LLM planner (command, objects in view with positions, gesture, motion)"
        ),
    ]
    motion: Annotated[Optional[Motion], described("**v1 extension**, for `move` / `turn`; absent or nil otherwise")] = (
        None
    )
    speaker: Annotated[Optional[Speaker], described("**v1 extension**: who said it; absent or nil when not known")] = (
        None
    )


class Clarification(Sample, kw_only=True):
    id: Annotated[NonEmpty, described("deterministic, like a command's")]
    text: Annotated[Optional[str], described("the utterance that needs clarifying")] = None
    reason: ClarificationReason
    question: Annotated[
        NonEmpty, described('a question a person can answer ("Which candy: the red one on the left or …?")')
    ]
    candidates: Annotated[list[Target], described("the objects the question is between")]
    speaker: Annotated[Optional[Speaker], described("**v1 extension**: who said it; absent or nil when not known")] = (
        None
    )


SpokenKind = Literal["question", "refusal", "confirmation", "text"]


class Spoken(Sample, kw_only=True):
    """v1 extension (issue #43): what the robot's voice says and when, published as its audio starts playing
    (`stamp` = `start`). The speech service masks its microphones over [`start`, `end`] plus an echo tail, so the
    robot never hears itself (docs/voice.md)."""

    id: Annotated[NonEmpty, described("this utterance of the robot's (deterministic from what it answers)")]
    text: Annotated[NonEmpty, described("the words spoken")]
    kind: Annotated[
        SpokenKind,
        described("`question` (a clarification), `refusal`, `confirmation` (of a command) or `text` (asked to say)"),
    ]
    answers: Annotated[
        Optional[str], described("the id of the Clarification or FusedCommand it speaks, nil for free text")
    ] = None
    start: Annotated[Finite, described("source time of its first audio sample")]
    end: Annotated[Finite, described("source time just after its last audio sample")]
    speaker: Annotated[NonEmpty, described("the voice's output id: its audio is on `voice/{speaker}/pcm`")]
    voice: Annotated[NonEmpty, described('the synthesiser and voice ("piper:joe")')]

    def _check_sample(self) -> None:
        _check_span(self.start, self.end)


class Stats(Sample, kw_only=True):
    """Reply of a service's stats queryable."""

    service: NonEmpty
    instance: NonEmpty
    uptime: Annotated[Finite, described("seconds")]
    received: Annotated[int, described("samples received")]
    published: Annotated[int, described("samples published")]
    skipped: Annotated[int, described("stale frames replaced by newer ones")]
    rejected: Annotated[dict[str, int], described("invalid samples by reason")]
    other: Annotated[
        dict[str, int], described("service-specific counters, e.g. `undecodable`, `non_command`, `dropped_overflow`")
    ] = msgspec.field(default_factory=dict)


# ---------------------------------------------------------------------------
# v1 extension (the robot, issue #43): its profile (published by fusion) and its state (published by the robot)
# ---------------------------------------------------------------------------
Kilograms = Annotated[float, Meta(gt=0.0, le=_MAX_FLOAT)]


class CameraMount(Struct, kw_only=True):
    """Where the camera sits on the robot: its optical frame in the robot's base frame."""

    parent: Annotated[NonEmpty, described("the robot's frame the camera is fixed to (`base_link`)")]
    frame_id: Annotated[NonEmpty, described("the camera's optical frame (Detections' `frame_id`)")]
    xyz: Annotated[Point3, described("metres: the optical frame's origin in `parent` (REP-103: x forward, z up)")]
    rpy: Annotated[
        Point3,
        described("radians: roll, pitch, yaw of the optical frame in `parent` (a level camera: [-pi/2, 0, -pi/2])"),
    ]


class RobotProfile(Sample, kw_only=True):
    """v1 extension: what this robot can do (docs/robot.md). Fusion publishes it at start and answers queries."""

    name: Annotated[NonEmpty, described("the profile's name (`default`, `tabletop-arm`, …)")]
    description: Annotated[str, described("one line for people")] = ""
    never_grasp: Annotated[
        dict[str, list[NonEmpty]],
        described('classes it never grasps, by the kind a refusal names ("furniture": [`chair`, …])'),
    ]
    max_weight_kg: Annotated[
        Optional[Kilograms], described("the most it lifts; nil = no weight limit (classes and size only)")
    ] = None
    max_size_m: Annotated[Metres, described("the largest visible size it grasps (measured with depth)")]
    weights_kg: Annotated[
        dict[str, Kilograms], described("typical weight of each class (an assumption, docs/robot.md)")
    ] = msgspec.field(default_factory=dict)
    carries: Annotated[bool, described("it can hold an object and hand it over (`bring`)")]
    navigates: Annotated[bool, described("it can move its base (`go_to come_here follow move turn`)")]
    speaks: Annotated[bool, described("it has a voice (questions and refusals are said aloud)")]
    while_busy: Annotated[
        WhileBusy, described("a command while busy: `ask` whether to do it now, or `queue` it until the robot is idle")
    ]
    camera: Annotated[Optional[CameraMount], described("where the camera sits; nil = not said")] = None


class HeldObject(Struct, kw_only=True):
    """What the robot holds."""

    label: Annotated[NonEmpty, described("its class (`cup`)")]
    id: Annotated[Optional[str], described("its object id when it was a command's target (`Target.id`)")] = None
    color: Annotated[Optional[str], described("its colour name, nil = not known")] = None


class RobotState(Sample, kw_only=True):
    """v1 extension: what the robot is doing, published by the robot (or the ROS 2 bridge) when it changes."""

    status: Annotated[RobotStatus, described("`idle`, `busy` (with `command`), `done` or `failed` (with `reason`)")]
    command: Annotated[
        Optional[str], described("the FusedCommand id it works on (busy), finished (done) or gave up (failed)")
    ] = None
    intent: Annotated[Optional[str], described("what it is doing, one of FusedCommand's intents; nil = not said")] = (
        None
    )
    holding: Annotated[Optional[HeldObject], described("what is in its gripper now; nil = nothing")] = None
    reason: Annotated[Optional[str], described('why it failed, in words ("couldn\'t reach it")')] = None

    def _check_sample(self) -> None:
        if self.status == "failed" and not (self.reason or "").strip():
            raise InvalidSample("bad_value", "reason: a failed state says why")


ALL_SAMPLES: tuple[type[Sample], ...] = (
    Frame,
    DepthFrame,
    AudioChunk,
    Detections,
    Hands,
    Bodies,
    Faces,
    Persons,
    GestureEvent,
    Transcript,
    FusedCommand,
    Clarification,
    Spoken,
    Stats,
    RobotProfile,
    RobotState,
    SpeechDecoding,
)
