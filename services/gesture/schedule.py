"""Which of the gesture service's paced stages run on a frame (issue #34; pure, no MediaPipe here).

Each paced stage decides on its own when it is due: full pose at `--pose-max-rate`, the face stage at
`--faces-max-rate`, the hand search while no hand is in view on every `--hands-idle-every`-th frame, the person
stage on every `--persons-every`-th frame. Left alone they fall on the same frames now and then (pose + hand search
+ person stage + faces: ~40 ms of CPU on the 2-core machine) and on others almost nothing runs; the service's lag
tail is set by those heavy frames. `StageScheduler` spreads them: pose runs whenever it is due (it is never
deferred; tracked hands run on every frame too); each other due stage (faces, then the hand search, then the person
stage) runs on this frame if the frame's expected cost stays within the budget (one pose run's cost), else it is
deferred to the next frame, where it runs whatever that frame holds: **at most one frame late, never skipped**.
Every due run happens, so each stage keeps its rate on average; its own pacer stays anchored on when it was due.
Nothing is deferred on a stream's first frame (nothing is known yet), nor when pose runs on every frame (no
lighter frame to move to), nor a stage that is itself due on every frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class RatePace:
    """At most `rate` runs per second of source time (0: every frame), at that rate on average: each run is due one
    period after the previous one was due, not after the frame it ran on, so stamps that jitter around the frame
    period (a 30 fps camera at a 15/s cap) give every 2nd frame, not every 3rd. A frame a quarter period early
    counts as due; a gap or a clock going back starts afresh."""

    rate: float
    next_due: float | None = None

    def due(self, stamp: float) -> bool:
        if self.rate <= 0:
            return True
        period = 1.0 / self.rate
        early = period / 4
        nxt = self.next_due
        if nxt is not None and nxt - period <= stamp < nxt - early:
            return False
        on_time = nxt is not None and nxt - early <= stamp < nxt + period
        self.next_due = nxt + period if on_time and nxt is not None else stamp + period
        return True


DEFERRABLE = ("faces", "hand_search", "persons")  # in the order they are given room on a frame


@dataclass(frozen=True)
class StageCosts:
    """Expected CPU ms of one run of each stage on 480x480 frames of the 2-core machine (docs/benchmarks.md):
    only their ratios matter. `hands`: the hand search with nothing in view, or tracking a hand in view; `persons`:
    the person stage on the face stage's faces with one person in view."""

    pose: float = 21.0
    hands: float = 11.0
    faces: float = 6.0
    persons: float = 3.0

    def of(self, stage: str) -> float:
        return {"faces": self.faces, "hand_search": self.hands, "persons": self.persons}[stage]


@dataclass(frozen=True)
class Due:
    """What each stage's own pacer says about this frame. `hands_tracked`: a hand is in view (tracked on every
    frame, not deferrable); `every_frame`: the stages whose pacer makes them due on every frame (rate 0, every 1)."""

    pose: bool = False
    hands_tracked: bool = False
    faces: bool = False
    hand_search: bool = False
    persons: bool = False
    every_frame: frozenset[str] = frozenset()

    def of(self, stage: str) -> bool:
        return bool(getattr(self, stage))


@dataclass(frozen=True)
class FramePlan:
    """The stages that run on this frame and their expected cost (ms, `StageCosts`)."""

    pose: bool
    faces: bool
    hand_search: bool
    persons: bool
    cost: float
    deferred: tuple[str, ...] = ()  # stages with a due run not done by this frame: it runs on the next


@dataclass
class StageScheduler:
    """One camera's frames -> which paced stages run (`plan`). `stagger` off: every stage runs when its own pacer
    says (the stages independent, as before issue #34's scheduling)."""

    stagger: bool = True
    costs: StageCosts = StageCosts()
    owed: dict[str, int] = field(default_factory=dict)  # runs due on an earlier frame, not run yet (at most 1 each)
    first: bool = True  # the stream's first frame comes next

    def restart(self) -> None:
        """A new stream or timeline: nothing owed, the next frame is a first frame."""
        self.owed, self.first = {}, True

    def plan(self, due: Due) -> FramePlan:
        cost = (self.costs.pose if due.pose else 0.0) + (self.costs.hands if due.hands_tracked else 0.0)
        spread = self.stagger and not self.first and "pose" not in due.every_frame
        runs: dict[str, bool] = {}
        deferred: list[str] = []
        for stage in DEFERRABLE:
            waiting = self.owed.get(stage, 0)
            owed = waiting + (1 if due.of(stage) else 0)
            fits = cost + self.costs.of(stage) <= self.costs.pose
            runs[stage] = owed > 0 and (waiting > 0 or fits or not spread or stage in due.every_frame)
            if runs[stage]:
                cost, owed = cost + self.costs.of(stage), owed - 1
            if owed > 0:
                deferred.append(stage)
            self.owed[stage] = owed
        self.first = False
        return FramePlan(due.pose, runs["faces"], runs["hand_search"], runs["persons"], cost, tuple(deferred))


def eased(plan: FramePlan) -> FramePlan:
    """The plan of a frame while speech decodes an utterance (common/speech_first.py, issue #42): full pose and the
    person stage skipped (the skeleton is carried, the last persons stand), the hand search and the tracked hands
    kept (a stop palm is never eased), and the face stage kept: the next utterance often starts while the last one
    decodes (one person answers another), and who says it is read from the mouths seen while it is said — a face
    stage eased for the decode left that answer's speaker unknown (the CI failure of test_speaker_e2e: 2 of 3 faces
    at 15 frames/s of 25). It is the cheapest of the three (StageCosts). Skipped runs are not owed: each stage's
    pacer goes on."""
    skipped = tuple(s for s in ("pose", "persons") if getattr(plan, s))
    if not skipped:
        return plan
    costs = StageCosts()
    cost = plan.cost - sum(costs.pose if s == "pose" else costs.of(s) for s in skipped)
    return FramePlan(False, plan.faces, plan.hand_search, False, max(0.0, cost), plan.deferred)
