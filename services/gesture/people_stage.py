"""The person stage of one camera (issue #33), the gesture shell's helper: MediaPipe face detection and pose per
person region feeding the pure tracker (services/gesture/persons.py), turned into the wire's `Person` list, each
hand's and skeleton's person id, and a body for every person.

Its faces are MediaPipe's full-range face detection on every run (faces at room distance, which the face stage's
Face Mesh misses beyond ~2 m) merged with the face stage's on the frames that stage ran on (their boxes and ids win
where both found a face; `persons.merge_faces`, issue #40). It runs on every `every`-th frame of a camera
(`--persons-every`: pose per extra person costs a full pose run, ~35 ms on this machine); on the frames between,
hands are given to the persons of the last run (their boxes and wrists are at most `every - 1` frames old).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import cast

import numpy as np

from common.image import frame_fields
from common.schema import Frame, Handedness, Person, Persons
from services.gesture.body import Arm, arm
from services.gesture.landmarks import FaceDetector, RegionPose
from services.gesture.persons import (
    Box,
    PersonTrack,
    PersonTracker,
    Seen,
    assign_hands,
    crop_int,
    merge_faces,
    observe_people,
)
from services.gesture.pose_rotation import PoseRotation, planned_regions
from services.gesture.space import FrameRays, torso_point
from services.gesture.temporal import Observation, Ray as TrackedRay


@dataclass
class PeopleOfFrame:
    """What the stage says about one frame."""

    ran: bool  # the stage ran on this frame (publish Persons); else the last run's persons are reused
    persons: list[PersonTrack]
    hand_owners: list[str | None]  # per hand observation
    hand_sides: list[str]  # per hand observation: "left" / "right"
    main_person: str | None  # the person of the full-frame skeleton (the gesture tracker's arms)
    positions: dict[str, list[float]] = field(default_factory=dict)  # id -> torso centre, metres (with depth)
    frame_id: str | None = None
    pose_ages: dict[str, float] = field(default_factory=dict)  # id -> s since its skeleton was posed (carried: > 0)


def hand_person(seen: PeopleOfFrame | None, k: int) -> str | None:
    """The person of the frame's k-th hand observation (None: no stage, or nobody's)."""
    return seen.hand_owners[k] if seen is not None else None


def other_skeletons(seen: PeopleOfFrame | None) -> list[np.ndarray]:
    """The skeletons of the persons other than the full-frame skeleton's (the stage's last run between its runs)."""
    if seen is None:
        return []
    return [p.body for p in seen.persons if p.body is not None and p.id != seen.main_person]


def event_person(seen: PeopleOfFrame | None, hand: str, ray: TrackedRay | None) -> str | None:
    """The person of a gesture event: for an arm seen by pose alone (a `body` ray), the full-frame skeleton's
    person; else the person of this frame's hand of that side."""
    if seen is None:
        return None
    if ray is not None and ray.source == "body":
        return seen.main_person
    return next((owner for side, owner in zip(seen.hand_sides, seen.hand_owners) if side == hand), None)


