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
        rng, m = self.rng, self.map
        kind = rng.choice(KINDS if not isinstance(self.valid, Frame) else KINDS + FRAME_KINDS)
        field = rng.choice(self.fields)
        now = time.time()
        if kind == "random_bytes":
            return kind, rng.randbytes(rng.randint(0, 2000))
        if kind == "truncated":
            return kind, self.encoded[: rng.randint(0, len(self.encoded) - 1)]
        if kind == "not_a_map":
            return kind, self._pack(rng.choice([[1, 2, 3], 42, "frame", None, b"\0" * 10, 1.5, True]))
        if kind == "missing_field":
            return kind, self._pack({k: v for k, v in m.items() if k != field})
        if kind == "wrong_type":
            return kind, self._with(**{field: rng.choice(["x", [], {}, True, None, b"\1", {"a": 1}])})
        if kind == "not_finite":
            return kind, self._with(stamp=rng.choice([float("nan"), float("inf"), float("-inf")]))
        if kind == "huge_int":
            return kind, self._with(**{rng.choice(["stamp", field]): rng.choice([U64_MAX, I64_MIN, 2**63])})
        if kind == "deep_nesting":
            return kind, (
                b"\x91" * 100_000 + b"\x01"
                if rng.random() < 0.5
                else self._with(**{field: nested(rng.randint(100, 400))})
            )
        if kind == "far_future":
            return kind, self._with(stamp=rng.choice([1.8e19, now + 3600.0, now + 86400.0 * 365, float(U64_MAX)]))
        if kind == "far_past":
            return kind, self._with(stamp=rng.choice([0.0, -1e9, now - 1e6 * rng.random(), 1e-300]))
        # frames only
        if kind == "bgr8_wrong_size":
            return kind, self._with(encoding="bgr8", data=b"\0" * rng.randint(0, 5000))
        if kind == "undecodable_jpeg":
            return kind, self._with(stamp=now, encoding="jpeg", data=undecodable_jpeg(m["data"]))
        if kind == "header_lies":
            return kind, self._with(stamp=now, width=m["width"] + rng.randint(1, 50))
        if kind == "image_bomb":
            big = rng.random() < 0.5  # declared as what it is (over the pixel cap) or as a small frame
            return kind, self._with(
                stamp=now,
                encoding="png",
                data=self.bomb,
                width=15000 if big else m["width"],
                height=15000 if big else m["height"],
            )
        raise AssertionError(kind)

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
