"""MessagePack codec for the wire contract: the one place samples become bytes and back.

Decoding and validation are one step in msgspec's C decoder (a typed decoder per schema, made once).
Encoding validates too, by decoding what it packed: nobody can publish what nobody could read.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, TypeVar

import msgpack
import msgspec

from common.schema import InvalidSample, Sample, Struct, rejection

ENCODING = "application/msgpack"

S = TypeVar("S", bound=Struct)

_encoder = msgspec.msgpack.Encoder()


@lru_cache(maxsize=None)
def _decoder(schema: type) -> msgspec.msgpack.Decoder:
    return msgspec.msgpack.Decoder(schema)


def _pack(obj: Struct) -> bytes:
    try:
        return _encoder.encode(obj)
    except (TypeError, OverflowError) as exc:  # a value of a type MessagePack has no form for (np.float32, …)
        raise InvalidSample("wrong_type", f"{type(obj).__name__}: {exc}") from None


def _unpack_checked(payload: bytes | bytearray | memoryview, schema: type[S]) -> S:
    try:
        return _decoder(schema).decode(payload)
    except (msgspec.DecodeError, InvalidSample, RecursionError) as exc:  # ValidationError is a DecodeError
        raise rejection(exc, bytes(payload)) from None
    except Exception as exc:  # a rule's bug must still not escape as a crash
        raise InvalidSample("invalid", f"{type(exc).__name__}: {exc}") from None


def validate(obj: S) -> S:
    """`obj` checked against its schema as a receiver would check it (types, ranges, cross-field rules)."""
    return _unpack_checked(_pack(obj), type(obj))


def encode(sample: Sample) -> bytes:
    """Validate `sample` against its schema and pack it. Raises InvalidSample if it breaks the contract."""
    payload = _pack(sample)
    if len(payload) > sample.MAX_BYTES:
        raise InvalidSample("oversized", f"{len(payload)} bytes > cap {sample.MAX_BYTES} for {type(sample).__name__}")
    _unpack_checked(payload, type(sample))
    return payload


def unpack(payload: bytes | bytearray | memoryview, max_bytes: int) -> Any:
    """Bytes -> plain msgpack value, with the size cap applied before any parsing (for untyped readers)."""
    if len(payload) > max_bytes:
        raise InvalidSample("oversized", f"{len(payload)} bytes > cap {max_bytes}")
    try:
        return msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # truncated, garbage, extra data, invalid utf-8 ...
        raise InvalidSample("not_msgpack", f"{type(exc).__name__}: {exc}") from None


def decode(payload: bytes | bytearray | memoryview, schema: type[S]) -> S:
    """Bytes -> validated sample of `schema`. Raises InvalidSample, never anything else."""
    if len(payload) > schema.MAX_BYTES:
        raise InvalidSample("oversized", f"{len(payload)} bytes > cap {schema.MAX_BYTES}")
    return _unpack_checked(payload, schema)
