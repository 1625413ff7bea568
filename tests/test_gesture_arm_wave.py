"""A wave seen by the body alone (services/gesture/deliberate.py `ArmSwing`, issue #40): the real skeletons of
tests/data/landmarks/real_bodies.json with the wrist (and elbow) moved along a path over source time, as the pose
stage would report an arm waving at room distance whose hand the hand stage does not see. A lifted arm swinging
side to side is a wave, whatever the frame rate; a hanging arm or a small sway is not; the tracker's wave carries
the marks fusion needs for a call (held from the swing's start, raised)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable, cast

import numpy as np
import pytest

from common.schema import GestureEvent
from services.fusion.gestures import WAVE_HOLD_S, Person, deliberate
from services.gesture.body import body_scale
from services.gesture.deliberate import SWEEP_MIN_SCALES, SWING_MIN_SCALES, ArmSwing, arm_lifted
from services.gesture.temporal import Event, GestureTracker

if TYPE_CHECKING:
    from common.schema import GesturePhase, Handedness

REAL = json.loads((Path(__file__).parent / "data" / "landmarks" / "real_bodies.json").read_text())
LIFTED = "arm_at_camera"  # the right arm held up at the camera, the wrist at shoulder height
HANGING = "standing_fist_hanging"  # the right arm hanging at the side
R_ELBOW, R_WRIST = 14, 16


def _skeleton(name: str) -> np.ndarray:
    return np.array(REAL[name]["pose"], dtype=float)


def _moved(name: str, dx: float) -> np.ndarray:
    """The real skeleton with its right forearm moved `dx` body scales sideways."""
    p = _skeleton(name)
    p[[R_ELBOW, R_WRIST], 0] += dx * body_scale(p)
    return p


def _series(name: str, path: Callable[[float], float], seconds: float, fps: float) -> list[tuple[float, np.ndarray]]:
    return [(i / fps, _moved(name, path(i / fps))) for i in range(int(seconds * fps) + 1)]


def _waving(series: list[tuple[float, np.ndarray]]) -> list[float | None]:
    swing = ArmSwing()
    out = []
    for stamp, body in series:
        swing.add(stamp, body, "right")
        out.append(swing.waving())
    return out


def test_the_real_skeletons_arm_is_lifted_at_the_shoulder_and_not_hanging() -> None:
    assert arm_lifted(_skeleton(LIFTED), "right")
    assert not arm_lifted(_skeleton(HANGING), "right")
    assert not arm_lifted(_moved(HANGING, 2.0), "right")  # swung out but still at the hip: not lifted


@pytest.mark.parametrize("fps", [10.0, 15.0, 25.0, 30.0])
def test_a_lifted_arm_sweeping_across_is_a_wave_from_the_sweeps_start_at_any_frame_rate(fps: float) -> None:
    """One sweep of 1.25 x `SWEEP_MIN_SCALES` over 1.2 s (the KARD clip's arm: ~3 body scales in 1.2 s): a wave once
    it has covered `SWEEP_MIN_SCALES`, dated from its first frame."""
    reach = 1.25 * SWEEP_MIN_SCALES
    waving = _waving(_series(LIFTED, lambda t: -reach * min(t / 1.2, 1.0), 1.5, fps))
    first = next(i for i, w in enumerate(waving) if w is not None)
    assert 0.9 * 1.2 / 1.25 <= first / fps <= 1.1 * 1.2 / 1.25 + 1 / fps
    assert all(w == 0.0 for w in waving[first:])


@pytest.mark.parametrize("fps", [10.0, 25.0])
def test_a_lifted_arm_waving_back_and_forth_is_a_wave(fps: float) -> None:
    amplitude = 0.6 * SWING_MIN_SCALES  # x2 peak to peak: more than the least swing, far less than a sweep
    waving = _waving(_series(LIFTED, lambda t: amplitude * math.sin(2 * math.pi * t), 1.5, fps))
    assert waving[-1] == 0.0
    assert waving[int(0.5 * fps)] is None  # one swing across, no turn yet


@pytest.mark.parametrize(
    "name, path",
    [
        (LIFTED, lambda t: 0.4 * SWING_MIN_SCALES * math.sin(2 * math.pi * 1.5 * t)),  # a sway, as hands talking
        (LIFTED, lambda t: 0.0),  # held still
        (HANGING, lambda t: 1.5 * math.sin(2 * math.pi * t)),  # a hanging arm swung widely (walking, reaching)
    ],
)
def test_a_small_sway_a_still_arm_or_a_hanging_arm_is_no_wave(name: str, path: Callable[[float], float]) -> None:
    assert _waving(_series(name, path, 3.0, 25.0)) == [None] * 76


def test_a_lost_skeleton_starts_the_swing_afresh() -> None:
    series = _series(LIFTED, lambda t: -2.5 * min(t / 1.2, 1.0), 1.2, 25.0)
    swing = ArmSwing()
    for stamp, body in series[:15]:
        swing.add(stamp, body, "right")
    swing.add(0.62, None, "right")
    for stamp, body in series[16:]:
        swing.add(stamp, body, "right")
    assert swing.waving() is None  # the rest of the sweep alone (0.64-1.2 s) covers less than a sweep


def _tracker_waves(fps: float, keep: Callable[[int], bool] = lambda i: True) -> list[Event]:
    """The tracker fed the sweeping skeleton and no hand at all (the hand stage lost the blurred hand)."""
    tracker = GestureTracker(start_time=0.15)
    width, height = REAL[LIFTED]["width"], REAL[LIFTED]["height"]
    events = []
    # up for 0.3 s, then one sweep across and back over 1.6 s, then lowered
    series = _series(LIFTED, lambda t: -2.4 * math.sin(math.pi * max(t - 0.3, 0.0) / 1.6), 1.9, fps)
    for i, (stamp, body) in enumerate(series):
        if keep(i):
            events += tracker.update(stamp, [], body, (width, height))[1]
    events += tracker.update(2.0, [], None, (width, height))[1] + tracker.flush()
    return [e for e in events if e.gesture == "wave"]


def _wire(ev: Event) -> GestureEvent:
    return GestureEvent(
        stamp=ev.end,
        source="gesture/test",
        cam="cam0",
        width=460,
        height=459,
        gesture="wave",
        phase=cast("GesturePhase", ev.phase),
        start=ev.start,
        end=ev.end,
        score=ev.score,
        hand=cast("Handedness", ev.hand),
        still=ev.still,
        raised=ev.raised,
    )


@pytest.mark.parametrize("fps, keep", [(25.0, "all"), (25.0, "every 2nd"), (15.0, "all")])
def test_the_tracker_waves_with_the_arm_alone_long_and_raised_enough_to_call(fps: float, keep: str) -> None:
    waves = _tracker_waves(fps, (lambda i: True) if keep == "all" else (lambda i: i % 2 == 1))
    assert waves and {e.hand for e in waves} == {"right"}
    assert sum(e.phase == "start" for e in waves) == 1  # one wave, not one per frame the arm turned
    called = [e for e in waves if deliberate(_wire(e), Person(engaged=True))]
    assert called and called[0].end - called[0].start >= WAVE_HOLD_S
    assert all(e.raised for e in waves if e.phase != "end")
    # the same wave by someone speaking, or turned away, calls nobody
    assert not any(deliberate(_wire(e), Person(engaged=True, speaking=True)) for e in waves)
    assert not any(deliberate(_wire(e), Person(engaged=False)) for e in waves)
