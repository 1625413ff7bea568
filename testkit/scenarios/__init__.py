"""The fusion scenario suite as data: timed input samples and the expected outcome.

A scenario is a list of steps in *publish order*; each step carries its own source time
(seconds relative to the scenario's base stamp), so out-of-order delivery is just a
different publish order. `expect` lists the outcomes the fusion service must publish
(commands and clarifications, in order), and nothing else.

`run_in_process()` drives `FusionCore` directly (used by the unit tests and by
benchmarks/fusion_eval.py); tests/test_fusion_scenarios.py publishes the same samples over Zenoh
to the real process.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

from common.keys import Keys
from common.language import canonical_label
from common.schema import (
    Bodies,
    Clarification,
    DetectedObject,
    Detections,
    FusedCommand,
    GestureEvent,
    GestureName,
    GesturePhase,
    Hand,
    Handedness,
    Hands,
    ImageQuality,
    Ray,
    RobotState,
    Sample,
    Spoken,
    Transcript,
    Word,
)
from services.fusion.ground import SceneObject

if TYPE_CHECKING:  # fusion's core is imported where it runs (run_in_process), not by every scenario user
    from services.fusion.core import FusionCore
    from services.fusion.outputs import Output

BASE_STAMP = 1_700_000_000.0
SCENARIO_SPACING = 200.0  # s of source time between scenarios run in one process
W, H = 640, 480
KEYS = Keys("hri")
GOOD = (0.55, 0.5, 0.6)  # brightness, contrast, sharpness of a well-lit frame
DARK = (0.04, 0.05, 0.1)


@dataclass(frozen=True)
class Obj:
    id: str
    label: str
    color: str | None
    center: tuple[float, float]
    size: tuple[float, float] = (60.0, 80.0)
    score: float = 0.9

    def detected(self) -> DetectedObject:
        w, h = self.size
        return DetectedObject(
            id=self.id,
            label=self.label,
            color=self.color,
            score=self.score,
            bbox=[self.center[0] - w / 2, self.center[1] - h / 2, w, h],
            center=list(self.center),
        )


def scene_of(objs: list[Obj], quality: float = 1.0) -> list[SceneObject]:
    """The objects as grounding sees them (camera `cam0`, 640x480, at BASE_STAMP), for unit tests of ground.py."""
    return [
        SceneObject(
            o.id,
            canonical_label(o.label),
            o.label,
            o.color,
            bbox_of(o.detected()),
            o.center,
            o.score,
            "cam0",
            640,
            480,
            BASE_STAMP,
            quality,
        )
        for o in objs
    ]


@dataclass
class Step:
    t: float  # source time relative to the scenario base
    build: Callable[[float], tuple[str, Sample]]
    what: str = ""


@dataclass
class Expect:
    kind: str  # "command" or "clarification"
    intent: str | None = None
    target: str | None = None  # expected target id (None: no target)
    reason: str | None = None  # clarification reason
    location: bool = False  # a Location is expected
    candidates: tuple[str, ...] | None = None  # clarification candidate ids (as a set)
    motion: tuple[str | None, float | None, float | None] | None = None  # (direction, metres, degrees) if given
    question: str | None = None  # a clarification's question must contain this
    among: tuple[str, ...] | None = None  # clarification candidates: at least two, all of these ids

    def matches(self, sample: Any) -> bool:
        return not self.mismatch(sample)

    def mismatch(self, sample: Any) -> str:
        """What in `sample` is not as expected ("" when it matches)."""
        if self.kind == "command":
            return self._command_mismatch(sample)
        return self._clarification_mismatch(sample)

    def _command_mismatch(self, sample: Any) -> str:
        if not isinstance(sample, FusedCommand):
            return f"expected a command, got {describe(sample)}"
        if sample.intent != self.intent:
            return f"intent {sample.intent} != {self.intent}"
        got = sample.target.id if sample.target else None
        if got != self.target:
            return f"target {got} != {self.target}"
        if self.location != (sample.location is not None):
            return f"location {sample.location} (expected {'one' if self.location else 'none'})"
        if self.motion is not None:
            m = sample.motion
            got_motion = (m.direction, m.distance, m.angle) if m is not None else None
            if got_motion != self.motion:
                return f"motion {got_motion} != {self.motion}"
        return ""

    def _clarification_mismatch(self, sample: Any) -> str:
        if not isinstance(sample, Clarification):
            return f"expected a clarification ({self.reason}), got {describe(sample)}"
        if sample.reason != self.reason:
            return f"reason {sample.reason} != {self.reason}"
        if self.candidates is not None and {c.id for c in sample.candidates} != set(self.candidates):
            return f"candidates {[c.id for c in sample.candidates]} != {list(self.candidates)}"
        got_ids = {c.id for c in sample.candidates}
        if self.among is not None and (len(got_ids) < 2 or not got_ids <= set(self.among)):
            return f"candidates {sorted(got_ids)} are not two or more of {list(self.among)}"
        if self.question is not None and self.question not in sample.question:
            return f"question {sample.question!r} does not say {self.question!r}"
        return ""


def describe(sample: Any) -> str:
    if isinstance(sample, FusedCommand):
        return f"command {sample.intent} -> {sample.target.id if sample.target else None} ({sample.explanation})"
    if isinstance(sample, Clarification):
        return f"clarification {sample.reason}: {sample.question}"
    return repr(sample)


@dataclass
class Scenario:
    name: str
    steps: list[Step]
    expect: list[Expect]
    tags: tuple[str, ...] = ()
    config: dict[str, Any] = field(default_factory=dict)  # Config overrides (run in their own process)

    def samples(self, base: float) -> list[tuple[str, Sample]]:
        return [s.build(base) for s in self.steps]


# ---------------------------------------------------------------------------
# Sample builders. Each returns a Step; times are relative to the scenario base.
# ---------------------------------------------------------------------------
def say(
    start: float,
    end: float,
    text: str,
    conf: float = 0.92,
    mic: str = "mic0",
    word_conf: float | None = None,
    final: bool = True,
    lag: float = 0.2,
) -> Step:
    """A final transcript; words spread evenly over [start, end]; published `lag` s after the end."""

    def build(base: float) -> tuple[str, Sample]:
        tokens = text.split()
        span = (end - start) / max(len(tokens), 1)
        words = [
            Word(
                word=w.strip(",.!?"),
                start=base + start + i * span,
                end=base + start + (i + 1) * span,
                confidence=word_conf if word_conf is not None else conf,
            )
            for i, w in enumerate(tokens)
        ]
        return KEYS.transcript(mic), Transcript(
            stamp=base + end + lag,
            source=f"speech/{mic}",
            mic=mic,
            start=base + start,
            end=base + end,
            text=text,
            confidence=conf,
            words=words,
            final=final,
            backend="test",
        )

    return Step(end + lag, build, f"say {text!r}")


def detections_at(
    t: float,
    objects: list[DetectedObject],
    quality: ImageQuality,
    width: int = W,
    height: int = H,
    cam: str = "cam0",
    what: str = "objects",
) -> Step:
    """A Detections sample of `objects` stamped `t` s after the scenario's base (its seq follows the time)."""

    def build(base: float) -> tuple[str, Sample]:
        return KEYS.objects(cam), Detections(
            stamp=base + t,
            source=f"vision/{cam}",
            seq=int(t * 10) + 1000,
            cam=cam,
            width=width,
            height=height,
            objects=objects,
            quality=quality,
        )

    return Step(t, build, f"see {len(objects)} {what}")


