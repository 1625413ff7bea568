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
from dataclasses import MISSING, dataclass, field, fields, is_dataclass
from typing import Any, Callable, ClassVar, Literal, Optional, Union, get_args, get_origin, get_type_hints

SCHEMA_VERSION = 1

GESTURES = ("point", "open_palm", "wave", "fist", "thumbs_up")
GESTURE_PHASES = ("start", "hold", "end")
CLARIFICATION_REASONS = ("ambiguous", "conflict", "not_found", "low_confidence")
INTENTS = (
    "pick_up", "bring", "put_down", "go_to", "come_here", "stop", "look_at", "follow", "greet",
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
# Validator compilation. A checker takes (value, path) and returns the value in
# its canonical Python form (floats as float, nested maps as dataclasses), or
# raises InvalidSample.
# ---------------------------------------------------------------------------
Checker = Callable[[Any, str], Any]


def _type_name(value: Any) -> str:
    return type(value).__name__


def _check_int(value: Any, path: str) -> int:
    if type(value) is not int:  # bool is a subclass of int: refuse it explicitly
        raise InvalidSample("wrong_type", f"{path}: expected int, got {_type_name(value)}")
    return value


def _check_float(value: Any, path: str) -> float:
    t = type(value)
    if t is float:
        if not math.isfinite(value):
            raise InvalidSample("not_finite", f"{path}: {value!r} is not a finite number")
        return value
    if t is int:
        return float(value)
    raise InvalidSample("wrong_type", f"{path}: expected number, got {_type_name(value)}")


def _check_str(value: Any, path: str) -> str:
    if type(value) is not str:
        raise InvalidSample("wrong_type", f"{path}: expected str, got {_type_name(value)}")
    return value


def _check_bool(value: Any, path: str) -> bool:
    if type(value) is not bool:
        raise InvalidSample("wrong_type", f"{path}: expected bool, got {_type_name(value)}")
    return value


def _check_bytes(value: Any, path: str) -> bytes:
    if type(value) is bytes:
        return value
    if isinstance(value, (bytearray, memoryview)):
        return bytes(value)
    raise InvalidSample("wrong_type", f"{path}: expected bin, got {_type_name(value)}")


_SCALARS: dict[Any, Checker] = {
    int: _check_int, float: _check_float, str: _check_str, bool: _check_bool, bytes: _check_bytes,
}


def _compile(tp: Any, meta: dict[str, Any] | None = None) -> Checker:
    meta = meta or {}
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        inner = _compile(args[0] if len(args) == 1 else Union[tuple(args)], meta)

        def check_optional(value: Any, path: str) -> Any:
            return None if value is None else inner(value, path)
        return check_optional
    if origin is Literal:
        choices = get_args(tp)

        def check_choice(value: Any, path: str) -> Any:
            if type(value) is not str:
                raise InvalidSample("wrong_type", f"{path}: expected str, got {_type_name(value)}")
            if value not in choices:
                raise InvalidSample("bad_value", f"{path}: {value!r} is not one of {list(choices)}")
            return value
        return check_choice
    if origin is list:
        (item_tp,) = get_args(tp)
        item = _compile(item_tp)
        length = meta.get("length")

        def check_list(value: Any, path: str) -> list:
            if type(value) is not list and type(value) is not tuple:
                raise InvalidSample("wrong_type", f"{path}: expected list, got {_type_name(value)}")
            if length is not None and len(value) != length:
                raise InvalidSample("bad_value", f"{path}: expected {length} items, got {len(value)}")
            return [item(v, f"{path}[{i}]") for i, v in enumerate(value)]
        return check_list
    if origin is dict:
        key_tp, val_tp = get_args(tp)
        key, val = _compile(key_tp), _compile(val_tp)

        def check_dict(value: Any, path: str) -> dict:
            if type(value) is not dict:
                raise InvalidSample("wrong_type", f"{path}: expected map, got {_type_name(value)}")
            return {key(k, f"{path}.<key>"): val(v, f"{path}.{k}") for k, v in value.items()}
        return check_dict
    if isinstance(tp, type) and is_dataclass(tp):
        return lambda value, path: tp.from_dict(value, path)
    base = _SCALARS.get(tp)
    if base is None:
        raise TypeError(f"no wire validator for type {tp!r}")
    rng, nonempty = meta.get("rng"), meta.get("nonempty")
    if rng is not None:
        lo, hi = rng

        def check_range(value: Any, path: str) -> Any:
            value = base(value, path)
            if not lo <= value <= hi:
                raise InvalidSample("out_of_range", f"{path}: {value} is outside [{lo}, {hi}]")
            return value
        return check_range
    if nonempty:
        def check_nonempty(value: Any, path: str) -> Any:
            value = base(value, path)
            if not value:
                raise InvalidSample("bad_value", f"{path}: must not be empty")
            return value
        return check_nonempty
    return base


def _to_wire(value: Any) -> Any:
    if isinstance(value, Struct):
        return value.to_dict()
    if type(value) is list or type(value) is tuple:
        return [_to_wire(v) for v in value]
    if type(value) is dict:
        return {k: _to_wire(v) for k, v in value.items()}
    return value


class Struct:
    """Base of every wire map. Subclasses are `@dataclass(kw_only=True)`."""

    _checkers: ClassVar[tuple[tuple[str, Checker, bool, Any], ...]]
    _names: ClassVar[tuple[str, ...]]

    @classmethod
    def _compile_checkers(cls) -> None:
        hints = get_type_hints(cls)
        specs = []
        for f in fields(cls):  # type: ignore[arg-type]
            required = f.default is MISSING and f.default_factory is MISSING
            default = f.default if f.default is not MISSING else f.default_factory
            specs.append((f.name, _compile(hints[f.name], dict(f.metadata)), required, default))
        cls._checkers = tuple(specs)
        cls._names = tuple(s[0] for s in specs)

    @classmethod
    def from_dict(cls, data: Any, path: str = "") -> Any:
        """Validate a decoded msgpack map and build the typed object. Unknown keys are ignored."""
        if type(data) is not dict:
            raise InvalidSample("not_a_map" if not path else "wrong_type",
                                f"{path or cls.__name__}: expected map, got {_type_name(data)}")
        values = {}
        for fname, check, required, default in cls._checkers:
            if fname in data:
                values[fname] = check(data[fname], f"{path}.{fname}" if path else fname)
            elif required:
                raise InvalidSample("missing_field", f"{path}.{fname}" if path else fname)
            else:
                values[fname] = default() if callable(default) else default
        obj = cls(**values)
        obj._check_invariants(path or cls.__name__)
        return obj

    def _check_invariants(self, path: str) -> None:
        """Cross-field rules; subclasses override."""

    def to_dict(self) -> dict[str, Any]:
        return {n: _to_wire(getattr(self, n)) for n in self._names}


def wire(cls: type) -> type:
    """Class decorator: make a keyword-only dataclass and compile its validator."""
    cls = dataclass(kw_only=True)(cls)
    cls._compile_checkers()
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

    def _check_invariants(self, path: str) -> None:
        norm = math.hypot(*self.direction)
        if abs(norm - 1.0) > 1e-3:
            raise InvalidSample("bad_value", f"{path}.direction: not a unit vector (norm {norm:.4f})")


@wire
class Hand(Struct):
    hand: Literal["left", "right"]
    score: float = unit()
    landmarks: list[list[float]] = vec(21)
    gesture: Optional[Literal["point", "open_palm", "wave", "fist", "thumbs_up"]] = None
    ray: Optional[Ray] = None

    def _check_invariants(self, path: str) -> None:
        for i, point in enumerate(self.landmarks):
            if len(point) != 2:
                raise InvalidSample("bad_value", f"{path}.landmarks[{i}]: expected [x, y]")


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
class Weights(Struct):
    speech: float = unit()
    vision: float = unit()
    gesture: float = unit()


# ---------------------------------------------------------------------------
# Top-level samples: every one carries v, stamp and source.
# ---------------------------------------------------------------------------
class Sample(Struct):
    MAX_BYTES: ClassVar[int] = 1 * MIB

    def _check_invariants(self, path: str) -> None:
        if self.v != SCHEMA_VERSION:
            raise InvalidSample("bad_version", f"v={self.v}, this build speaks v{SCHEMA_VERSION}")
        if self.stamp <= 0:
            raise InvalidSample("out_of_range", f"stamp: {self.stamp} is not a UNIX time")
        self._check_sample(path)

    def _check_sample(self, path: str) -> None:
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

    def _check_sample(self, path: str) -> None:
        if self.width <= 0 or self.height <= 0 or self.seq < 0:
            raise InvalidSample("out_of_range", f"{path}: width/height must be > 0 and seq >= 0")
        if self.encoding == "bgr8" and len(self.data) != self.width * self.height * 3:
            raise InvalidSample(
                "bad_value", f"{path}.data: bgr8 needs {self.width * self.height * 3} bytes, got {len(self.data)}")


@_envelope
class AudioChunk(Sample):
    MAX_BYTES: ClassVar[int] = 4 * MIB
    mic: str = name()
    rate: int
    channels: int
    format: Literal["s16le"]
    data: bytes

    def _check_sample(self, path: str) -> None:
        if not 1000 <= self.rate <= 384000 or not 1 <= self.channels <= 32:
            raise InvalidSample("out_of_range", f"{path}: rate {self.rate} Hz / {self.channels} channels")
        if len(self.data) % (2 * self.channels):
            raise InvalidSample("bad_value", f"{path}.data: {len(self.data)} bytes is not whole s16le frames")


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

    def _check_sample(self, path: str) -> None:
        if self.start > self.end:
            raise InvalidSample("bad_value", f"{path}: start {self.start} is after end {self.end}")


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

    def _check_sample(self, path: str) -> None:
        if self.start > self.end:
            raise InvalidSample("bad_value", f"{path}: start {self.start} is after end {self.end}")


@_envelope
class FusedCommand(Sample):
    id: str = name()
    intent: str = name()
    text: Optional[str] = None
    target: Optional[Target] = None
    location: Optional[Location] = None
    gesture: Optional[str] = None
    confidence: float = unit()
    weights: Weights
    inputs: dict[str, Optional[float]]
    explanation: str
    prompt: str


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
