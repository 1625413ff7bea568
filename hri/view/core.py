"""What `hri view` knows: cameras, a timeline in source time, services. Pure: fed decoded-or-not payloads.

Every payload is validated against the contract here; one that does not decode is counted per key and
reason and dropped, so a malformed sample never reaches the page. Frames are kept latest-only and released
to the page at most `max_fps` per camera; a JPEG frame is passed through as is, other encodings are
re-encoded to JPEG once per released frame.
"""

from __future__ import annotations

import bisect
import collections
import itertools
import threading
from dataclasses import dataclass, field
from typing import Any

import cv2

from common.codec import decode
from common.image import UndecodableFrame, frame_image
from common.keys import Keys
from common.schema import (
    Clarification,
    DepthFrame,
    Detections,
    Frame,
    FusedCommand,
    GestureEvent,
    Hands,
    InvalidSample,
    Persons,
    Sample,
    Stats,
    Transcript,
)
from hri.view import DEFAULT_MAX_FPS

TIMELINE_MAX = 500  # entries kept; the oldest go first
# Caps on what a stream of odd keys could make the server remember (memory stays bounded whatever arrives).
MAX_CAMERAS = 32
MAX_SERVICES = 256
MAX_IGNORED_KEYS = 100
OTHER_KEYS = "(other keys)"
JPEG_QUALITY = 85


@dataclass
class ShownFrame:
    """A frame as the page gets it: JPEG bytes and where it came from."""

    seq: int
    stamp: float
    width: int
    height: int
    jpeg: bytes
    n: int  # release counter of this camera: the page asks for "a frame newer than n"


@dataclass
class CameraState:
    cam: str
    pending: Frame | None = None  # newest frame not yet released (latest-only)
    shown: ShownFrame | None = None
    released_at: float = float("-inf")
    received: int = 0
    released: int = 0
    detections: Detections | None = None
    hands: Hands | None = None
    persons: Persons | None = None  # people in view with their ids (issue #33)
    depth: DepthFrame | None = None  # latest; colourized only when the page asks (the depth toggle)
    depth_jpeg: tuple[int, float, bytes] | None = None  # (seq, stamp, JPEG) of the last colourized one


# the samples of which a camera keeps the latest, and the CameraState field that holds it
LATEST_PER_CAMERA: dict[type, str] = {Detections: "detections", Hands: "hands", DepthFrame: "depth", Persons: "persons"}


@dataclass
class ServiceState:
    service: str
    instance: str
    alive: bool | None = None  # None: unknown (recording mode, or only seen through samples)
    stats: dict[str, Any] | None = None
    last_sample: float | None = None  # stamp of the newest sample it published