class PeopleStage:
    """One camera's person stage: its face detector, its pose-per-region graph and its person tracker."""

    def __init__(self, every: int = 2, keep_s: float = 1.0, max_poses: int = 0):
        self.every = every
        self.keep_s = keep_s
        self.max_poses = max_poses  # region poses per run at most, in turn over the persons (pose_rotation.py)
        self.faces = FaceDetector()
        self.regions = RegionPose()
        self.restart()

    def restart(self) -> None:
        """A new stream: new person ids. The models are kept: neither holds state between frames (single-image
        detection), and building MediaPipe graphs again on every restart costs time and memory."""
        self.tracker = PersonTracker(keep_s=self.keep_s)
        self.rotation = PoseRotation(self.max_poses)
        self.frames = 0  # frames counted by `due`
        self.last: list[PersonTrack] = []
        self.main: str | None = None

    def update(
        self,
        stamp: float,
        img: np.ndarray,
        skeleton: np.ndarray | None,
        hands: list[Observation],
        rays3d: FrameRays | None = None,
        faces: list[tuple[Box, str | None]] | None = None,
        run: bool | None = None,
    ) -> PeopleOfFrame:
        """`faces`: the face stage's faces of this frame (box, `Face.id`) when it ran on it; the stage's own
        full-range face detection adds the faces they miss (boxes without ids). `run`: whether the stage runs on this
        frame (the gesture core's schedule, which asked `due`); None: it runs when `due`."""
        ran = self.due() if run is None else run
        if ran:
            h, w = img.shape[:2]
            previous = [b for _, b in self.tracker.bodies()]
            detected = [box for box, _ in self.faces.detect(img)]  # full range: faces at room distance too
            seen = Seen(w, h, merge_faces(faces or [], detected), skeleton, previous)
            regions = planned_regions(lambda pose_in: observe_people(seen, pose_in))
            turn = self.rotation.turn(self.tracker.tracks, regions, lambda r: self.regions.detect(img, crop_int(r)))
            found = observe_people(seen, turn)
            self.last = self.tracker.update(stamp, found)
            self.rotation.done(turn, stamp, self.last)
            # the full-frame skeleton's person: the tracker's arms (pointing, raised palms) are theirs
            self.main = next((p.id for p in self.last if skeleton is not None and p.body is skeleton), None)
        owners = assign_hands([(o.hand, o.landmarks) for o in hands], self.last)
        out = PeopleOfFrame(ran, self.last, owners, [o.hand for o in hands], self.main)
        out.pose_ages = {p.id: self.rotation.age(p.id, stamp) for p in self.last if p.body is not None}
        view = rays3d.view if rays3d is not None and ran else None
        if view is not None:
            out.frame_id = view.frame_id
            for p in self.last:
                point = torso_point(view, p.body) if p.body is not None else None
                if point is not None:
                    out.positions[p.id] = [round(float(v), 3) for v in point]
        return out

    def due(self) -> bool:
        """Whether the stage is due on this frame: every `every`-th frame since the stream (re)started."""
        due = self.frames % self.every == 0
        self.frames += 1
        return due

    def wire(self, people: PeopleOfFrame) -> list[Person]:
        """The persons of a frame as the wire's `Person`s (`face` stays nil until a face tracker names faces)."""
        hands: dict[str, list[Handedness]] = {}
        for side, owner in zip(people.hand_sides, people.hand_owners):
            if owner is not None:
                hands.setdefault(owner, []).append(cast(Handedness, side))
        return [
            Person(
                id=p.id,
                bbox=[round(v, 1) for v in p.box],
                score=round(p.score, 3),
                face=p.face_id,
                has_body=p.body is not None,
                hands=sorted(hands.get(p.id, [])),
                position=people.positions.get(p.id),
                frame_id=people.frame_id if p.id in people.positions else None,
            )
            for p in people.persons
        ]

    def face_owners(self) -> dict[str, str]:
        """Face id -> person id of the persons seen last (`Face.person` for the face stage's samples)."""
        return {p.face_id: p.id for p in self.last if p.face_id is not None and p.seen_now}

    def close(self) -> None:
        self.faces.close()
        self.regions.close()


def other_arms(landmarks: np.ndarray, width: int, height: int) -> list[tuple[Arm, TrackedRay | None]]:
    """The arms of a person other than the gesture tracker's, judged on this frame alone (no hysteresis, no
    steadying), in the shape of `GestureTracker.last_arms` (the shell's `to_body` makes the wire `Body`)."""
    out: list[tuple[Arm, TrackedRay | None]] = []
    for side in ("left", "right"):
        a = arm(landmarks, side, width, height)
        ray = TrackedRay(a.ray[0], a.ray[1], a.confidence, "body") if a.pointing and a.ray is not None else None
        out.append((a, ray))
    return out


class CameraPeople:
    """The person stage of every camera (`every` 0: off). A camera whose stream restarts (`fresh`: new, or gone
    quiet and back) restarts its tracker: new ids (the models are kept)."""

    def __init__(self, every: int, max_poses: int = 0):
        self.every = every
        self.max_poses = max_poses
        self.stages: dict[str, PeopleStage] = {}
        self.persons: dict[str, Persons] = {}  # cam -> the Persons of the stage's last run (the face stage links to)

    def due(self, frame: Frame, fresh: bool) -> bool:
        """Whether the stage is due on this frame of its camera (`PeopleStage.due`); a camera's stage is made here
        on its first frame and restarted when its stream is `fresh`."""
        if not self.every:
            return False
        if frame.cam not in self.stages:
            self.stages[frame.cam] = PeopleStage(every=self.every, max_poses=self.max_poses)
        elif fresh:
            self.stages[frame.cam].restart()
        return self.stages[frame.cam].due()

    def update(
        self,
        frame: Frame,
        img: np.ndarray,
        skeleton: np.ndarray | None,
        hands: list[Observation],
        rays3d: FrameRays | None,
        fresh: bool,
        faces: list[tuple[Box, str | None]] | None = None,
        run: bool | None = None,
    ) -> PeopleOfFrame | None:
        """`faces`: the face stage's faces of this frame, when it ran on it (PeopleStage.update). `run`: whether
        the stage runs on this frame (the gesture core's schedule, which asked `due` with `fresh`); None: it runs
        when `due`."""
        if not self.every:
            return None
        ran = self.due(frame, fresh) if run is None else run
        if frame.cam not in self.stages:  # `run` given without `due` asked first
            self.stages[frame.cam] = PeopleStage(every=self.every, max_poses=self.max_poses)
        return self.stages[frame.cam].update(frame.stamp, img, skeleton, hands, rays3d, faces, run=ran)

    def sample(self, frame: Frame, seen: PeopleOfFrame, source: str) -> Persons:
        """The `Persons` of a frame the stage ran on."""
        return Persons(**frame_fields(frame, source), persons=self.stages[frame.cam].wire(seen))

    def close(self) -> None:
        for stage in self.stages.values():
            stage.close()
