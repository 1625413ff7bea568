"""The stack's CPU budget (issue #42): given the cores of the machine and the services on it, the rate of each
video stage, degraded in the order a user would choose. Pure arithmetic, standard library only; `hri up` turns
the result into the services' flags and prints why.

The model: each stage costs about `STAGE_MS` of CPU per run (measured on the project's 2-core VM on busy real
scenes, docs/benchmarks.md; a faster machine only has room to spare). The stack may use `TARGET_SHARE` of the
cores; the services that cannot skip (speech's decode, fusion, the router) and the camera's encoding are kept
out of it first (`RESERVE_CORES`). What is left is the video stages' share. When the stages at full rate need more,
they are lowered, in this order, each no lower than its floor (`FLOOR_HZ`, the goal of issue #42) before the next
one gives anything:

1. vision's model rate (objects move slowly; their colours and ids are carried between runs);
2. the person stage and the face stage, together in proportion (who is there and who speaks change slowly);
3. full-body pose (the skeleton is carried between runs by the tracked hands);
4. hands last — they carry pointing and the stop palm; they are never lowered here (a hand in view is tracked on
   every frame; with no room left the budget says so instead).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

# CPU ms per run of each stage on the 2-core VM (busy scenes): YOLOX-Nano + colours (capped: --color-max); hands
# tracked; full pose; the face stage; the person stage with its capped region poses (--persons-max-poses 2).
STAGE_MS: dict[str, float] = {"vision": 35.0, "hands": 11.0, "pose": 21.0, "faces": 6.0, "persons": 25.0}
COLOR_VISION_MS = 8.0  # vision's colour backend (HSV segmentation, no model): an estimate, a few ms a frame
FULL_HZ: dict[str, float] = {"vision": 30.0, "hands": 30.0, "pose": 10.0, "faces": 20.0, "persons": 15.0}
FLOOR_HZ: dict[str, float] = {"vision": 10.0, "hands": 30.0, "pose": 5.0, "faces": 10.0, "persons": 5.0}
SERVICE_OF: dict[str, str] = {
    "vision": "vision",
    "hands": "gesture",
    "pose": "gesture",
    "faces": "gesture",
    "persons": "gesture",
}
DEGRADE_ORDER: tuple[tuple[str, ...], ...] = (("vision",), ("persons", "faces"), ("pose",), ("hands",))
TARGET_SHARE = 0.9  # of the cores: the goal's 1.8 of 2
# cores kept for what cannot skip or must run: speech's steady VAD work and its decodes come first (speech_first
# eases video while it decodes), fusion, the router, the camera's capture and JPEG encoding
RESERVE_CORES: dict[str, float] = {"speech": 0.15, "fusion": 0.05, "router": 0.02, "camera": 0.15}


@dataclass(frozen=True)
class Budget:
    """The rate (Hz) each video stage runs at, why, and what the video stages then need (cores)."""

    cores: float
    rates: dict[str, float]
    why: dict[str, str]
    video_cores: float  # the video stages' share of the budget
    needed_cores: float  # what they need at these rates
    fits: bool = True
    notes: list[str] = field(default_factory=list)


def plan_budget(cores: float, services: set[str], fps: float = 30.0, costs: dict[str, float] | None = None) -> Budget:
    """The rates of the video stages of `services` (names of common/stack.py NODES; "router" too) on a machine of
    `cores` cores, a camera at `fps` (the most any stage can run at); `costs`: CPU ms per run of some stages
    instead of STAGE_MS's (vision's colour backend: COLOR_VISION_MS)."""
    ms = {**STAGE_MS, **(costs or {})}

    def stage_cores(stage: str, hz: float) -> float:
        return hz * ms[stage] / 1000.0

    stages = [s for s in STAGE_MS if SERVICE_OF[s] in services]
    reserve = sum(v for k, v in RESERVE_CORES.items() if k in services or k == "router")
    video = max(0.0, TARGET_SHARE * cores - reserve)
    rates = {s: min(FULL_HZ[s], fps) for s in stages}
    why = {s: f"full rate ({rates[s]:g} Hz): it fits" for s in stages}
    excess = sum(stage_cores(s, rates[s]) for s in stages) - video
    for group in DEGRADE_ORDER:
        group = tuple(s for s in group if s in rates and rates[s] > FLOOR_HZ[s])
        if excess <= 1e-9 or not group:
            continue
        room = sum(stage_cores(s, rates[s] - FLOOR_HZ[s]) for s in group)
        give = min(excess, room)
        for s in group:
            share = stage_cores(s, rates[s] - FLOOR_HZ[s]) / room  # in proportion to what each can give
            rates[s] -= give * share * 1000.0 / ms[s]
            why[s] = (
                f"lowered to {rates[s]:.1f} Hz (floor {FLOOR_HZ[s]:g}): the video stages at full rate need "
                f"{video + excess:.2f} of the {video:.2f} cores left of {TARGET_SHARE:g} x {cores:g} cores, and "
                f"{' and '.join(group)} give{'s' if len(group) == 1 else ''} way "
                f"{_order_text(group)}"
            )
        excess -= give
    needed = sum(stage_cores(s, r) for s, r in rates.items())
    notes = []
    if excess > 1e-9:
        notes.append(
            f"every stage at its floor still needs {needed:.2f} cores of {video:.2f}: expect skipped frames "
            f"(a machine of {cores:g} cores is below what the stack needs on a busy scene)"
        )
    return Budget(cores, rates, why, video, needed, fits=excess <= 1e-9, notes=notes)


def _order_text(group: tuple[str, ...]) -> str:
    rank = next(k for k, g in enumerate(DEGRADE_ORDER) if group[0] in g)
    return ("first (objects move slowly)", "second (who is there changes slowly)", "third", "last")[rank]


def budget_flags(budget: Budget, fps: float) -> dict[str, list[str]]:
    """The services' flags for `budget` (only the stages it lowered; a stage at full rate keeps its default)."""
    lowered = {s: r for s, r in budget.rates.items() if r < min(FULL_HZ[s], fps) - 1e-6}
    flags: dict[str, list[str]] = {}
    if "vision" in lowered:
        flags.setdefault("vision", []).append(f"--max-rate={lowered['vision']:.1f}")
    if "pose" in lowered:
        flags.setdefault("gesture", []).append(f"--pose-max-rate={lowered['pose']:.1f}")
    if "faces" in lowered:
        flags.setdefault("gesture", []).append(f"--faces-max-rate={lowered['faces']:.1f}")
    if "persons" in lowered:
        every = max(1, math.ceil(fps / lowered["persons"] - 1e-6))  # never above the rate budgeted
        flags.setdefault("gesture", []).append(f"--persons-every={every}")
    return flags


@dataclass
class MaxRate:
    """At most `hz` runs per second of source time (0: every frame), anchored on when each run was due (a 30 fps
    camera at 12 Hz gives runs 2 and 3 frames apart, 12 a second); a frame a quarter period early counts as due; a
    gap or a clock going back starts afresh. The same rule as gesture's RatePace (services/gesture/schedule.py)."""

    hz: float
    next_due: float | None = None

    def take(self, stamp: float) -> bool:
        if self.hz <= 0:
            return True
        period = 1.0 / self.hz
        nxt = self.next_due
        if nxt is not None and nxt - period <= stamp < nxt - period / 4:
            return False
        on_time = nxt is not None and nxt - period / 4 <= stamp < nxt + period
        self.next_due = nxt + period if on_time and nxt is not None else stamp + period
        return True
