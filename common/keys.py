"""Key expressions of the wire contract, under a configurable prefix (default `hri`).

Every topic's key pattern is declared once, in common/stack.py TOPICS; `Keys.key(topic, **chunks)` builds them
(the named methods are shorthands). Only the liveliness keys (alive/{service}/{instance}) are not a topic: no
sample is published there."""

from __future__ import annotations

import common.stack as stack
from common.schema import Sample

DEFAULT_PREFIX = "hri"

# What a placeholder of a topic's pattern names, for the error message of a bad chunk.
CHUNK_NAMES = {"cam": "camera id", "mic": "microphone id", "service": "service", "instance": "instance"}


def key_table() -> tuple[tuple[str, type[Sample]], ...]:
    """(path below the prefix with {placeholders}, schema) of every topic of the stack (common/stack.py)."""
    return tuple((t.pattern, t.schema) for t in stack.TOPICS)


KEY_TABLE = key_table()


def check_chunk(value: str, what: str) -> str:
    """A single key chunk: no '/', no wildcard unless it *is* the wildcard."""
    if not value or "/" in value or (value != "*" and any(c in value for c in "*$?#")):
        raise ValueError(f"invalid {what} {value!r}: use a non-empty name without '/', '*', '$', '?', '#'")
    return value


class Keys:
    """Builds the contract's key expressions. Pass '*' for a wildcard chunk."""

    def __init__(self, prefix: str = DEFAULT_PREFIX):
        self.prefix = prefix.strip("/") or DEFAULT_PREFIX

    def _k(self, *chunks: str) -> str:
        return "/".join((self.prefix, *chunks))

    def key(self, topic: str, **chunks: str) -> str:
        """The key of `topic` (a name in common/stack.py TOPICS) with its placeholders filled from `chunks`; a
        placeholder not given is '*'. E.g. key("objects", cam="front") -> 'hri/vision/front/objects'."""
        t = stack.topic(topic)
        unknown = set(chunks) - set(t.placeholders())
        if unknown:
            raise ValueError(f"topic {topic!r} ({t.pattern}) has no placeholder {sorted(unknown)}")
        parts = [
            check_chunk(chunks.get(c[1:-1], "*"), CHUNK_NAMES.get(c[1:-1], c[1:-1])) if c.startswith("{") else c
            for c in t.pattern.split("/")
        ]
        return self._k(*parts)

    def frame(self, cam: str = "*") -> str:
        return self.key("frame", cam=cam)

    def depth(self, cam: str = "*") -> str:
        return self.key("depth", cam=cam)

    def audio(self, mic: str = "*") -> str:
        return self.key("audio", mic=mic)

    def objects(self, cam: str = "*") -> str:
        return self.key("objects", cam=cam)

    def hands(self, cam: str = "*") -> str:
        return self.key("hands", cam=cam)

    def bodies(self, cam: str = "*") -> str:
        return self.key("bodies", cam=cam)

    def faces(self, cam: str = "*") -> str:
        return self.key("faces", cam=cam)

    def persons(self, cam: str = "*") -> str:
        return self.key("persons", cam=cam)

    def gesture_event(self, cam: str = "*") -> str:
        return self.key("event", cam=cam)

    def transcript(self, mic: str = "*") -> str:
        return self.key("transcript", mic=mic)

    def command(self) -> str:
        return self.key("command")

    def clarification(self) -> str:
        return self.key("clarification")

    def robot_state(self) -> str:
        return self.key("robot_state")

    def robot_profile(self) -> str:
        return self.key("robot_profile")

    def alive(self, service: str = "*", instance: str = "*") -> str:
        return self._k("alive", check_chunk(service, "service"), check_chunk(instance, "instance"))

    def stats(self, service: str = "*", instance: str = "*") -> str:
        return self.key("stats", service=service, instance=instance)

    def schema_for(self, key: str) -> type[Sample] | None:
        """The schema published on a concrete key, or None if the key is not in the contract."""
        head = self.prefix + "/"
        if not key.startswith(head):
            return None
        chunks = key[len(head) :].split("/")
        for pattern, schema in key_table():
            parts = pattern.split("/")
            if len(parts) == len(chunks) and all(p.startswith("{") or p == c for p, c in zip(parts, chunks)):
                return schema
        return None

    def parse_alive(self, key: str) -> tuple[str, str] | None:
        """'hri/alive/vision/abc' -> ('vision', 'abc')."""
        head = self.prefix + "/alive/"
        if not key.startswith(head):
            return None
        parts = key[len(head) :].split("/")
        return (parts[0], parts[1]) if len(parts) == 2 else None
