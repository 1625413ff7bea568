"""Engagement with the robot (issue #40, common/engagement.py): the frame rule (head toward the camera, face in the
robot's field, within reach), the window (over the utterance and at its end), REP-155's levels on `Persons`, and
fusion's "said to the robot?" — on the real faces of ../shared/data/talking (tests/data/talking_faces.json, made by
the face stage) and of ../shared/data/people_multi (photos, through the face stage here)."""

from __future__ import annotations

import functools
import json

import msgspec
import pytest

from common.engagement import (
    EngagementConfig,
    EngagementTracker,
    engaged_flag,
    engaged_over,
    frame_engaged,
    head_angle,
    mark_engagement,
    next_level,
)
from common.schema import Face, Faces, Person, Persons
from services.fusion.speaker import attribute
from testkit.shared import shared_dir, shared_path
from testkit.talking import load_cache, person_of_face, talking_json, transcript_of, utterances

CFG = EngagementConfig()


def face(yaw: float | None, pitch: float | None = 0.0, bbox: tuple[float, ...] = (300, 200, 40, 50)) -> Face:
    return Face(id="cam0/face-1", bbox=list(bbox), score=0.5, yaw=yaw, pitch=pitch)


@functools.cache
def cached() -> dict[str, list[Faces]]:
    return load_cache()


# -- the frame rule --------------------------------------------------------------------------------------------
def test_head_angle_takes_yaw_and_pitch_together() -> None:
    assert head_angle(0.0, 0.0) == pytest.approx(0.0)
    assert head_angle(20.0, 0.0) == pytest.approx(20.0)
    assert head_angle(0.0, -20.0) == pytest.approx(20.0)
    assert head_angle(15.0, 15.0) == pytest.approx(21.1, abs=0.1)  # each alone would pass 20, together they do not
    assert head_angle(None, 0.0) is None


def test_a_frame_is_engaged_only_facing_the_robot_in_its_field_within_reach() -> None:
    width, height = 640, 480  # a 60 deg camera: focal 554 px
    centre = (300, 200, 40, 50)
    assert frame_engaged(face(10.0, bbox=centre), width, height, CFG).engaged is True
    assert frame_engaged(face(15.0, 15.0, bbox=centre), width, height, CFG).engaged is False  # head turned
    assert frame_engaged(face(None, bbox=centre), width, height, CFG).engaged is None  # orientation not known
    # the field: a frontal face at the corner of a 120 deg camera is ~52 deg off its axis (> 30)
    wide = EngagementConfig(engage_camera_fov=120.0)
    corner = frame_engaged(face(0.0, bbox=(0, 0, 40, 50)), width, height, wide)
    assert corner.off_axis > 30 and corner.engaged is False
    # reach: a face 50 px tall with a 554 px focal is 554 * 0.19 / 50 = 2.1 m; 20 px tall, 5.3 m
    near = frame_engaged(face(0.0, bbox=centre), width, height, CFG)
    assert near.distance == pytest.approx(2.1, abs=0.05) and not near.from_depth
    far = frame_engaged(face(0.0, bbox=(310, 215, 16, 20)), width, height, CFG)
    assert far.distance > 4.0 and far.engaged is False
    # depth, when known, wins over the face's size
    measured = frame_engaged(face(0.0, bbox=(310, 215, 16, 20)), width, height, CFG, distance=3.0)
    assert measured.from_depth and measured.distance == 3.0 and measured.engaged is True


def _series(f: Face, stamps: list[float], width: int = 640, height: int = 480) -> list[Faces]:
    return [
        Faces(stamp=s, source="test/gesture", seq=i, cam="cam0", width=width, height=height, faces=[f])
        for i, s in enumerate(stamps)
    ]


def test_the_window_needs_the_utterance_and_its_end() -> None:
    stamps = [10.0 + i * 0.05 for i in range(41)]  # 10.0 - 12.0 at 20 fps
    toward, away = face(5.0), face(40.0)
    frames = [msgspec.structs.replace(s, faces=[toward if s.stamp < 11.2 else away]) for s in _series(toward, stamps)]
    turned_away_at_the_end = engaged_over(frames, "cam0/face-1", 10.0, 12.0)
    assert turned_away_at_the_end.share is not None and turned_away_at_the_end.share >= 0.5
    assert turned_away_at_the_end.share_at_end == 0.0 and turned_away_at_the_end.engaged is False
    frames = [msgspec.structs.replace(s, faces=[away if s.stamp < 10.9 else toward]) for s in _series(toward, stamps)]
    turned_toward = engaged_over(frames, "cam0/face-1", 10.0, 12.0)
    assert turned_toward.engaged is True and "at the end" in turned_toward.reason
    unknown = engaged_over(_series(face(None), stamps), "cam0/face-1", 10.0, 12.0)
    assert unknown.engaged is None and unknown.frames == 0
    assert engaged_over(frames, "person-9", 10.0, 12.0).engaged is None  # nobody of that id in view


