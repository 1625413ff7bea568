"""Malformed samples for the fuzz test: seeded, so a failure can be replayed.

`Fuzzer(valid).payloads(n)` yields (kind, bytes) made from one valid sample of a schema: random bytes,
truncated msgpack, non-maps, missing and mistyped fields, NaN/inf, huge integers, deep nesting, far-future
and far-past stamps, and for frames wrong-size bgr8, an undecodable JPEG and an image bomb.
"""

from __future__ import annotations

import random
import time
from typing import Any, Iterator

import cv2
import msgpack
import numpy as np

from common.codec import encode
from common.schema import Frame, Sample

U64_MAX = 2**64 - 1
I64_MIN = -(2**63)


def image_bomb() -> bytes:
    """A ~220 kB PNG that decodes to 15000x15000 pixels (225 megapixels)."""
    return cv2.imencode(".png", np.zeros((15000, 15000), np.uint8), [cv2.IMWRITE_PNG_COMPRESSION, 9])[1].tobytes()


def undecodable_jpeg(valid_jpeg: bytes) -> bytes:
    """A JPEG whose headers are intact (so it passes the header check) and whose image data is garbage."""
    sos = valid_jpeg.index(b"\xff\xda")
    return valid_jpeg[:sos] + b"\xff\xda\x00\x0c" + bytes(range(256)) * 8


def nested(depth: int) -> Any:
    value: Any = 1
    for _ in range(depth):
        value = [value]
    return value


class Fuzzer:
    def __init__(self, valid: Sample, seed: int = 0, bomb: bytes | None = None):
        self.valid = valid
        self.map = valid.to_dict()
        self.encoded = encode(valid)
        self.rng = random.Random(seed)
        self.fields = [k for k in self.map if k != "v"]
        self.bomb = bomb

    def _pack(self, d: Any) -> bytes:
        return msgpack.packb(d, use_bin_type=True)

    def _with(self, **changes: Any) -> bytes:
        return self._pack({**self.map, **changes})

    def one(self) -> tuple[str, bytes]:
        """One malformed payload: (its kind, its bytes)."""
        kind = self.rng.choice(KINDS if not isinstance(self.valid, Frame) else KINDS + FRAME_KINDS)
        field = self.rng.choice(self.fields)
        return kind, getattr(self, f"_{kind}")(field, time.time())

    # one method per kind of malformation: (a field of the sample to spoil, now) -> payload
    def _random_bytes(self, field: str, now: float) -> bytes:
        return self.rng.randbytes(self.rng.randint(0, 2000))

    def _truncated(self, field: str, now: float) -> bytes:
        return self.encoded[: self.rng.randint(0, len(self.encoded) - 1)]

    def _not_a_map(self, field: str, now: float) -> bytes:
        return self._pack(self.rng.choice([[1, 2, 3], 42, "frame", None, b"\0" * 10, 1.5, True]))

    def _missing_field(self, field: str, now: float) -> bytes:
        return self._pack({k: v for k, v in self.map.items() if k != field})

    def _wrong_type(self, field: str, now: float) -> bytes:
        return self._with(**{field: self.rng.choice(["x", [], {}, True, None, b"\1", {"a": 1}])})

    def _not_finite(self, field: str, now: float) -> bytes:
        return self._with(stamp=self.rng.choice([float("nan"), float("inf"), float("-inf")]))

    def _huge_int(self, field: str, now: float) -> bytes:
        rng = self.rng
        return self._with(**{rng.choice(["stamp", field]): rng.choice([U64_MAX, I64_MIN, 2**63])})

    def _deep_nesting(self, field: str, now: float) -> bytes:
        rng = self.rng
        return (
            b"\x91" * 100_000 + b"\x01" if rng.random() < 0.5 else self._with(**{field: nested(rng.randint(100, 400))})
        )

    def _far_future(self, field: str, now: float) -> bytes:
        return self._with(stamp=self.rng.choice([1.8e19, now + 3600.0, now + 86400.0 * 365, float(U64_MAX)]))

    def _far_past(self, field: str, now: float) -> bytes:
        return self._with(stamp=self.rng.choice([0.0, -1e9, now - 1e6 * self.rng.random(), 1e-300]))

    # frames only
    def _bgr8_wrong_size(self, field: str, now: float) -> bytes:
        return self._with(encoding="bgr8", data=b"\0" * self.rng.randint(0, 5000))

    def _undecodable_jpeg(self, field: str, now: float) -> bytes:
        return self._with(stamp=now, encoding="jpeg", data=undecodable_jpeg(self.map["data"]))

    def _header_lies(self, field: str, now: float) -> bytes:
        return self._with(stamp=now, width=self.map["width"] + self.rng.randint(1, 50))

    def _image_bomb(self, field: str, now: float) -> bytes:
        big = self.rng.random() < 0.5  # declared as what it is (over the pixel cap) or as a small frame
        return self._with(
            stamp=now,
            encoding="png",
            data=self.bomb,
            width=15000 if big else self.map["width"],
            height=15000 if big else self.map["height"],
        )

    def payloads(self, n: int) -> Iterator[tuple[str, bytes]]:
        for _ in range(n):
            yield self.one()

    def oversized(self) -> bytes:
        return self._with(pad=b"\0" * (type(self.valid).MAX_BYTES + 1))


KINDS = [
    "random_bytes",
    "truncated",
    "not_a_map",
    "missing_field",
    "wrong_type",
    "not_finite",
    "huge_int",
    "deep_nesting",
    "far_future",
    "far_past",
]
FRAME_KINDS = ["bgr8_wrong_size", "undecodable_jpeg", "header_lies", "image_bomb"]
