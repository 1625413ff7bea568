"""The gesture service's core: per camera, MediaPipe hands (and body) -> tracked gestures and their rays, and
(issue #33) the persons and faces in view, as the wire samples of one frame.
No Zenoh here: the shell (__main__.py) feeds frames and publishes what comes back."""

from __future__ import annotations

import collections
from dataclasses import InitVar, dataclass, field
from typing import Any, cast

import numpy as np

from common.engagement import EngagementTracker, mark_engagement
from common.image import frame_fields
from common.schema import (
    Bodies,
    Body,
    DepthFrame,
    Faces,
    Frame,
    GestureEvent,
    GestureName,
    GesturePhase,
    Hand,
    Handedness,
    Hands,
    Persons,
    Ray,
    Ray3D,
)
from services.gesture.faces import FaceConfig, FaceStage, FaceStages, FaceTracker, link_faces
from services.gesture.landmarks import HandLandmarker, PoseLandmarker
from services.gesture.people_stage import (
    CameraPeople,
    PeopleOfFrame,
    PeopleStage,
    event_person,
    hand_person,
    other_arms,
    other_skeletons,
)
from services.gesture.persons import Box
from services.gesture.pose_rotation import MAX_POSES
from services.gesture.pose_track import PoseRun, carried, hands_on_arms
from services.gesture.schedule import Due, FramePlan, RatePace, StageScheduler, eased
from services.gesture.space import FrameRays
from services.gesture.temporal import Event, GestureTracker, Observation, TrackedHand


def to_ray(ray: Any, ray3d: Ray3D | None = None) -> Ray | None:
    if ray is None:
        return None
    return Ray(
        origin=[round(v, 2) for v in ray.origin],
        direction=list(ray.direction),
        confidence=ray.confidence,
        source=ray.source,
        ray3d=ray3d,
    )


def to_body(landmarks: np.ndarray, arms: list, rays3d: FrameRays | None = None, age_s: float = 0.0) -> Body:
    """A pose skeleton (33x3) and the last frame's judged arms -> the wire `Body` (3-D rays when depth is known);
    `age_s`: source time since the pose model found it (0: on this frame; else carried by `pose_track`)."""
    rays = {arm.side: to_ray(ray, rays3d.arm(arm.side) if rays3d and ray else None) for arm, ray in arms}
    return Body(
        landmarks=[[round(x, 1), round(y, 1)] for x, y in landmarks[:, :2].tolist()],
        visibility=[round(min(1.0, max(0.0, v)), 3) for v in landmarks[:, 2].tolist()],
        left_ray=rays.get("left"),
        right_ray=rays.get("right"),
        pose_age_ms=round(age_s * 1000.0, 1) if age_s > 0 else None,
    )


Body3 = tuple[np.ndarray | None, np.ndarray | None, float]  # skeleton 33x3, world landmarks 33x3, age in s


@dataclass(frozen=True)
class GestureSettings:
    model: str = "lite"
    max_hands: int = 2
    mirrored: bool = False
    start_frames: int = 3
    end_frames: int = 3
    start_s: float = 0.0
    ray_from: str = "eyes"
    body: bool = True
    pose_max_rate: float = 10.0  # full pose at most this many times per second of source time (0: every frame)
    persons_every: int = 2  # the person stage on every Nth frame (issue #33; 0: off)
    persons_max_poses: int = MAX_POSES  # region poses per person-stage run at most, in turn (issue #42; 0: no cap)
    hands_idle_every: int = 2  # while no hand is in view, look for hands on every Nth frame only (1: every frame)
    faces: bool = True  # the face stage: Faces for who is speaking (issue #33)
    face: FaceConfig = FaceConfig()
    stagger: bool = True  # spread the paced stages over frames (schedule.py); False: each runs when it is due


@dataclass
class FrameResult:
    """What one frame gives: the Hands (and Bodies) to publish, the gesture events, the 3-D rays (for the
    events' rays) and why depth could not be used, if it could not."""

    hands: Hands
    bodies: Bodies | None
    events: list[Event]
    rays3d: FrameRays | None
    hand_rays3d: dict[str, Ray3D | None]
    persons: Persons | None = None  # on the frames the person stage ran on
    seen: PeopleOfFrame | None = None  # whose hands and gestures these are
    faces: Faces | None = None  # the face stage's sample (None: off, skipped by faces_max_rate, or deferred)
    plan: FramePlan | None = None  # which paced stages ran on this frame (schedule.py)


