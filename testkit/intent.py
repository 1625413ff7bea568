"""Real clips through the gesture core and fusion, as the two services run them (issue #40): which gesture-only
commands (stop, come here) a clip gives, and what becomes of utterances placed over it.

`gesture_samples` runs a clip's frames (all of them, or a subset: the frames a loaded service happened to process)
through `GestureCore` and returns the wire samples the gesture service publishes, in order; `run_fusion` feeds them
(and any transcripts, arriving `SPEECH_LAG` s after their end) to `FusionCore` in source time and returns what it
publishes. Stamps are `BASE + i / fps` for frame i of the file, so a subset keeps each frame's own time."""

from __future__ import annotations

import json
import random
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import cv2
import numpy as np

from common.schema import Bodies, Faces, Frame, FusedCommand, GestureEvent, Hands, Persons, Sample, Transcript, Word
from testkit.frames import bgr_frame, read_frames

if TYPE_CHECKING:  # MediaPipe loads with the gesture core: only for callers that run it
    from services.fusion.core import Config
    from services.gesture.core import GestureSettings

BASE = 1_700_000_000.0
PROCESSING = 0.03  # s from a frame's capture to its samples reaching fusion
SPEECH_LAG = 0.3  # s from an utterance's end to its transcript reaching fusion
GESTURE_INTENTS = ("stop", "come_here")


def clip_frames(path: Path, limit: int = 10_000) -> tuple[list[np.ndarray], float]:
    """A clip's frames (BGR, at most `limit`) and its frame rate as OpenCV reads it (GIFs: 0 -> caller's)."""
    cap = cv2.VideoCapture(str(path))
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
    cap.release()
    return read_frames(path, limit), fps


def subset(n: int, kind: str) -> list[int]:
    """The frame indices of a named subset of n frames: `all`, `everyK+O` (every K-th frame from O: `every2+0`,
    `every2+1`, `every3+0`), `random70/S` (70 % of the frames drawn with seed S, in order)."""
    if kind == "all":
        return list(range(n))
    if kind.startswith("every"):  # everyK+O: every K-th frame from O
        step, first = (int(v) for v in kind.removeprefix("every").split("+"))
        return list(range(first, n, step))
    if kind.startswith("random70/"):
        rng = random.Random(int(kind.split("/")[1]))
        return sorted(rng.sample(range(n), round(0.7 * n)))
    raise ValueError(f"unknown frame subset {kind!r}")


def gesture_samples(
    settings: GestureSettings, images: list[np.ndarray], fps: float, keep: list[int] | None = None
) -> list[Sample]:
    """The frames `keep` (default: all) of a clip through the gesture core as one camera's stream: every sample
    the service publishes (Faces, Persons, Hands, Bodies, then the frame's GestureEvents), in order."""
    from services.gesture.core import GestureCore

    event_sample = _event_sample()

    source = "gesture/test"
    core = GestureCore(settings, source, depth_kept=2)
    out: list[Sample] = []
    frame = None
    try:
        for n, k in enumerate(keep if keep is not None else range(len(images))):
            frame = bgr_frame(images[k], k, BASE + k / fps)
            r = core.process(frame, images[k], fresh=n == 0)
            out += [s for s in (r.faces, r.persons, r.hands, r.bodies) if s is not None]
            out += [event_sample(frame, ev, source, r.rays3d, r.hand_rays3d, seen=r.seen) for ev in r.events]
        if frame is not None:  # the stream stops: the shell's idle end
            out += [event_sample(frame, ev, source) for cam in core.cameras.values() for ev in cam.tracker.flush()]
    finally:
        core.close()
    return out


def _event_sample() -> Callable[..., GestureEvent]:
    """The gesture service's own event builder (services/gesture/core.py `event_sample`); for a checkout before it
    existed (benchmarks/intent.py --before), the same fields built here."""
    import services.gesture.core as core

    if hasattr(core, "event_sample"):
        return core.event_sample
    from services.gesture.people_stage import event_person

    def build(
        frame: Frame, ev: Any, source: str, rays3d: Any = None, hand_rays3d: Any = None, seen: Any = None
    ) -> GestureEvent:
        return GestureEvent(
            stamp=frame.stamp,
            source=source,
            cam=frame.cam,
            width=frame.width,
            height=frame.height,
            gesture=ev.gesture,
            phase=ev.phase,
            start=ev.start,
            end=ev.end,
            score=ev.score,
            hand=ev.hand,
            ray=core.to_ray(ev.ray),
            person=event_person(seen, ev.hand, ev.ray),
        )

    return build


