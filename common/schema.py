"""Wire contract v1: the typed samples every service publishes and consumes.

Each schema is a keyword-only dataclass. Its type hints *are* the contract: a
validator is compiled from them once per class, and `common.codec` runs it on
every encode and decode. Field metadata adds ranges (`rng`), fixed lengths
(`length`) and non-empty strings (`nonempty`). docs/wire.md is the prose twin of
this file; change both together.
"""

from __future__ import annotations

import math
import types
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, Callable, ClassVar, Literal, Optional, Union, get_args, get_origin, get_type_hints

SCHEMA_VERSION = 1

GESTURES = ("point", "open_palm", "wave", "fist", "thumbs_up")
GESTURE_PHASES = ("start", "hold", "end")
CLARIFICATION_REASONS = ("ambiguous", "conflict", "not_found", "low_confidence")
INTENTS = (
    "pick_up", "bring", "put_down", "go_to", "come_here", "stop", "look_at", "follow", "greet",
    "move", "turn",  # v1 extension: with FusedCommand.motion
)
MODALITIES = ("speech", "vision", "gesture")

KIB = 1024
MIB = 1024 * KIB


class InvalidSample(ValueError):
    """A payload that breaks the contract. `reason` is a short counter key, `detail` says where."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


def _meta(rng: tuple[float, float] | None = None, length: int | None = None,
          nonempty: bool = False, default: Any = MISSING, default_factory: Any = MISSING) -> Any:
    metadata = {"rng": rng, "length": length, "nonempty": nonempty}
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata=metadata)
    return field(default=default, metadata=metadata)


def unit(**kw: Any) -> Any:
    """A float in [0, 1]."""
    return _meta(rng=(0.0, 1.0), **kw)


def vec(n: int, **kw: Any) -> Any:
    """A fixed-length list of finite numbers."""
    return _meta(length=n, **kw)


def name(**kw: Any) -> Any:
    """A non-empty string."""
    return _meta(nonempty=True, **kw)


# ---------------------------------------------------------------------------
# Validator generation. For each class, Python source is generated from the type
# hints and compiled once: one function that validates a decoded map and builds
# the object, one that validates an object while turning it into a map. The
# success path builds no strings; a failing check raises _Bad, and each enclosing
# level adds its piece of the path on the way out.
# ---------------------------------------------------------------------------
class _Bad(Exception):
    def __init__(self, reason: str, message: str, *path: str):
        self.reason, self.message, self.path = reason, message, list(path)

    def under(self, *prefix: str) -> "_Bad":
        self.path[:0] = prefix
        return self

    def as_invalid(self, root: str) -> InvalidSample:
        where = root
        for part in self.path:
            where = f"{where}{part}" if part.startswith("[") else (f"{where}.{part}" if where else part)
        return InvalidSample(self.reason, f"{where}: {self.message}" if where else self.message)


def _type_name(value: Any) -> str:
    return type(value).__name__


def _bad_type(expected: str, value: Any, *path: str) -> _Bad:
    return _Bad("wrong_type", f"expected {expected}, got {_type_name(value)}", *path)


def _float(x: Any) -> float:
    t = type(x)
    if t is float:
        if x - x != 0.0:  # NaN and ±inf are the only floats for which x - x is not 0
            raise _Bad("not_finite", f"{x!r} is not a finite number")
        return x
    if t is int:
        return float(x)
    raise _bad_type("number", x)


def _floats(x: Any, length: int | None) -> list[float]:
    if type(x) is not list:
        if type(x) is not tuple:
            raise _bad_type("list", x)
        x = list(x)
    if length is not None and len(x) != length:
        raise _Bad("bad_value", f"expected {length} items, got {len(x)}")
    for v in x:  # fast path: all finite floats, nothing to convert
        if type(v) is not float or v - v != 0.0:
            break
    else:
        return x
    out = list(x)
    for i, v in enumerate(out):
        if type(v) is not float or v - v != 0.0:
            try:
                out[i] = _float(v)
            except _Bad as bad:
                raise bad.under(f"[{i}]") from None
    return out


def _points(x: Any, length: int | None) -> list[list[float]]:
    """A list of [x, y] pairs (landmarks): the hot loop of Hands, kept flat."""
    if type(x) is not list and type(x) is not tuple:
        raise _bad_type("list", x)
    if length is not None and len(x) != length:
        raise _Bad("bad_value", f"expected {length} items, got {len(x)}")
    out = []
    append = out.append
    for i, p in enumerate(x):
        if type(p) is list and len(p) == 2:
            a, b = p
            if type(a) is float and type(b) is float and a - a == 0.0 and b - b == 0.0:
                append(p)
                continue
        try:
            append(_floats(p, 2))
        except _Bad as bad:
            raise bad.under(f"[{i}]") from None
    return out


def _items(x: Any, convert: Callable[[Any], Any], length: int | None) -> list:
    if type(x) is not list and type(x) is not tuple:
        raise _bad_type("list", x)
    if length is not None and len(x) != length:
        raise _Bad("bad_value", f"expected {length} items, got {len(x)}")
    out = []
    for i, v in enumerate(x):
        try:
            out.append(convert(v))
        except _Bad as bad:
            raise bad.under(f"[{i}]") from None
    return out


def _mapping(x: Any, key: Callable[[Any], Any], val: Callable[[Any], Any]) -> dict:
    if type(x) is not dict:
        raise _bad_type("map", x)
    out = {}
    for k, v in x.items():
        try:
            out[key(k)] = val(v)
        except _Bad as bad:
            raise bad.under(str(k)) from None
    return out


class _Gen:
    """Emits the check of one value `x` (already bound) for a type, for the decode or encode direction."""

    def __init__(self, encode: bool):
        self.encode = encode
        self.env: dict[str, Any] = {
            "_Bad": _Bad, "_bad_type": _bad_type, "_float": _float, "_floats": _floats, "_points": _points,
            "_items": _items, "_mapping": _mapping, "bytearray": bytearray, "memoryview": memoryview,
        }
        self.n = 0

    def const(self, value: Any) -> str:
        self.n += 1
        name = f"_c{self.n}"
        self.env[name] = value
        return name

    def converter(self, tp: Any) -> str:
        """A name bound to a function converting one value of type `tp`."""
        lines = self.check(tp, {}, "x", "    ")
        self.n += 1
        fname = f"_conv{self.n}"
        src = f"def {fname}(x):\n" + "".join(lines) + "    return x\n"
        exec(src, self.env)
        return fname

    def check(self, tp: Any, meta: dict[str, Any], x: str, ind: str) -> list[str]:
        origin = get_origin(tp)
        if origin in (Union, types.UnionType):
            args = [a for a in get_args(tp) if a is not type(None)]
            inner = self.check(args[0], meta, x, ind + "    ")
            return [f"{ind}if {x} is not None:\n", *inner] if inner else []
        if origin is Literal:
            choices = self.const(frozenset(get_args(tp)))
            listed = self.const(sorted(get_args(tp)))
            return [f"{ind}if type({x}) is not str: raise _bad_type('str', {x})\n",
                    f"{ind}if {x} not in {choices}: raise _Bad('bad_value', f'{{{x}!r}} is not one of {{{listed}}}')\n"]
        length = meta.get("length")
        if origin is list:
            (item,) = get_args(tp)
            if item is float:
                return [f"{ind}{x} = _floats({x}, {length!r})\n"]
            if get_origin(item) is list and get_args(item) == (float,):
                return [f"{ind}{x} = _points({x}, {length!r})\n"]
            return [f"{ind}{x} = _items({x}, {self.converter(item)}, {length!r})\n"]
        if origin is dict:
            key_tp, val_tp = get_args(tp)
            return [f"{ind}{x} = _mapping({x}, {self.converter(key_tp)}, {self.converter(val_tp)})\n"]
        if isinstance(tp, type) and issubclass(tp, Struct):
            cls = self.const(tp)
            if self.encode:
                return [f"{ind}if type({x}) is not {cls}: raise _bad_type({tp.__name__!r}, {x})\n",
                        f"{ind}{x} = {x}._encode_map()\n"]
            return [f"{ind}{x} = {cls}._decode_map({x})\n"]
        lines: list[str]
        if tp is float:
            lines = [f"{ind}if type({x}) is not float or {x} - {x} != 0.0: {x} = _float({x})\n"]
        elif tp is int:
            lines = [f"{ind}if type({x}) is not int: raise _bad_type('int', {x})\n"]
        elif tp is str:
            lines = [f"{ind}if type({x}) is not str: raise _bad_type('str', {x})\n"]
        elif tp is bool:
            lines = [f"{ind}if type({x}) is not bool: raise _bad_type('bool', {x})\n"]
        elif tp is bytes:
            lines = [f"{ind}if type({x}) is not bytes:\n",
                     f"{ind}    if isinstance({x}, (bytearray, memoryview)): {x} = bytes({x})\n",
                     f"{ind}    else: raise _bad_type('bin', {x})\n"]
        else:
            raise TypeError(f"no wire validator for type {tp!r}")
        rng = meta.get("rng")
        if rng is not None:
            lo, hi = rng
            lines.append(f"{ind}if not {lo!r} <= {x} <= {hi!r}: "
                         f"raise _Bad('out_of_range', f'{{{x}}} is outside [{lo}, {hi}]')\n")
        if meta.get("nonempty"):
            lines.append(f"{ind}if not {x}: raise _Bad('bad_value', 'must not be empty')\n")
        return lines


def _generate(cls: type) -> None:
    hints = get_type_hints(cls)
    specs = []
    for f in fields(cls):  # type: ignore[arg-type]
        required = f.default is MISSING and f.default_factory is MISSING
        specs.append((f.name, hints[f.name], dict(f.metadata), required, f))
    cls._names = tuple(s[0] for s in specs)
    cls._required = tuple(s[0] for s in specs if s[3])

    dec = _Gen(encode=False)
    dec.env.update({"_cls": cls, "_new": object.__new__})
    body = ["def _decode_map(data):\n",
            "    if type(data) is not dict: raise _bad_type('map', data)\n",
            "    obj = _new(_cls)\n", "    d = obj.__dict__\n"]
    for fname, tp, meta, required, f in specs:
        body.append(f"    x = data.get({fname!r}, _MISSING)\n")
        body.append("    if x is _MISSING:\n")
        if required:
            body.append(f"        raise _Bad('missing_field', 'required field is missing', {fname!r})\n")
        elif f.default_factory is not MISSING:
            body.append(f"        x = {dec.const(f.default_factory)}()\n")
        else:
            body.append(f"        x = {dec.const(f.default)}\n")
        body.append("    else:\n        try:\n")
        body += dec.check(tp, meta, "x", "            ") or ["            pass\n"]
        body.append(f"        except _Bad as bad: raise bad.under({fname!r}) from None\n")
        body.append(f"    d[{fname!r}] = x\n")
    body.append("    obj._check_invariants()\n    return obj\n")
    dec.env["_MISSING"] = MISSING
    exec("".join(body), dec.env)
    cls._decode_map = staticmethod(dec.env["_decode_map"])

    enc = _Gen(encode=True)
    body = ["def _encode_map(self):\n", "    self._check_invariants()\n", "    d = self.__dict__\n", "    out = {}\n"]
    for fname, tp, meta, _, _ in specs:
        body.append(f"    x = d[{fname!r}]\n    try:\n")
        body += enc.check(tp, meta, "x", "        ") or ["        pass\n"]
        body.append(f"    except _Bad as bad: raise bad.under({fname!r}) from None\n")
        body.append(f"    out[{fname!r}] = x\n")
    body.append("    return out\n")
    exec("".join(body), enc.env)
    cls._encode_map = enc.env["_encode_map"]


class Struct:
    """Base of every wire map. Subclasses are made with `@wire` (keyword-only dataclasses)."""

    _names: ClassVar[tuple[str, ...]]
    _required: ClassVar[tuple[str, ...]]

    @classmethod
    def from_dict(cls, data: Any) -> Any:
        """Validate a decoded msgpack map and build the typed object. Unknown keys are ignored."""
        if type(data) is not dict:
            raise InvalidSample("not_a_map", f"{cls.__name__}: expected a map, got {_type_name(data)}")
        try:
            return cls._decode_map(data)
        except _Bad as bad:
            raise bad.as_invalid("") from None

    def to_dict(self) -> dict[str, Any]:
        """Validate this object and return it as a plain map (what goes on the wire)."""
        try:
            return self._encode_map()
        except _Bad as bad:
            raise bad.as_invalid("") from None

    @classmethod
    def required_fields(cls) -> tuple[str, ...]:
        return cls._required

    def _check_invariants(self) -> None:
        """Cross-field rules; subclasses override and raise _Bad."""

    @staticmethod
    def _decode_map(data: dict) -> Any:  # replaced per class by _generate
        raise NotImplementedError

    def _encode_map(self) -> dict:  # replaced per class by _generate
        raise NotImplementedError


def wire(cls: type) -> type:
    """Class decorator: make a keyword-only dataclass and generate its validators."""
    cls = dataclass(kw_only=True)(cls)
    _generate(cls)
    return cls


# ---------------------------------------------------------------------------
# Nested maps
# ---------------------------------------------------------------------------
@wire
class DetectedObject(Struct):
    id: str = name()
    label: str = name()
    color: Optional[str] = None
    score: float = unit()
    bbox: list[float] = vec(4)  # x, y, w, h in pixels
    center: list[float] = vec(2)


@wire
class ImageQuality(Struct):
    brightness: float = unit()
    contrast: float = unit()
    sharpness: float = unit()


@wire
class Ray(Struct):
    origin: list[float] = vec(2)  # pixels
    direction: list[float] = vec(2)  # unit vector, image axes (x right, y down)
    confidence: float = unit(default=1.0)
    source: Optional[Literal["hand", "body"]] = None  # v1 extension: index finger or arm (None: hand, older senders)

    def _check_invariants(self) -> None:
        norm = math.hypot(*self.direction)
        if abs(norm - 1.0) > 1e-3:
            raise _Bad("bad_value", f"not a unit vector (norm {norm:.4f})", "direction")


@wire
class Hand(Struct):
    hand: Literal["left", "right"]
    score: float = unit()
    landmarks: list[list[float]] = vec(21)
    gesture: Optional[Literal["point", "open_palm", "wave", "fist", "thumbs_up"]] = None
    ray: Optional[Ray] = None


@wire
class Body(Struct):
    """One person's MediaPipe Pose skeleton (v1 extension, `Bodies`)."""
    landmarks: list[list[float]] = vec(33)  # [x, y] px, MediaPipe Pose order (11/12 shoulders, 15/16 wrists)
    visibility: list[float] = vec(33)  # each in [0, 1]
    left_ray: Optional[Ray] = None  # the person's own left arm points: its steadied ray
    right_ray: Optional[Ray] = None

    def _check_invariants(self) -> None:
        if any(not 0.0 <= v <= 1.0 for v in self.visibility):
            raise _Bad("out_of_range", "visibility must be in [0, 1]", "visibility")