def test_depth_of_the_person_gives_the_distance() -> None:
    stamps = [10.0 + i * 0.1 for i in range(11)]
    small = msgspec.structs.replace(face(0.0, bbox=(310, 215, 16, 20)), person="person-1")  # 5.3 m by its size
    frames = _series(small, stamps)
    assert engaged_over(frames, "person-1", 10.0, 11.0).engaged is False
    persons = [
        Persons(
            stamp=s,
            source="test/gesture",
            seq=i,
            cam="cam0",
            width=640,
            height=480,
            persons=[Person(id="person-1", bbox=[300, 200, 60, 200], score=0.9, position=[0.1, 0.2, 2.5])],
        )
        for i, s in enumerate(stamps)
    ]
    by_depth = engaged_over(frames, "person-1", 10.0, 11.0, persons=persons)
    assert (
        by_depth.engaged is True and by_depth.distance == pytest.approx(2.51, abs=0.01) and "depth" in by_depth.reason
    )


# -- REP-155 levels --------------------------------------------------------------------------------------------
def test_levels_follow_hri_engagement_transitions() -> None:
    assert next_level("unknown", 1.0) == "disengaged"  # first seen: disengaged, then it rises
    assert next_level("disengaged", -0.3) == "engaging" and next_level("disengaged", -0.5) == "disengaged"
    assert next_level("engaging", 0.6) == "engaged" and next_level("engaging", -0.7) == "disengaged"
    assert next_level("engaged", 0.3) == "disengaging" and next_level("engaged", 0.45) == "engaged"
    assert next_level("disengaging", 0.7) == "engaged" and next_level("disengaging", -0.6) == "disengaged"
    assert [engaged_flag(level) for level in ("unknown", "disengaged", "engaging", "engaged", "disengaging")] == [
        None,
        False,
        False,
        True,
        True,
    ]


def test_tracker_on_a_real_face_that_turns_away_and_back() -> None:
    """grid_single_lbax4n's real face series (frontal, 25 fps, 3 s) played, then the same frames with the head
    read 35 deg further turned (what Face Mesh reads for a head turned ~45: people_multi), then frontal again."""
    frames = cached()["grid_single_lbax4n.mpg"]
    span = frames[-1].stamp - frames[0].stamp + 0.04
    turned = [
        msgspec.structs.replace(
            s, stamp=s.stamp + span, faces=[msgspec.structs.replace(f, yaw=(f.yaw or 0) + 35) for f in s.faces]
        )
        for s in frames
    ]
    back = [msgspec.structs.replace(s, stamp=s.stamp + 2 * span) for s in frames]
    tracker = EngagementTracker()
    levels: list[str] = []
    between: list[bool | None] = []  # engaged_between over the last second, at the end of each part
    for part in (frames, turned, back):
        for sample in part:
            tracker.update(sample)
            level = tracker.level(sample.faces[0].id)
            if not levels or levels[-1] != level:
                levels.append(level)
        t1 = part[-1].stamp
        between.append(tracker.engaged_between(part[-1].faces[0].id, t1 - 1.0, t1))
    assert between == [True, False, True]
    assert tracker.engaged_between("cam0/face-9", 0.0, 1e12) is None
    assert levels == [
        "unknown",
        "disengaged",
        "engaging",
        "engaged",
        "disengaging",
        "disengaged",
        "engaging",
        "engaged",
    ]


def test_persons_carry_the_level_of_their_face() -> None:
    frames = cached()["comp_turns_bbaf2n_lbbc2a.mp4"]
    tracker = EngagementTracker()
    for sample in frames[:40]:
        tracker.update(sample)
    ids = sorted({f.id for f in frames[39].faces})
    persons = Persons(
        stamp=frames[39].stamp,
        source="test/gesture",
        seq=39,
        cam="cam0",
        width=724,
        height=288,
        persons=[Person(id=f"person-{k}", bbox=[0, 0, 10, 10], score=1.0, face=i) for k, i in enumerate(ids)]
        + [Person(id="person-9", bbox=[0, 0, 10, 10], score=1.0)],
    )
    mark_engagement(persons, tracker)
    assert [(p.engagement, p.engaged) for p in persons.persons] == [("engaged", True)] * 2 + [(None, None)]
    assert Persons.from_dict(persons.to_dict()) == persons  # on the wire as a v1 extension


# -- real material ---------------------------------------------------------------------------------------------
def test_every_labelled_speaker_of_the_talking_clips_is_engaged() -> None:
    """All faces of ../shared/data/talking face the camera: each utterance's speaker is engaged over it."""
    shared_path("data/talking/talking.json")
    count = 0
    for clip in talking_json()["clips"]:
        faces = cached()[clip["clip"]]
        mapping = person_of_face(clip, faces)
        for u in utterances(clip):
            face_id = next(i for i, p in mapping.items() if p == u.speaker)
            t = transcript_of(u)
            result = engaged_over(faces, face_id, t.start, t.end)
            assert result.engaged is True, (clip["clip"], u, result)
            count += 1
    assert count == 15