WARM_SIZE = (480, 640)  # (height, width) of the blank frame a new camera's graphs are warmed on


@dataclass
class CameraGraphs:
    """The MediaPipe graphs one camera needs: hands, the full-frame pose, the face mesh and the person stage's (each
    per the settings). Building them takes ~0.05 s; MediaPipe sets a graph's models up on its first run (~0.2-0.7 s
    each, ~300 MB for the set), so `warm` runs each once on a blank frame: a camera's first frames then cost what
    its later ones do. A blank frame leaves no state behind (no hand, body or face is tracked from it)."""

    hands: HandLandmarker
    pose: PoseLandmarker | None
    faces: FaceStage | None
    people: PeopleStage | None

    def warm(self) -> None:
        blank = np.zeros((*WARM_SIZE, 3), np.uint8)
        self.hands.detect(blank)
        if self.pose is not None:
            self.pose.detect(blank, 0.0)  # stamp 0: every camera's stamps come after it, as the graph's clock needs
        if self.faces is not None:
            self.faces.mesher.detect(blank)
        if self.people is not None:
            self.people.faces.detect(blank)
            self.people.regions.detect(blank, (0, 0, WARM_SIZE[1], WARM_SIZE[0]))

    def close(self) -> None:
        for graph in (self.hands, self.pose, self.faces, self.people):
            if graph is not None:
                graph.close()


def build_graphs(settings: GestureSettings, warm: bool = True) -> CameraGraphs:
    """The graphs of one camera under these settings, warmed (`CameraGraphs.warm`) unless `warm` is False."""
    s = settings
    graphs = CameraGraphs(
        hands=HandLandmarker(s.model, s.max_hands, s.mirrored),
        pose=PoseLandmarker() if s.body else None,
        faces=FaceStage(s.face) if s.faces else None,
        people=PeopleStage(every=s.persons_every) if s.persons_every else None,
    )
    if warm:
        graphs.warm()
    return graphs