def transcript(start: float, end: float, text: str, confidence: float = 0.9) -> Transcript:
    """A final transcript said over [start, end] s of the clip, words spread evenly."""
    tokens = text.split()
    span = (end - start) / max(len(tokens), 1)
    words = [
        Word(word=w, start=BASE + start + i * span, end=BASE + start + (i + 1) * span, confidence=confidence)
        for i, w in enumerate(tokens)
    ]
    return Transcript(
        stamp=BASE + end,
        source="speech/test",
        mic="mic0",
        start=BASE + start,
        end=BASE + end,
        text=text,
        confidence=confidence,
        words=words,
        final=True,
        backend="test",
    )


def _arrival(sample: Sample) -> float:
    return sample.stamp + (SPEECH_LAG if isinstance(sample, Transcript) else PROCESSING)


def run_fusion(samples: list[Sample], transcripts: list[Transcript] = (), config: Config | None = None) -> list[Sample]:  # type: ignore[assignment]
    """The samples (and transcripts) into fusion's core in order of arrival, ticking after each like the service's
    worker; then every deadline expires. Returns what fusion publishes."""
    from services.fusion.core import Config, FusionCore

    core = FusionCore(config or Config(), "fusion/test")
    core.on_liveliness("gesture", "test", True)
    out: list[Sample] = []
    wall_of = 1000.0 - BASE
    feed = sorted([*samples, *transcripts], key=_arrival)
    for s in feed:
        wall = _arrival(s) + wall_of
        outs = []
        if isinstance(s, Transcript):
            outs = core.on_transcript("hri/transcript/mic0", s, wall)
        elif isinstance(s, GestureEvent):
            outs = core.on_gesture_event("hri/gesture/cam0", s, wall)
        elif isinstance(s, Hands):
            outs = core.on_hands("hri/hands/cam0", s, wall)
        elif isinstance(s, Bodies):
            outs = core.on_bodies("hri/bodies/cam0", s, wall)
        elif isinstance(s, Faces):
            outs = core.on_faces("hri/faces/cam0", s, wall)
        elif isinstance(s, Persons):
            outs = core.on_persons("hri/persons/cam0", s, wall)
        out += [o.sample for o in outs] + [o.sample for o in core.tick(wall)]
    last = feed[-1].stamp + wall_of if feed else 1000.0
    out += [o.sample for o in core.tick(last + 100.0)]
    return out


def gesture_commands(outputs: list[Sample]) -> list[tuple[str, float]]:
    """(intent, source time in the clip) of each command a gesture alone gave."""
    return [
        (o.intent, round(o.stamp - BASE, 3))
        for o in outputs
        if isinstance(o, FusedCommand) and o.text is None and o.intent in GESTURE_INTENTS
    ]


@dataclass(frozen=True)
class Clip:
    """One labelled clip of intent.json or talking.json."""

    folder: str
    file: str
    kind: str  # intent.json's kind; "talk" for talking.json's clips
    fps: float
    expect: tuple[str, ...]  # gesture-only commands meant: () none, else alternatives ("come_here|greet")
    utterances: tuple[tuple[float, float, str], ...]  # labelled speech (talking.json): start, end, speaker


def load_clips(shared: Path) -> list[Clip]:
    """The clips of shared/data/intent/intent.json and shared/data/talking/talking.json that are present."""
    clips = []
    intent = shared / "data" / "intent" / "intent.json"
    if intent.exists():
        for c in json.loads(intent.read_text())["clips"]:
            expect = tuple(e.split(" ")[0] for e in c["expect"] if "nothing" not in e)
            clips.append(Clip("intent", c["file"], c["kind"], float(c["fps"]), expect, ()))
    talking = shared / "data" / "talking" / "talking.json"
    if talking.exists():
        for c in json.loads(talking.read_text())["clips"]:
            speech = tuple((float(s["start"]), float(s["end"]), s["speaker"]) for s in c["speech"])
            clips.append(Clip("talking", c["clip"], "talk", float(c["fps"]), (), speech))
    return clips