def see(t: float, objects: list[Obj], quality: tuple[float, float, float] = GOOD, cam: str = "cam0") -> Step:
    b, c, s = quality
    quality_sample = ImageQuality(brightness=b, contrast=c, sharpness=s)
    return detections_at(t, [o.detected() for o in objects], quality_sample, cam=cam)


def landmarks_at(x: float, y: float) -> list[list[float]]:
    return [[x + 3 * math.cos(i), y + 3 * math.sin(i)] for i in range(21)]


def ray_towards(
    origin: tuple[float, float], target: tuple[float, float], jitter_deg: float = 0.0
) -> tuple[float, float]:
    a = math.atan2(target[1] - origin[1], target[0] - origin[0]) + math.radians(jitter_deg)
    return (math.cos(a), math.sin(a))


def hands(  # noqa: PLR0913 - a scenario step: every detail has a default and a scenario names the few it changes
    t: float,
    point_at: tuple[float, float] | None = None,
    origin: tuple[float, float] = (320.0, 470.0),
    score: float = 0.95,
    ray_conf: float = 0.9,
    jitter_deg: float = 0.0,
    cam: str = "cam0",
    hand: Handedness = "right",
    show: GestureName | None = None,
) -> Step:
    """A Hands frame: one pointing hand if `point_at`, else no hands. `jitter_deg`: the ray wobbles
    by up to that much from frame to frame (a shaky or badly tracked hand)."""

    def build(base: float) -> tuple[str, Sample]:
        found = []
        if point_at is not None:
            d = ray_towards(origin, point_at, jitter_deg * math.sin(t * 37.0))
            found.append(
                Hand(
                    hand=hand,
                    score=score,
                    landmarks=landmarks_at(*origin),
                    gesture="point",
                    ray=Ray(origin=list(origin), direction=list(d), confidence=ray_conf),
                )
            )
        elif show is not None:  # a hand showing another gesture (open_palm, fist …), no ray
            found.append(Hand(hand=hand, score=score, landmarks=landmarks_at(*origin), gesture=show))
        return KEYS.hands(cam), Hands(
            stamp=base + t, source=f"gesture/{cam}", seq=int(t * 30) + 5000, cam=cam, width=W, height=H, hands=found
        )

    return Step(t, build, "hands" + (f" pointing at {point_at}" if point_at else " (none)"))