@dataclass
class ViewState:
    """The model behind the page. Thread-safe: zenoh callbacks ingest, web handlers read."""

    keys: Keys = field(default_factory=Keys)
    max_fps: float = DEFAULT_MAX_FPS
    timeline_max: int = TIMELINE_MAX

    def __post_init__(self) -> None:
        self.lock = threading.RLock()
        self.reset()

    def reset(self) -> None:
        """Forget everything seen (a recording seeks backwards); `epoch` tells the page to start over."""
        with self.lock:
            self.epoch = getattr(self, "epoch", 0) + 1
            self.version = 0
            self.cameras: dict[str, CameraState] = {}
            self.timeline: list[tuple[float, int, dict[str, Any]]] = []  # (stamp, n, entry), sorted
            self._entry_n = itertools.count(1)
            self.command: FusedCommand | None = None
            self.clarification: Clarification | None = None
            self.services: dict[tuple[str, str], ServiceState] = {}
            self.ignored: collections.Counter[tuple[str, str]] = collections.Counter()
            self.last_stamp: float | None = None

    # -- input ----------------------------------------------------------------
    def ingest(self, key: str, payload: bytes, now: float) -> bool:
        """Validate and take in one sample; False if it was ignored (and counted)."""
        schema = self.keys.schema_for(key)
        if schema is None:
            return self.ignore(key, "not_in_contract")
        try:
            sample = decode(payload, schema)
        except InvalidSample as exc:
            return self.ignore(key, exc.reason)
        with self.lock:
            cam = getattr(sample, "cam", None)
            if cam is not None and cam not in self.cameras and len(self.cameras) >= MAX_CAMERAS:
                return self.ignore(key, "too_many_cameras")
            self._take(sample, now)
            self.last_stamp = sample.stamp if self.last_stamp is None else max(self.last_stamp, sample.stamp)
            self._seen(sample)
            self.version += 1
        return True

    def ignore(self, key: str, reason: str) -> bool:
        with self.lock:
            if (key, reason) not in self.ignored and len(self.ignored) >= MAX_IGNORED_KEYS:
                key = OTHER_KEYS
            self.ignored[(key, reason)] += 1
            self.version += 1
        return False

    def _camera(self, cam: str) -> CameraState:
        state = self.cameras.get(cam)
        if state is None:
            state = self.cameras[cam] = CameraState(cam)
        return state

    def _seen(self, sample: Sample) -> None:
        if isinstance(sample, Stats):
            return
        service, _, instance = sample.source.partition("/")
        entry = self.services.get((service, instance or "-"))
        if entry is None:
            if len(self.services) >= MAX_SERVICES:
                return
            entry = self.services[(service, instance or "-")] = ServiceState(service, instance or "-")
        entry.last_sample = sample.stamp if entry.last_sample is None else max(entry.last_sample, sample.stamp)

    def _take(self, sample: Sample, now: float) -> None:
        if isinstance(sample, Frame):
            cam = self._camera(sample.cam)
            cam.received += 1
            cam.pending = sample
            self._release(cam, now)
        elif isinstance(sample, (Detections, Hands, DepthFrame, Persons)):  # the latest of each is drawn
            setattr(self._camera(sample.cam), LATEST_PER_CAMERA[type(sample)], sample)
        elif isinstance(sample, GestureEvent):
            if sample.phase == "start":  # "hold" comes every 100 ms; the start is the event a person sees
                self._add_entry(
                    sample.stamp,
                    {
                        "kind": "gesture",
                        "gesture": sample.gesture,
                        "hand": sample.hand,
                        "cam": sample.cam,
                        "score": sample.score,
                        "source": sample.source,
                    },
                )
        elif isinstance(sample, Transcript):
            if sample.final:
                self._add_entry(
                    sample.stamp,
                    {
                        "kind": "transcript",
                        "text": sample.text,
                        "confidence": sample.confidence,
                        "mic": sample.mic,
                        "backend": sample.backend,
                        "source": sample.source,
                    },
                )
        elif isinstance(sample, FusedCommand):
            if self.command is None or sample.stamp >= self.command.stamp:
                self.command = sample
            self._add_entry(sample.stamp, {"kind": "command", **_plain(sample)})
        elif isinstance(sample, Clarification):
            if self.clarification is None or sample.stamp >= self.clarification.stamp:
                self.clarification = sample
            self._add_entry(sample.stamp, {"kind": "clarification", **_plain(sample)})
        elif isinstance(sample, Stats):
            self.set_stats(sample)

    def _add_entry(self, stamp: float, entry: dict[str, Any]) -> None:
        n = next(self._entry_n)
        entry = {"n": n, "t": stamp, **entry}
        bisect.insort(self.timeline, (stamp, n, entry), key=lambda e: (e[0], e[1]))
        if len(self.timeline) > self.timeline_max:
            del self.timeline[0]

    # -- frames -----------------------------------------------------------------
    def _release(self, cam: CameraState, now: float, force: bool = False) -> bool:
        """Promote the pending frame to the shown one if the camera's frame budget allows."""
        if cam.pending is None or (not force and now - cam.released_at < 1.0 / self.max_fps):
            return False
        frame, cam.pending = cam.pending, None
        try:
            jpeg = jpeg_of(frame)
        except UndecodableFrame:
            self.ignore(self.keys.frame(frame.cam), "undecodable")
            return False
        cam.released += 1
        cam.released_at = now
        cam.shown = ShownFrame(frame.seq, frame.stamp, frame.width, frame.height, jpeg, cam.released)
        return True

    def tick(self, now: float, force: bool = False) -> list[str]:
        """Release frames whose budget has come (the last frame of a burst must not wait for a next one)."""
        with self.lock:
            released = [c.cam for c in self.cameras.values() if self._release(c, now, force)]
            if released:
                self.version += 1
            return released

    def frame(self, cam: str) -> ShownFrame | None:
        with self.lock:
            state = self.cameras.get(cam)
            return state.shown if state else None

    def depth_picture(self, cam: str) -> tuple[int, float, bytes] | None:
        """(seq, stamp, JPEG) of the camera's latest depth frame colourized (near red, far blue, none black);
        None without depth, or when it does not decode (counted)."""
        with self.lock:
            state = self.cameras.get(cam)
            depth = state.depth if state else None
            if state is None or depth is None:
                return None
            if state.depth_jpeg is not None and state.depth_jpeg[:2] == (depth.seq, depth.stamp):
                return state.depth_jpeg
        from common.depth import UndecodableDepth, depth_metres
        from hri.view.draw import colourize_depth

        try:
            picture = colourize_depth(depth_metres(depth))
        except UndecodableDepth:
            self.ignore(self.keys.depth(cam), "undecodable")
            return None
        ok, buf = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            return None
        with self.lock:
            state.depth_jpeg = (depth.seq, depth.stamp, buf.tobytes())
            return state.depth_jpeg

    # -- services ---------------------------------------------------------------
    def set_alive(self, service: str, instance: str, alive: bool) -> None:
        with self.lock:
            entry = self.services.setdefault((service, instance), ServiceState(service, instance))
            entry.alive = alive
            self.version += 1

    def set_stats(self, stats: Stats) -> None:
        with self.lock:
            entry = self.services.setdefault(
                (stats.service, stats.instance), ServiceState(stats.service, stats.instance)
            )
            entry.stats = {k: v for k, v in stats.to_dict().items() if k not in ("v", "source", "service", "instance")}
            self.version += 1

    # -- output -----------------------------------------------------------------
    def overlay(self, cam: str) -> dict[str, Any]:
        """What is drawn over a camera's frame: each layer is a plain map (same for page and snapshot)."""
        with self.lock:
            state = self.cameras.get(cam)
            det = state.detections if state else None
            hands = state.hands if state else None
            layers: dict[str, Any] = {
                "objects": [o.to_dict() for o in det.objects] if det else [],
                "quality": det.quality.to_dict() if det else None,
                "objects_seq": det.seq if det else None,
                "hands": [h.to_dict() for h in hands.hands] if hands else [],
                "persons": persons_layer(state.persons if state else None, self.command, self.clarification),
                "target": None,
                "candidates": [],
            }
            # the newer of the latest command and clarification decides what is highlighted
            command, question = self.command, self.clarification
            if command is not None and (question is None or command.stamp >= question.stamp):
                if command.target is not None and command.target.cam == cam:
                    layers["target"] = {**command.target.to_dict(), "intent": command.intent}
                if command.location is not None and command.location.cam == cam:
                    layers["location"] = command.location.to_dict()
            elif question is not None:
                layers["candidates"] = [c.to_dict() for c in question.candidates if c.cam == cam]
            return layers

    def snapshot(self, after_n: int = 0) -> dict[str, Any]:
        """The page's view of the state; timeline entries after `after_n` only (the page keeps the rest)."""
        with self.lock:
            cameras = {}
            for cam, state in sorted(self.cameras.items()):
                shown = state.shown
                cameras[cam] = {
                    "frame": None
                    if shown is None
                    else {
                        "n": shown.n,
                        "seq": shown.seq,
                        "stamp": shown.stamp,
                        "width": shown.width,
                        "height": shown.height,
                    },
                    "received": state.received,
                    "released": state.released,
                    "depth": None if state.depth is None else {"seq": state.depth.seq, "stamp": state.depth.stamp},
                    **self.overlay(cam),
                }
            ignored: dict[str, dict[str, int]] = {}
            for (key, reason), count in sorted(self.ignored.items()):
                ignored.setdefault(key, {})[reason] = count
            return {
                "epoch": self.epoch,
                "version": self.version,
                "last_stamp": self.last_stamp,
                "cameras": cameras,
                "timeline": [entry for _, n, entry in self.timeline if n > after_n],
                "services": [
                    {
                        "service": s.service,
                        "instance": s.instance,
                        "alive": s.alive,
                        "stats": s.stats,
                        "last_sample": s.last_sample,
                    }
                    for _, s in sorted(self.services.items())
                ],
                "ignored": ignored,
                "ignored_total": sum(self.ignored.values()),
            }


