"""MessagePack codec for the wire contract: the one place samples become bytes and back."""

from __future__ import annotations

from typing import Any, TypeVar

import msgpack

from common.schema import InvalidSample, Sample

ENCODING = "application/msgpack"

S = TypeVar("S", bound=Sample)


def encode(sample: Sample) -> bytes:
    """Validate `sample` against its schema and pack it. Raises InvalidSample if it breaks the contract."""
    data = sample.to_dict()  # validates: nobody can publish what nobody could read
    payload = msgpack.packb(data, use_bin_type=True)
    if len(payload) > sample.MAX_BYTES:
        raise InvalidSample("oversized", f"{len(payload)} bytes > cap {sample.MAX_BYTES} for {type(sample).__name__}")
    return payload


def unpack(payload: bytes | bytearray | memoryview, max_bytes: int) -> Any:
    """Bytes -> plain msgpack value, with the size cap applied before any parsing."""
    if len(payload) > max_bytes:
        raise InvalidSample("oversized", f"{len(payload)} bytes > cap {max_bytes}")
    try:
        return msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except Exception as exc:  # truncated, garbage, extra data, invalid utf-8 ...
        raise InvalidSample("not_msgpack", f"{type(exc).__name__}: {exc}") from None


def decode(payload: bytes | bytearray | memoryview, schema: type[S]) -> S:
    """Bytes -> validated sample of `schema`. Raises InvalidSample, never anything else."""
    data = unpack(payload, schema.MAX_BYTES)
    try:
        return schema.from_dict(data)
    except InvalidSample:
        raise
    except Exception as exc:  # a validator bug must still not escape as a crash
        raise InvalidSample("invalid", f"{type(exc).__name__}: {exc}") from None