@wire
class Word(Struct):
    word: str
    start: float
    end: float
    confidence: float = unit()


@wire
class Target(Struct):
    id: str = name()
    label: str = name()
    color: Optional[str] = None
    bbox: list[float] = vec(4)
    center: list[float] = vec(2)
    score: float = unit()
    cam: str = name()


@wire
class Location(Struct):
    x: float
    y: float
    cam: str = name()


@wire
class Motion(Struct):
    """The robot moving itself ("go forward ten meters", "turn left"): FusedCommand intents `move` and `turn`."""
    direction: Optional[Literal["forward", "back", "left", "right", "around"]] = None
    distance: Optional[float] = None  # metres (>= 0); nil: not said, a small move
    angle: Optional[float] = None  # degrees (>= 0), for turns

    def _check_invariants(self) -> None:
        for name in ("distance", "angle"):
            value = getattr(self, name)
            if value is not None and value < 0:
                raise _Bad("out_of_range", f"{value} is negative", name)


@wire
class Weights(Struct):
    speech: float = unit()
    vision: float = unit()
    gesture: float = unit()


# ---------------------------------------------------------------------------
# Top-level samples: every one carries v, stamp and source.
# ---------------------------------------------------------------------------
class Sample(Struct):
    MAX_BYTES: ClassVar[int] = 1 * MIB

    def _check_invariants(self) -> None:
        if self.v != SCHEMA_VERSION:
            raise _Bad("bad_version", f"v={self.v}, this build speaks v{SCHEMA_VERSION}", "v")
        if not self.stamp > 0:
            raise _Bad("out_of_range", f"{self.stamp} is not a UNIX time", "stamp")
        self._check_sample()

    def _check_sample(self) -> None:
        """Schema-specific cross-field rules."""


