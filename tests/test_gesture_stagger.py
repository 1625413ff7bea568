"""The paced stages staggered (issue #34, services/gesture/schedule.py) on real clips: the gesture service's whole
path as shipped against the same path with each stage on the frames it is due (`stagger=False`). The person and
face stages run as often, each run on the same frame or the next, and find the same people and faces; no frame
after the first runs pose together with another paced stage."""

from __future__ import annotations

import pytest

from common.boxes import iou
from services.gesture.core import FrameResult, GestureSettings
from services.gesture.schedule import FramePlan
from testkit.frames import run_gesture_on_clip
from testkit.shared import shared_path

FPS = 25.0  # the clips' own rate


def _run(stagger: bool, name: str) -> list[FrameResult]:
    """The clip's first 75 frames through the whole path; not staggered, the same run as
    tests/test_gesture_pose_pacing.py's at 10/s (shared: testkit.frames.run_gesture_on_clip)."""
    return run_gesture_on_clip(GestureSettings(stagger=stagger), shared_path(f"data/talking/{name}"), 75, FPS)


def _pairs(before: list[int], after: list[int]) -> list[tuple[int, int]]:
    """The k-th run of each path, side by side; each staggered run on the frame of its due run or the next."""
    assert len(before) - len(after) in (0, 1)  # a run owed at the last frame has not happened yet
    pairs = list(zip(before, after))
    assert all(0 <= b - a <= 1 for a, b in pairs), pairs
    return pairs


@pytest.mark.parametrize("name", ["comp_turns_bbaf2n_lbbc2a.mp4", "comp_dub_brbk7n_lbax4n_audioL.mp4"])
def test_staggered_stages_find_the_same_people_and_faces_on_two_person_clips(name: str) -> None:
    """Two people on a real 25 fps clip, 75 frames: with the stages staggered the Persons come as often (each at
        most one frame later) with the same ids, bodies and faces and boxes overlapping (IoU >= 0.6), the Faces as
        often with the same ids; pose runs on the same frames and, after the first, never with the hand search or the
    person stage."""
    before, after = _run(False, name), _run(True, name)
    assert len(before) == 75, name  # the clip has the frames
    persons_before = [k for k, r in enumerate(before) if r.persons is not None]
    persons_after = [k for k, r in enumerate(after) if r.persons is not None]
    assert len(persons_before) >= 35
    for a, b in _pairs(persons_before, persons_after):
        pa, pb = before[a].persons, after[b].persons
        assert pa is not None and pb is not None
        assert [(p.id, p.has_body, p.face) for p in pa.persons] == [(p.id, p.has_body, p.face) for p in pb.persons]
        assert len(pa.persons) == 2
        for p, q in zip(pa.persons, pb.persons):
            assert iou(p.bbox, q.bbox) >= 0.6
    faces_before = [k for k, r in enumerate(before) if r.faces is not None]
    faces_after = [k for k, r in enumerate(after) if r.faces is not None]
    for a, b in _pairs(faces_before, faces_after):
        fa, fb = before[a].faces, after[b].faces
        assert fa is not None and fb is not None
        assert [f.id for f in fa.faces] == [f.id for f in fb.faces]
    plans_before, plans_after = _plans(before), _plans(after)
    assert [p.pose for p in plans_before] == [p.pose for p in plans_after]
    assert [k for k, p in enumerate(plans_after[1:], 1) if p.pose and (p.hand_search or p.persons)] == []
    assert any(p.pose and p.persons for p in plans_before[1:])  # the case the schedule is there for
    # the face stage due on 4 frames of 5 (20/s at 25 fps) cannot leave every pose frame (3 of 5 are free): it
    # shares no more of them than before, and only when it was moved there from the frame before
    with_faces = [k for k, p in enumerate(plans_after[1:], 1) if p.pose and p.faces]
    assert len(with_faces) <= sum(1 for p in plans_before[1:] if p.pose and p.faces)
    assert all("faces" in plans_after[k - 1].deferred for k in with_faces)


def _plans(results: list[FrameResult]) -> list[FramePlan]:
    plans = [r.plan for r in results]
    assert all(p is not None for p in plans)
    return [p for p in plans if p is not None]