@dataclass
class CameraGestures:
    """One camera's MediaPipe graphs (they track between frames) and gesture tracker; the pose graph at its own
    rate, its skeleton carried between its runs (`pose_track`). `graphs`: its hands and pose graphs built
    beforehand (`build_graphs`), else built here."""

    settings: GestureSettings
    graphs: InitVar[CameraGraphs | None] = None
    hands: HandLandmarker = field(init=False)
    pose: PoseLandmarker | None = field(init=False, default=None)
    tracker: GestureTracker = field(init=False)
    hands_in_view: bool = field(init=False, default=False)  # the last hand search found a hand
    idle_skipped: int = field(init=False, default=0)  # frames since the last search while none is in view
    pose_pace: RatePace = field(init=False)
    pose_run: PoseRun | None = field(init=False, default=None)  # the pose model's last run
    schedule: StageScheduler = field(init=False)  # which paced stages run on a frame

    def __post_init__(self, graphs: CameraGraphs | None) -> None:
        s = self.settings
        self.hands = graphs.hands if graphs is not None else HandLandmarker(s.model, s.max_hands, s.mirrored)
        if s.body:
            self.pose = graphs.pose if graphs is not None and graphs.pose is not None else PoseLandmarker()
        self.restart(new_pose=False)

    def restart(self, new_pose: bool = True) -> None:
        """New stream or a new timeline (common/stamps.py): gestures start afresh (on a new timeline, with a new pose
        graph: its clock and smoothing must not see time go back)."""
        s = self.settings
        self.tracker = GestureTracker(
            start_frames=s.start_frames, end_frames=s.end_frames, start_time=s.start_s, ray_from=s.ray_from
        )
        if s.body and new_pose:
            if self.pose is not None:
                self.pose.close()
            self.pose = PoseLandmarker()
        self.pose_pace, self.pose_run = RatePace(s.pose_max_rate), None
        self.schedule = StageScheduler(stagger=s.stagger)
        # a new stream's first frame is searched (as if the idle frames had all gone by)
        self.hands_in_view, self.idle_skipped = False, s.hands_idle_every

    def search_due(self) -> bool:
        """Whether the hand search is due on this frame while no hand is in view: on every `hands_idle_every`-th
        frame only (MediaPipe's palm detector, most of the hands stage's cost when nothing is tracked). Counted from
        when it was due, not when it ran (the schedule may move it a frame), so it keeps its rate."""
        if self.hands_in_view:
            return False
        if self.idle_skipped + 1 < self.settings.hands_idle_every:
            self.idle_skipped += 1
            return False
        self.idle_skipped = 0
        return True

    def find_hands(self, img: np.ndarray, search: bool) -> list[Observation]:
        """The hands of this frame: a hand in view is tracked on every frame; while none is, only the frames the
        search runs on (`search`) look: a hand coming into view is found at most `hands_idle_every` - 1 frames
        late, one more when the schedule moved the search off a pose frame."""
        if not self.hands_in_view and not search:
            return []
        found = self.hands.detect(img)
        self.hands_in_view = bool(found)
        return found

    def pose_due(self, stamp: float) -> bool:
        """Whether the pose model runs on this frame (`pose_max_rate`; always before its first run)."""
        if self.pose is None:
            return False
        due = self.pose_pace.due(stamp)
        return due or self.pose_run is None

    def find_body(self, stamp: float, img: np.ndarray, hands: list[Observation], run: bool) -> Body3:
        """The full-frame skeleton of this frame, its world landmarks and its age (s): the pose model's when it
        runs (`run`: `pose_due`), else its last run's carried to this frame's hands (`pose_track.carried`)."""
        if self.pose is None:
            return None, None, 0.0
        run_before = self.pose_run
        if run_before is None or run:
            skeleton = self.pose.detect(img, stamp)
            wrists = hands_on_arms(skeleton, hands) if skeleton is not None else {}
            self.pose_run = PoseRun(skeleton, self.pose.world if skeleton is not None else None, stamp, wrists)
            return skeleton, self.pose_run.world, 0.0
        return carried(run_before, hands), run_before.world, max(0.0, stamp - run_before.stamp)

    def plan(self, stamp: float, faces_due: bool, persons_due: bool) -> FramePlan:
        """This frame's paced stages, each pacer asked once (they count the frames they are asked about)."""
        s = self.settings
        every_frame = {"pose"} if s.pose_max_rate <= 0 else set()
        every_frame |= {"hand_search"} if s.hands_idle_every <= 1 else set()
        every_frame |= {"faces"} if s.face.faces_max_rate <= 0 else set()
        every_frame |= {"persons"} if s.persons_every == 1 else set()
        due = Due(
            pose=self.pose_due(stamp),
            hands_tracked=self.hands_in_view,
            faces=faces_due,
            hand_search=self.search_due(),
            persons=persons_due,
            every_frame=frozenset(every_frame),
        )
        return self.schedule.plan(due)

    def close(self) -> None:
        self.hands.close()
        if self.pose is not None:
            self.pose.close()


