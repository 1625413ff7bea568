"""At most N pose runs per person-stage run, in turn over the persons, their skeletons carried between (issue #42;
pure, no MediaPipe here).

The person stage (persons.py `observe_people`) runs pose on one region per person it does not already have a body
for: its cost grows with the people in view (~35 ms per extra person on a 2-core machine), so a busy room took
the gesture service's whole budget. With a cap of `max_poses`, a stage run poses at most that many regions:

* the regions the run will ask for are known before it (`planned_regions`: `observe_people` with a pose that finds
  nothing), each the region of a track: the one whose last skeleton's nose lies in it, else whose face box's centre
  does (a person seen by the face alone); a region of no track is a new person;
* the regions posed are the `max_poses` whose track was posed longest ago, a new person's first of all (one region
  per track: a person's face region before their last body's);
* every other region gets its track's last skeleton as it was (carried; `age` says how old), or none on this run
  when the track has no skeleton yet.

A carried skeleton still has to fit its face (`body_fits_face`): a person who moved away from it loses the body
for that run. Every track asked for is posed within ceil(n / max_poses) runs (`runs_to_pose_all`), n the regions
asked for: the longest unposed go first.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from common.boxes import iou
from services.gesture.persons import NOSE, Box, PersonTrack, body_box

MAX_POSES = 2  # pose runs per person-stage run at most (0: no cap): with the full-frame pose, 3 persons posed

PoseIn = Callable[[Box], "np.ndarray | None"]


def runs_to_pose_all(persons: int, cap: int) -> int:
    """Stage runs in which every one of `persons` persons needing a region pose is posed at least once, under a
    cap of `cap` per run (0: no cap): ceil(persons / cap)."""
    if persons <= 0:
        return 0
    return 1 if cap <= 0 else -(-persons // cap)


def region_track(region: Box, tracks: list[PersonTrack]) -> PersonTrack | None:
    """The track a region is for: the one whose last skeleton's nose lies in it (overlapping it most, if several),
    else one whose face box's centre does; None: a new person."""
    x, y, w, h = region

    def inside(px: float, py: float) -> bool:
        return x <= px <= x + w and y <= py <= y + h

    best: tuple[float, PersonTrack] | None = None
    for t in tracks:
        box = body_box(t.body) if t.body is not None else None
        if t.body is not None and box is not None and inside(float(t.body[NOSE, 0]), float(t.body[NOSE, 1])):
            overlap = iou(box, region)
            if best is None or overlap > best[0]:
                best = (overlap, t)
    if best is not None:
        return best[1]
    for t in tracks:
        if t.face_box is not None and inside(t.face_box[0] + t.face_box[2] / 2, t.face_box[1] + t.face_box[3] / 2):
            return t
    return None


def planned_regions(observe: Callable[[PoseIn], object]) -> list[Box]:
    """The regions a person-stage run asks pose for, in order, found by running it (`observe(pose_in)`) with a pose
    that finds nothing: pure and cheap (no model). It may list a person's last-body region besides their face's."""
    asked: list[Box] = []

    def nothing(region: Box) -> None:
        asked.append(region)

    observe(nothing)
    return asked


@dataclass
class RotationTurn:
    """One stage run's pose calls under the cap: call it with a region (as `observe_people`'s `pose_in`)."""

    pose: PoseIn  # the real pose on a region
    chosen: dict[Box, str | None]  # the regions posed on this run -> their track (None: a new person)
    tracks: list[PersonTrack]  # the tracker's tracks before this run
    uncapped: bool = False  # every region asked for is posed
    runs: int = 0
    tried: set[str] = field(default_factory=set)  # tracks whose region was posed on this run
    asked: set[str] = field(default_factory=set)
    carried: dict[int, str] = field(default_factory=dict)  # id() of a carried skeleton -> its track

    def __call__(self, region: Box) -> np.ndarray | None:
        if self.uncapped or region in self.chosen:
            track_id = self.chosen.pop(region, None)
            self.runs += 1
            if track_id is not None:
                self.tried.add(track_id)
            return self.pose(region)
        track = region_track(region, self.tracks)
        if track is None or track.body is None or track.id in self.asked:
            return None
        self.asked.add(track.id)
        self.carried[id(track.body)] = track.id
        return track.body


@dataclass
class PoseRotation:
    """One camera's turn-taking of the region poses over its person stage's runs (module docstring)."""

    max_poses: int = MAX_POSES
    run: int = 0  # stage runs so far
    last_posed: dict[str, int] = field(default_factory=dict)  # track id -> the run its skeleton was posed on
    posed_at: dict[str, float] = field(default_factory=dict)  # track id -> source stamp of that run
    posed: int = 0  # region poses run, over all runs
    carried: int = 0  # skeletons carried instead of posed, over all runs

    def turn(self, tracks: list[PersonTrack], regions: list[Box], pose: PoseIn) -> RotationTurn:
        """This run's pose calls: `tracks` are the person tracker's before the run, `regions` the ones it will ask
        for (`planned_regions`)."""
        self.run += 1
        first: dict[str | None, int] = {}  # one region per track; every new person's
        order: list[tuple[int, int, Box, str | None]] = []
        for k, region in enumerate(regions):
            track = region_track(region, tracks)
            key = track.id if track is not None else None
            if key is not None and key in first:
                continue
            if key is not None:
                first[key] = k
            order.append((self.last_posed.get(key, -1) if key is not None else -2, k, region, key))
        if self.max_poses > 0:
            order = sorted(order)[: self.max_poses]
        chosen = {region: key for _, _, region, key in order}
        return RotationTurn(pose, chosen, list(tracks), uncapped=self.max_poses <= 0)

    def done(self, turn: RotationTurn, stamp: float, persons: list[PersonTrack]) -> None:
        """The run's persons (the tracker's update): a skeleton not carried was posed now (by region or the
        full-frame pose); a track whose region was posed was tried now, whatever pose found."""
        self.posed += turn.runs
        for track_id in turn.tried:
            self.last_posed[track_id] = self.run
        for p in persons:
            if p.body is None:
                continue
            if id(p.body) in turn.carried:
                self.carried += 1
            else:
                self.last_posed[p.id] = self.run
                self.posed_at[p.id] = stamp
        live = {p.id for p in persons}
        for gone in [k for k in self.last_posed if k not in live]:
            del self.last_posed[gone]
            self.posed_at.pop(gone, None)

    def age(self, person: str, stamp: float) -> float:
        """Source seconds since `person`'s skeleton was posed (0 when unknown)."""
        return max(0.0, stamp - self.posed_at.get(person, stamp))