def _envelope(cls: type) -> type:
    """Prepend the envelope fields (v, stamp, source) to a top-level sample."""
    ann = {"v": int, "stamp": float, "source": str}
    ann.update(cls.__dict__.get("__annotations__", {}))
    cls.__annotations__ = ann
    cls.v = field(default=SCHEMA_VERSION, metadata={})
    cls.stamp = field(default=MISSING, metadata={})
    cls.source = field(default=MISSING, metadata={"nonempty": True})
    return wire(cls)


@_envelope
class Frame(Sample):
    MAX_BYTES: ClassVar[int] = 64 * MIB
    seq: int
    cam: str = name()
    width: int
    height: int
    encoding: Literal["jpeg", "png", "bgr8"]
    data: bytes

    def _check_sample(self) -> None:
        if self.width <= 0 or self.height <= 0 or self.seq < 0:
            raise _Bad("out_of_range", "width/height must be > 0 and seq >= 0")
        if self.encoding == "bgr8" and len(self.data) != self.width * self.height * 3:
            raise _Bad("bad_value", f"bgr8 needs {self.width * self.height * 3} bytes, got {len(self.data)}", "data")


@_envelope
class AudioChunk(Sample):
    MAX_BYTES: ClassVar[int] = 4 * MIB
    mic: str = name()
    rate: int
    channels: int
    format: Literal["s16le"]
    data: bytes

    def _check_sample(self) -> None:
        if not 1000 <= self.rate <= 384000 or not 1 <= self.channels <= 32:
            raise _Bad("out_of_range", f"rate {self.rate} Hz / {self.channels} channels is not plausible audio")
        if len(self.data) % (2 * self.channels):
            raise _Bad("bad_value", f"{len(self.data)} bytes is not whole s16le frames", "data")