class GestureCore:
    """Frames of every camera -> FrameResult; depth frames kept per camera to lift the rays to 3-D."""

    def __init__(self, settings: GestureSettings, source: str, depth_kept: int) -> None:
        self.settings = settings
        self.source = source
        self.cameras: dict[str, CameraGestures] = {}
        self.depths: dict[str, collections.deque[DepthFrame]] = {}
        self.depth_kept = depth_kept
        self.last_stamp: dict[str, float] = {}
        self.depth_unmatched = 0  # frames of a camera with depth whose own depth had not come (yet)
        # issue #33: Persons, a body per person, whose hand; issue #42: at most N region poses per run, in turn
        self.people = CameraPeople(settings.persons_every, settings.persons_max_poses)
        self.faces = FaceStages(settings.face, enabled=settings.faces)  # issue #33: who is speaking
        self.engagement: dict[str, EngagementTracker] = {}  # cam -> REP-155 engagement of its persons (issue #40)

    def close(self) -> None:
        for cam in self.cameras.values():
            cam.close()
        self.people.close()
        self.faces.close()

    def add_depth(self, depth: DepthFrame) -> None:
        self.depths.setdefault(depth.cam, collections.deque(maxlen=self.depth_kept)).append(depth)

    def adopt(self, cam: str, graphs: CameraGraphs) -> None:
        """Give camera `cam` (not seen yet) these graphs, built beforehand (`build_graphs`): its frames are served
        from the first without building any."""
        self.cameras[cam] = CameraGestures(self.settings, graphs)
        if graphs.faces is not None:  # the face ids of this camera: "<cam>/face-N", as FaceStages names them
            graphs.faces.tracker = FaceTracker(keep=self.settings.face.face_keep, prefix=f"{cam}/face-")
            self.faces.stages[cam] = graphs.faces
        if graphs.people is not None:
            self.people.stages[cam] = graphs.people

    def camera(self, frame: Frame) -> CameraGestures:
        cam = self.cameras.get(frame.cam)
        if cam is None:  # one graph per stream: MediaPipe tracks between frames (cold: `adopt` gives warm ones)
            self.adopt(frame.cam, build_graphs(self.settings, warm=False))
            cam = self.cameras[frame.cam]
        elif frame.stamp < self.last_stamp.get(frame.cam, frame.stamp):
            cam.restart()
        self.last_stamp[frame.cam] = frame.stamp
        return cam

    def frame_rays(self, frame: Frame, skeleton: np.ndarray | None, world: Any) -> FrameRays | None:
        """The 3-D rays of this frame, when the depth of the same capture (same seq and stamp) has come."""
        kept = self.depths.get(frame.cam, ())
        depth = next((d for d in reversed(kept) if d.seq == frame.seq and d.stamp == frame.stamp), None)
        if depth is None:
            if frame.cam in self.depths:
                self.depth_unmatched += 1  # a camera with depth, but not of this capture (yet)
            return None
        return FrameRays(depth, skeleton, world)  # decoded only when a body is seen

    def process(self, frame: Frame, img: np.ndarray, fresh: bool, ease: bool = False) -> FrameResult:
        """One frame of a camera; `fresh`: its stream is new or came back after going quiet (new person ids);
        `ease`: speech is decoding, the heavy stages skip this frame (schedule.eased)."""
        cam = self.camera(frame)
        if fresh:
            cam.schedule.restart()
        plan = cam.plan(frame.stamp, self.faces.due(frame), self.people.due(frame, fresh))
        if ease:
            plan = eased(plan)
        observations = cam.find_hands(img, plan.hand_search)
        skeleton, world, pose_age = cam.find_body(frame.stamp, img, observations, plan.pose)
        rays3d = self.frame_rays(frame, skeleton, world)
        joints3d = rays3d.joints() if rays3d is not None else None  # with depth, arms are judged in 3-D
        size = (frame.width, frame.height)
        faces = self.faces.sample(frame, img, self.source, run=plan.faces)
        boxes = face_boxes(faces, self.settings.face.max_faces)
        seen = self.people.update(
            frame, img, skeleton, observations, rays3d, fresh=fresh, faces=boxes, run=plan.persons
        )
        others = other_skeletons(seen)  # their hands keep the resting rules of their own arms (issue #31)
        tracked, events = cam.tracker.update(frame.stamp, observations, skeleton, size, joints3d, others)
        hand_rays3d = {
            o.hand: rays3d.hand(o.landmarks, tip=t.ray.source == "hand")
            for o, t in zip(observations, tracked)
            if rays3d is not None and t.ray is not None
        }
        persons = self.people.sample(frame, seen, self.source) if seen is not None and seen.ran else None
        self.link(frame, faces, seen, persons)
        fields = frame_fields(frame, self.source)
        found = [
            to_hand(o, t, hand_rays3d.get(o.hand), hand_person(seen, k))
            for k, (o, t) in enumerate(zip(observations, tracked))
        ]
        hands = Hands(**fields, hands=found)
        bodies = None
        if self.settings.body:
            main = (skeleton, cam.tracker.last_arms, pose_age)
            bodies = Bodies(**fields, bodies=people_bodies(frame, main, rays3d, seen))
        return FrameResult(hands, bodies, events, rays3d, hand_rays3d, persons, seen, faces, plan)

    def link(self, frame: Frame, faces: Faces | None, seen: PeopleOfFrame | None, persons: Persons | None) -> None:
        """The face stage's Faces of this frame tied to the persons both ways (`link_faces`: a face's person, a
        person's face); the persons of the stage's last run stand for the frames between its runs. The faces feed
        the camera's engagement tracker, whose levels the persons carry (`Person.engagement`)."""
        if persons is not None:
            self.people.persons[frame.cam] = persons
        link_faces(faces, self.people.persons.get(frame.cam) if seen is not None else None)
        tracker = self.engagement.setdefault(frame.cam, EngagementTracker())
        if faces is not None:
            tracker.update(faces, self.people.persons.get(frame.cam))
        if persons is not None:
            mark_engagement(persons, tracker)