SPEAKER_SHOWN_S = 3.0  # source seconds a decided utterance's speaker stays marked after it was said
SPEAKING = 0.5  # `Person.speaking` at least this: marked as talking now (the face stage's mouth motion)


def persons_layer(
    persons: Persons | None, command: FusedCommand | None, question: Clarification | None
) -> list[dict[str, Any]]:
    """The persons of a camera, each marked `speaking` while their mouth moves with speech (`Person.speaking`) or
    for a few seconds after fusion attributed an utterance to them (`speaker` of the latest command/question)."""
    if persons is None:
        return []
    said = [s for s in (command, question) if s is not None and s.speaker is not None and s.speaker.person]
    recent = {
        s.speaker.person for s in said if s.speaker is not None and abs(persons.stamp - s.stamp) <= SPEAKER_SHOWN_S
    }
    return [
        {**p.to_dict(), "speaker": p.id in recent or (p.speaking is not None and p.speaking >= SPEAKING)}
        for p in persons.persons
    ]


def _plain(sample: Sample) -> dict[str, Any]:
    out = sample.to_dict()
    out.pop("v", None)
    return out


def jpeg_of(frame: Frame) -> bytes:
    """JPEG bytes of a frame: passed through when already JPEG, re-encoded otherwise."""
    if frame.encoding == "jpeg":
        return frame.data
    ok, buf = cv2.imencode(".jpg", frame_image(frame), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise UndecodableFrame(f"OpenCV could not re-encode a {frame.encoding} frame as JPEG")
    return buf.tobytes()
