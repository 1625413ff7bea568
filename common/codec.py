"""MessagePack codec for the wire contract: the one place samples become bytes and back.

Decoding and validation are one step in msgspec's C decoder (a typed decoder per schema, made once; the typed
pack/unpack pair lives in common/schema.py beside the rules it runs). Encoding validates too, by decoding what
it packed: nobody can publish what nobody could read. This module adds the size caps and the untyped reader.
"""

from __future__ import annotations

from typing import Any, TypeVar

import msgpack

from common.schema import InvalidSample, Sample, pack_sample, unpack_sample, validate

ENCODING = "application/msgpack"

S = TypeVar("S", bound=Sample)  # a top-level sample: it has a size cap (MAX_BYTES)

__all__ = ["ENCODING", "decode", "encode", "unpack", "validate"]


def encode(sample: Sample) -> bytes:
    """Validate `sample` against its schema and pack it. Raises InvalidSample if it breaks the contract."""
    payload = pack_sample(sample)
    if len(payload) > sample.MAX_BYTES:
        raise InvalidSample("oversized", f"{len(payload)} bytes > cap {sample.MAX_BYTES} for {type(sample).__name__}")
    unpack_sample(payload, type(sample))
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
    return unpack_sample(payload, schema)