@_envelope
class Detections(Sample):
    MAX_BYTES: ClassVar[int] = 4 * MIB
    seq: int
    cam: str = name()
    width: int
    height: int
    objects: list[DetectedObject]
    quality: ImageQuality


@_envelope
class Hands(Sample):
    seq: int
    cam: str = name()
    width: int
    height: int
    hands: list[Hand]


@_envelope
class Bodies(Sample):
    """v1 extension: the body stage's skeletons for one frame (an empty list when nobody is seen)."""
    seq: int
    cam: str = name()
    width: int
    height: int
    bodies: list[Body]


@_envelope
class GestureEvent(Sample):
    cam: str = name()
    width: int
    height: int
    gesture: Literal["point", "open_palm", "wave", "fist", "thumbs_up"]
    phase: Literal["start", "hold", "end"]
    start: float
    end: float
    score: float = unit()
    hand: Literal["left", "right"]
    ray: Optional[Ray] = None

    def _check_sample(self) -> None:
        if self.start > self.end:
            raise _Bad("bad_value", f"start {self.start} is after end {self.end}", "start")


@_envelope
class Transcript(Sample):
    mic: str = name()
    start: float
    end: float
    text: str
    confidence: float = unit()
    words: list[Word]
    final: bool
    backend: str = name()

    def _check_sample(self) -> None:
        if self.start > self.end:
            raise _Bad("bad_value", f"start {self.start} is after end {self.end}", "start")


@_envelope
class FusedCommand(Sample):
    id: str = name()
    intent: str = name()
    text: Optional[str] = None
    target: Optional[Target] = None
    location: Optional[Location] = None
    place: Optional[str] = None  # a named place of common.language.PLACE_PHRASES ("go to the kitchen")
    gesture: Optional[str] = None
    confidence: float = unit()
    weights: Weights
    inputs: dict[str, Optional[float]]
    explanation: str
    prompt: str
    motion: Optional[Motion] = None  # v1 extension: intents move / turn (docs/wire.md)


@_envelope
class Clarification(Sample):
    id: str = name()
    text: Optional[str] = None
    reason: Literal["ambiguous", "conflict", "not_found", "low_confidence"]
    question: str = name()
    candidates: list[Target]


@_envelope
class Stats(Sample):
    """Reply of a service's stats queryable."""
    service: str = name()
    instance: str = name()
    uptime: float
    received: int
    published: int
    skipped: int
    rejected: dict[str, int]
    other: dict[str, int] = _meta(default_factory=dict)


ALL_SAMPLES: tuple[type[Sample], ...] = (
    Frame, AudioChunk, Detections, Hands, GestureEvent, Transcript, FusedCommand, Clarification, Stats,
)