def _people_multi_faces() -> list[tuple[str, str, str, Faces]]:
    """(file, person, label, one-frame Faces) for each face the face stage finds on the people_multi photos."""
    import cv2

    from services.gesture.faces import FaceConfig, FaceStage

    labels = json.loads(shared_path("data/people_multi/people_multi.json").read_text())
    out = []
    for image in labels["images"]:
        img = cv2.imread(str(shared_dir() / "data/people_multi" / image["file"]))
        assert img is not None
        stage = FaceStage(FaceConfig(), video=False)
        found = stage.process(img, 1.0)
        stage.close()
        for f in found:
            cx = f.bbox[0] + f.bbox[2] / 2
            person = next(
                p
                for p in image["people"]
                if p["head_box"] and abs(cx - p["head_box"][0] - p["head_box"][2] / 2) < p["head_box"][2] / 2
            )
            h, w = img.shape[:2]
            sample = Faces(stamp=1.0, source="test/gesture", seq=0, cam="cam0", width=w, height=h, faces=[f])
            out.append((image["file"], person["id"], person["faces_camera"], sample))
    return out


def test_people_turned_away_on_real_photos_are_not_engaged() -> None:
    """../shared/data/people_multi: the two faces labelled turned away (~40 deg; three-quarter view) are not engaged
    (the old single-frame rule needed `look_yaw` 25 to hold them, with 5 deg to spare), and the near-frontal ones
    looking at the camera are; held as a 2 s still, as if the person kept the pose through an utterance."""
    turned, looking = [], []
    for name, pid, label, sample in _people_multi_faces():
        still = [msgspec.structs.replace(sample, stamp=1.0 + k * 0.1, seq=k) for k in range(21)]
        result = engaged_over(still, sample.faces[0].id, 1.0, 3.0)
        if label.startswith("no"):
            turned.append((name, pid, result))
        elif "eyes on the camera" in label or "frontal" in label:
            looking.append((name, pid, result))
    assert len(turned) >= 2 and len(looking) >= 4, (turned, looking)
    assert all(r.engaged is False for *_, r in turned), turned
    assert all(r.engaged is True for *_, r in looking), looking


def test_a_speaker_turned_away_is_not_addressed_in_fusion_attribution() -> None:
    """comp_turns_bbaf2n_lbbc2a, P1's turn: the real face series with P1's head read 24 deg off the camera
    (a real turn of about 30-35 deg, read short by Face Mesh): the old rule (25 deg, half the frames) took it as
    said to the robot; now the speaker is still found, and not addressed."""
    shared_path("data/talking/talking.json")  # skip, saying why, on a clone without ../shared
    clip = next(c for c in talking_json()["clips"] if c["clip"] == "comp_turns_bbaf2n_lbbc2a.mp4")
    u = utterances(clip)[1]
    faces = cached()[clip["clip"]]
    mapping = person_of_face(clip, faces)
    turned = [
        msgspec.structs.replace(
            s,
            faces=[
                msgspec.structs.replace(f, yaw=24.0, looking_at_camera=True) if mapping[f.id] == "P1" else f
                for f in s.faces
            ],
        )
        for s in faces
    ]
    speaker = attribute(transcript_of(u), turned)
    assert mapping.get(speaker.person or "") == "P1" and speaker.addressed is False
    assert attribute(transcript_of(u), faces).addressed is True  # as recorded: frontal, addressed


def test_the_gesture_service_publishes_the_level_on_persons() -> None:
    """The gesture core's whole path on a real two-person clip (both facing the camera, 75 frames at 25 fps): the
    Persons it publishes carry REP-155 levels that rise to `engaged` for both, with `engaged` true."""
    from services.gesture.core import GestureSettings
    from testkit.frames import read_frames, run_gesture

    images = read_frames(shared_path("data/talking/comp_turns_bbaf2n_lbbc2a.mp4"), 75)
    results = run_gesture(GestureSettings(), images, 25.0)
    published = [r.persons for r in results if r.persons is not None]
    assert len(published) >= 30
    first, last = published[0], published[-1]
    assert all(p.engagement is None for p in first.persons)  # nothing judged yet: unknown (nil)
    assert len(last.persons) == 2 and all(p.face is not None for p in last.persons)
    assert [(p.engagement, p.engaged) for p in last.persons] == [("engaged", True)] * 2
    levels = [p.engagement for s in published for p in s.persons if p.engagement is not None]
    # hri_engagement's way up from unknown (first seen: disengaged), and never down for people who keep facing it
    assert levels[0] == "disengaged" and set(levels) <= {"disengaged", "engaging", "engaged"}
