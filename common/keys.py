"""Key expressions of the wire contract, under a configurable prefix (default `hri`)."""

from __future__ import annotations

from common.schema import (
    AudioChunk,
    Bodies,
    Clarification,
    DepthFrame,
    Detections,
    Frame,
    FusedCommand,
    GestureEvent,
    Hands,
    Sample,
    Stats,
    Transcript,
)

DEFAULT_PREFIX = "hri"

# (path below the prefix with {placeholders}, schema). The one table of what is published where.
KEY_TABLE: tuple[tuple[str, type[Sample]], ...] = (
    ("camera/{cam}/frame", Frame),
    ("camera/{cam}/depth", DepthFrame),
    ("audio/{mic}/pcm", AudioChunk),
    ("vision/{cam}/objects", Detections),
    ("gesture/{cam}/hands", Hands),
    ("gesture/{cam}/event", GestureEvent),
    ("gesture/{cam}/bodies", Bodies),
    ("speech/{mic}/transcript", Transcript),
    ("fusion/command", FusedCommand),
    ("fusion/clarification", Clarification),
    ("stats/{service}/{instance}", Stats),
)


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

    def frame(self, cam: str = "*") -> str:
        return self._k("camera", check_chunk(cam, "camera id"), "frame")

    def depth(self, cam: str = "*") -> str:
        return self._k("camera", check_chunk(cam, "camera id"), "depth")

    def audio(self, mic: str = "*") -> str:
        return self._k("audio", check_chunk(mic, "microphone id"), "pcm")

    def objects(self, cam: str = "*") -> str:
        return self._k("vision", check_chunk(cam, "camera id"), "objects")

    def hands(self, cam: str = "*") -> str:
        return self._k("gesture", check_chunk(cam, "camera id"), "hands")

    def bodies(self, cam: str = "*") -> str:
        return self._k("gesture", check_chunk(cam, "camera id"), "bodies")

    def gesture_event(self, cam: str = "*") -> str:
        return self._k("gesture", check_chunk(cam, "camera id"), "event")

    def transcript(self, mic: str = "*") -> str:
        return self._k("speech", check_chunk(mic, "microphone id"), "transcript")

    def command(self) -> str:
        return self._k("fusion", "command")

    def clarification(self) -> str:
        return self._k("fusion", "clarification")

    def alive(self, service: str = "*", instance: str = "*") -> str:
        return self._k("alive", check_chunk(service, "service"), check_chunk(instance, "instance"))

    def stats(self, service: str = "*", instance: str = "*") -> str:
        return self._k("stats", check_chunk(service, "service"), check_chunk(instance, "instance"))

    def schema_for(self, key: str) -> type[Sample] | None:
        """The schema published on a concrete key, or None if the key is not in the contract."""
        head = self.prefix + "/"
        if not key.startswith(head):
            return None
        chunks = key[len(head) :].split("/")
        for pattern, schema in KEY_TABLE:
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