def face_boxes(faces: Faces | None, max_faces: int) -> list[tuple[Box, str | None]] | None:
    """The face stage's faces as the person stage's (box, face id), so that it needs no face detector of its own on
    this frame; None (the person stage detects faces itself) when the face stage did not run on it, or found as
    many faces as it tracks (there may be more)."""
    if faces is None or len(faces.faces) >= max_faces:
        return None
    return [((f.bbox[0], f.bbox[1], f.bbox[2], f.bbox[3]), f.id) for f in faces.faces]


def people_bodies(
    frame: Frame, full: tuple[np.ndarray | None, list, float], rays3d: FrameRays | None, seen: PeopleOfFrame | None
) -> list[Body]:
    """The full-frame skeleton with the tracker's arms and its age (`full`), plus (on the person stage's frames)
    every other person's."""
    skeleton, arms, age_s = full
    main = [] if skeleton is None else [to_body(skeleton, arms, rays3d, age_s)]
    if seen is None:
        return main
    for body in main:
        body.person = seen.main_person
    others = (
        [(p.id, p.body) for p in seen.persons if p.id != seen.main_person and p.body is not None] if seen.ran else []
    )
    for pid, b in others:  # their own arms, this frame's; no 3-D rays (FrameRays lifts the full-frame skeleton)
        main.append(to_body(b, other_arms(b, frame.width, frame.height), age_s=seen.pose_ages.get(pid, 0.0)))
        main[-1].person = pid
    return main


def to_hand(o: Observation, t: TrackedHand, ray3d: Ray3D | None, person: str | None) -> Hand:
    # the tracker's words are the schema's (its classes and hands are GestureName and Handedness values)
    return Hand(
        hand=cast(Handedness, o.hand),
        score=round(o.score, 4),
        landmarks=[[round(x, 2), round(y, 2)] for x, y in o.landmarks.tolist()],
        gesture=cast(GestureName | None, t.gesture),
        ray=to_ray(t.ray, ray3d),
        person=person,
    )


def event_sample(
    frame: Frame,
    ev: Event,
    source: str,
    rays3d: FrameRays | None = None,
    hand_rays3d: dict[str, Ray3D | None] | None = None,
    seen: PeopleOfFrame | None = None,
) -> GestureEvent:
    """A tracker event of `frame` as the wire's GestureEvent (the shell publishes it; tests and benchmarks feed it
    to fusion): its 3-D ray when depth is known, its person when the person stage runs."""
    ray3d = None
    if ev.ray is not None and rays3d is not None:
        ray3d = rays3d.arm(ev.hand) if ev.ray.source == "body" else (hand_rays3d or {}).get(ev.hand)
    return GestureEvent(
        stamp=frame.stamp,
        source=source,
        cam=frame.cam,
        width=frame.width,
        height=frame.height,
        gesture=cast(GestureName, ev.gesture),
        phase=cast(GesturePhase, ev.phase),
        start=ev.start,
        end=ev.end,
        score=ev.score,
        hand=cast(Handedness, ev.hand),
        ray=to_ray(ev.ray, ray3d),
        person=event_person(seen, ev.hand, ev.ray),
        still=ev.still,
        raised=ev.raised,
    )
