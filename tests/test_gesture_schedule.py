"""The paced stages spread over frames (issue #34, services/gesture/schedule.py; pure, no MediaPipe): a sequence of
frames, the stages' own pacers as the service has them (`RatePace`, every-N counters), and which stage runs on
which frame."""

from __future__ import annotations

from dataclasses import dataclass, field

from services.gesture.schedule import Due, FramePlan, RatePace, StageCosts, StageScheduler

STAGES = ("pose", "faces", "hand_search", "persons")


@dataclass
class Pacers:
    """The service's own pacers of one camera: pose and faces by source time, the idle hand search and the person
    stage every N frames (counted from when they were due)."""

    pose_rate: float = 10.0
    faces_rate: float = 20.0
    search_every: int = 2
    persons_every: int = 2
    pose: RatePace = field(init=False)
    faces: RatePace = field(init=False)
    frames: int = 0

    def __post_init__(self) -> None:
        self.pose, self.faces = RatePace(self.pose_rate), RatePace(self.faces_rate)

    def due(self, stamp: float, hands_tracked: bool = False) -> Due:
        k, self.frames = self.frames, self.frames + 1
        return Due(
            pose=self.pose.due(stamp),
            hands_tracked=hands_tracked,
            faces=self.faces.due(stamp),
            hand_search=not hands_tracked and k % self.search_every == 0,
            persons=k % self.persons_every == 0,
            every_frame=frozenset({"pose"} if self.pose_rate <= 0 else set()),
        )


def run(frames: int, fps: float = 30.0, stagger: bool = True, pacers: Pacers | None = None) -> list[FramePlan]:
    pace, schedule = pacers or Pacers(), StageScheduler(stagger=stagger)
    return [schedule.plan(pace.due(k / fps)) for k in range(frames)]


def ran(plans: list[FramePlan], stage: str) -> list[int]:
    return [k for k, p in enumerate(plans) if getattr(p, stage)]


def test_on_a_30_fps_camera_no_frame_holds_pose_with_another_paced_stage_after_the_first() -> None:
    """The shipped rates (pose 10/s, faces 20/s, hand search and persons every 2nd frame) on 300 frames: without the
    schedule 50 frames run pose with the hand search and the person stage together; with it, after the first frame
    (where everything runs: nothing is known yet), pose runs alone, and no frame's expected cost exceeds one pose
    run's."""
    before, after = run(300, stagger=False), run(300)
    assert sum(p.pose and p.hand_search and p.persons for p in before) == 50
    assert all(not (p.faces or p.hand_search or p.persons) for p in after[1:] if p.pose)
    assert max(p.cost for p in after[1:]) <= StageCosts().pose < max(p.cost for p in before)
    assert ran(after, "pose") == ran(before, "pose")  # pose is never moved


def test_every_stage_keeps_its_rate_and_each_run_is_at_most_one_frame_late() -> None:
    """Every due run happens (the same count as without the schedule, but for runs owed at the last frame), and the
    k-th run of each stage comes on the frame of its k-th due run or the one after: none is starved."""
    for fps in (30.0, 25.0, 20.0, 15.0):
        before, after = run(600, fps, stagger=False), run(600, fps)
        for stage in STAGES:
            due, done = ran(before, stage), ran(after, stage)
            assert len(due) - len(done) in (0, 1), (fps, stage)
            assert all(0 <= b - a <= 1 for a, b in zip(due, done)), (fps, stage)


def test_the_heavy_stages_are_spread_when_they_can_be() -> None:
    """At 30 fps pose runs on every 3rd frame: on the two frames between there is room for the others, so the hand
    search and the person stage never share a frame with pose, and each frame's cost stays within one pose run;
    the 600 frames' total work is the same as without the schedule."""
    before, after = run(600, stagger=False), run(600)
    assert not any(p.pose and (p.hand_search or p.persons) for p in after[1:])
    assert abs(sum(p.cost for p in after) - sum(p.cost for p in before)) <= StageCosts().pose


def test_a_tracked_hand_counts_toward_the_frame_and_the_rest_still_run() -> None:
    """With a hand in view (tracked on every frame, no search), faces and the person stage still keep their rates,
    moved off the pose frames."""
    pace, schedule = Pacers(), StageScheduler()
    plans = [schedule.plan(pace.due(k / 30.0, hands_tracked=True)) for k in range(300)]
    assert not any(p.hand_search for p in plans[1:])
    assert not any(p.pose and (p.faces or p.persons) for p in plans[1:])
    assert len(ran(plans, "faces")) >= 199 and len(ran(plans, "persons")) >= 149


def test_nothing_is_moved_when_pose_runs_on_every_frame_or_a_stage_is_due_on_every_frame() -> None:
    """Pose on every frame (`--pose-max-rate 0`): no lighter frame to move to, every stage runs when due. A stage
    due on every frame (faces at rate 0) is never moved (it would run a frame late forever)."""
    every = Pacers(pose_rate=0.0)
    plans = run(120, pacers=every)
    reference = run(120, stagger=False, pacers=Pacers(pose_rate=0.0))
    for stage in STAGES:
        assert ran(plans, stage) == ran(reference, stage)
    schedule = StageScheduler()
    faces_always = [
        schedule.plan(Due(pose=k % 3 == 0, faces=True, every_frame=frozenset({"faces"}))) for k in range(30)
    ]
    assert all(p.faces for p in faces_always)


def test_a_restart_runs_everything_due_on_its_first_frame() -> None:
    """A new stream (or one back after going quiet): its first frame runs every due stage, pose included."""
    schedule = StageScheduler()
    schedule.plan(Due(pose=True))
    late = schedule.plan(Due(pose=True, hand_search=True, persons=True, faces=True))
    assert late.deferred == ("faces", "hand_search", "persons")
    schedule.restart()
    first = schedule.plan(Due(pose=True, hand_search=True, persons=True, faces=True))
    assert first.pose and first.faces and first.hand_search and first.persons and first.deferred == ()