def gesture(  # noqa: PLR0913 - a scenario step: every detail has a default and a scenario names the few it changes
    t: float,
    name: GestureName,
    phase: GesturePhase = "start",
    score: float = 0.9,
    duration: float = 0.4,
    point_at: tuple[float, float] | None = None,
    origin: tuple[float, float] = (320.0, 470.0),
    cam: str = "cam0",
    hand: Handedness = "right",
) -> Step:
    def build(base: float) -> tuple[str, Sample]:
        ray = None
        if point_at is not None:
            ray = Ray(origin=list(origin), direction=list(ray_towards(origin, point_at)), confidence=0.9)
        return KEYS.gesture_event(cam), GestureEvent(
            stamp=base + t,
            source=f"gesture/{cam}",
            cam=cam,
            width=W,
            height=H,
            gesture=name,
            phase=phase,
            start=base + t - duration,
            end=base + t,
            score=score,
            hand=hand,
            ray=ray,
        )

    return Step(t, build, f"gesture {name} {phase}")


def stream(t0: float, t1: float, every: float, make: Callable[[float], Step]) -> list[Step]:
    n = int(round((t1 - t0) / every))
    return [make(round(t0 + i * every, 6)) for i in range(n + 1)]


def scene(
    objects: list[Obj],
    t0: float = -1.5,
    t1: float = 2.5,
    every: float = 0.2,
    quality: tuple[float, float, float] = GOOD,
    cam: str = "cam0",
) -> list[Step]:
    return stream(t0, t1, every, lambda t: see(t, objects, quality, cam))


def pointing(
    point_at: tuple[float, float] | None,
    t0: float = -1.5,
    t1: float = 2.5,
    every: float = 0.1,
    active: tuple[float, float] = (-10.0, 10.0),
    **kw: Any,
) -> list[Step]:
    """Hands frames over [t0, t1]; the hand points at `point_at` only during `active`."""
    return stream(t0, t1, every, lambda t: hands(t, point_at if active[0] <= t <= active[1] else None, **kw))


def by_time(steps: list[Step]) -> list[Step]:
    return sorted(steps, key=lambda s: s.t)


# ---------------------------------------------------------------------------
# Running a scenario in process (no zenoh): the unit tests and the evaluation use this.
# ---------------------------------------------------------------------------
def bbox_of(obj: DetectedObject) -> tuple[float, float, float, float]:
    x, y, w, h = obj.bbox
    return (x, y, w, h)


def deliver(core: FusionCore, key: str, sample: Sample, wall: float) -> list[Output]:
    """Hands one input sample to fusion's core, as the service's worker does, by its type."""
    if isinstance(sample, Transcript):
        return core.on_transcript(key, sample, wall)
    if isinstance(sample, Detections):
        return core.on_detections(key, sample, wall)
    if isinstance(sample, Hands):
        return core.on_hands(key, sample, wall)
    if isinstance(sample, GestureEvent):
        return core.on_gesture_event(key, sample, wall)
    if isinstance(sample, Bodies):
        return core.on_bodies(key, sample, wall)
    if isinstance(sample, RobotState):
        return core.on_robot_state(key, sample, wall)
    if isinstance(sample, Spoken):
        return core.on_spoken(key, sample, wall)
    raise TypeError(f"fusion takes no {type(sample).__name__}")


def run_in_process(
    scenario: Scenario,
    config: Any = None,
    base: float = BASE_STAMP,
    order: list[int] | None = None,
    profile: Any = None,
) -> list[Sample]:
    """Feed the steps (in `order` if given) with 2 ms of wall time between arrivals, ticking after each
    like the service's worker; then let every deadline expire. Returns the published samples. `profile`: the robot's
    (common/robot.py; None: the default)."""
    from common.robot import DEFAULT
    from services.fusion.core import Config, FusionCore

    cfg = config or Config(**scenario.config)
    core = FusionCore(cfg, "fusion/test", profile=profile or DEFAULT)
    out: list[Sample] = []
    wall = 1000.0
    for modality in ("vision", "gesture"):  # the services are running, as in a deployment (liveliness tokens)
        core.on_liveliness(modality, "test", True)
    steps = [scenario.steps[i] for i in order] if order is not None else scenario.steps
    for step in steps:
        out.extend(o.sample for o in deliver(core, *step.build(base), wall))
        out.extend(o.sample for o in core.tick(wall))
        wall += 0.002
    out.extend(o.sample for o in core.tick(wall + 100.0))
    return out


def check(scenario: Scenario, outputs: list[Sample]) -> str:
    """'' if the outputs are exactly what the scenario expects, else what differs."""
    problems = []
    if len(outputs) != len(scenario.expect):
        problems.append(
            f"expected {len(scenario.expect)} outputs, got {len(outputs)}: {[describe(o) for o in outputs]}"
        )
    for i, (exp, got) in enumerate(zip(scenario.expect, outputs)):
        why = exp.mismatch(got)
        if why:
            problems.append(f"output {i}: {why} [{describe(got)}]")
    return "; ".join(problems)
