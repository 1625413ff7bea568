"""Who is speaking (issue #33): the face stage on the real talking clips and the attribution core on their face
series (tests/data/talking_faces.json, made by our face stage from ../shared/data/talking/, see testkit/talking.py)
with the clips' labelled speech intervals as utterances."""

from __future__ import annotations

import functools

import msgspec
import numpy as np
import pytest

from common.schema import Face, Faces, Speaker
from services.fusion.speaker import FaceHistory, SpeakerConfig, attribute
from services.gesture.faces import FaceConfig, FaceTracker, head_angles, looking_at
from testkit.shared import shared_dir, shared_path
from testkit.talking import (
    CACHE,
    T0,
    TALKING,
    Utterance,
    extract,
    load_cache,
    person_of_face,
    talking_json,
    transcript_of,
    utterances,
)


@functools.cache
def cached() -> dict[str, list[Faces]]:
    return load_cache()


@functools.cache
def clips() -> dict[str, dict]:
    """talking.json's clips by name (the labels; the face series come from the cache)."""
    path = shared_path(f"{TALKING}/talking.json")
    assert path.exists()
    return {c["clip"]: c for c in talking_json()["clips"]}


def run(clip: str, u: Utterance, keep: set[str] | None = None) -> tuple[Speaker, str | None]:
    """Attribute `u` on the clip's faces (only the people in `keep`, when given); the speaker's label (P0, P1)."""
    faces = cached()[clip]
    mapping = person_of_face(clips()[clip], faces)
    if keep is not None:
        faces = [msgspec.structs.replace(s, faces=[f for f in s.faces if mapping[f.id] in keep]) for s in faces]
    speaker = attribute(transcript_of(u), faces)
    return speaker, mapping.get(speaker.person) if speaker.person else None


def all_utterances(prefix: str) -> list[tuple[str, Utterance]]:
    return [(name, u) for name, c in clips().items() if name.startswith(prefix) for u in utterances(c)]


def test_one_person_in_view_is_the_speaker() -> None:
    cases = all_utterances("grid_single_") + all_utterances("real_single_")
    assert len(cases) == 9
    for clip, u in cases:
        speaker, who = run(clip, u)
        assert (who, speaker.method) == ("P0", "only_face"), (clip, u, speaker)
        assert speaker.confidence >= 0.6 and speaker.addressed is True  # frontal faces, mouth moving


def test_two_people_taking_turns_the_talking_mouth_wins() -> None:
    cases = all_utterances("comp_turns_")
    assert len(cases) == 4
    for clip, u in cases:
        speaker, who = run(clip, u)
        assert (who, speaker.method) == (u.speaker, "mouth_motion"), (clip, u, speaker)
        assert speaker.confidence >= 0.7
        assert "not " in speaker.reason  # the other person is named as not speaking


def test_both_mouths_move_over_one_voice_never_the_silent_one() -> None:
    cases = all_utterances("comp_dub_")
    assert len(cases) == 2  # the same pixels, the audio of the left, then of the right person
    for clip, u in cases:
        speaker, who = run(clip, u)
        assert who in (u.speaker, None), (clip, u, speaker)
        if who is None:
            assert speaker.method == "unknown" and speaker.confidence == 0.0
            assert "both moved" in speaker.reason


def test_the_only_face_in_view_with_a_still_mouth_is_not_the_speaker() -> None:
    """The listener of a turn alone in view (the speaker cut out): the voice is someone else's."""
    clip, u = all_utterances("comp_turns_lbax4n")[1]  # P0 speaks 3.42-5.06; P1 listens
    listener = {"P0": "P1", "P1": "P0"}[u.speaker]
    speaker, who = run(clip, u, keep={listener})
    assert who is None and speaker.method == "unknown", speaker
    assert "still" in speaker.reason
    speaker, who = run(clip, u, keep={u.speaker})  # and the speaker alone is the only face
    assert (who, speaker.method) == (u.speaker, "only_face")


def test_no_face_in_view_is_unknown() -> None:
    clip, u = all_utterances("comp_turns_bbaf2n")[0]
    speaker, who = run(clip, u, keep=set())
    assert who is None and speaker.method == "unknown" and "no face" in speaker.reason
    assert attribute(transcript_of(u), []).method == "unknown"


def test_mouths_not_seen_is_unknown_with_two_faces() -> None:
    clip, u = all_utterances("comp_turns_bbaf2n")[0]
    faces = [
        msgspec.structs.replace(s, faces=[msgspec.structs.replace(f, mouth_open=None) for f in s.faces])
        for s in cached()[clip]
    ]
    speaker = attribute(transcript_of(u), faces)
    assert speaker.method == "unknown" and "no mouth" in speaker.reason


def test_speaking_while_facing_away_is_not_addressed() -> None:
    clip, u = all_utterances("comp_turns_bbaf2n")[1]  # P1 speaks
    mapping = person_of_face(clips()[clip], cached()[clip])
    faces = [
        msgspec.structs.replace(
            s,
            faces=[
                msgspec.structs.replace(f, looking_at_camera=False, yaw=55.0) if mapping[f.id] == "P1" else f
                for f in s.faces
            ],
        )
        for s in cached()[clip]
    ]
    speaker = attribute(transcript_of(u), faces)
    assert mapping.get(speaker.person or "") == "P1" and speaker.addressed is False


def test_person_id_is_preferred_to_the_face_id() -> None:
    clip, u = all_utterances("comp_turns_bbaf2n")[0]  # P0 speaks
    mapping = person_of_face(clips()[clip], cached()[clip])
    faces = [
        msgspec.structs.replace(
            s, faces=[msgspec.structs.replace(f, person=f"person-{mapping[f.id]}") for f in s.faces]
        )
        for s in cached()[clip]
    ]
    assert attribute(transcript_of(u), faces).person == "person-P0"


def test_a_stricter_margin_turns_a_clear_case_unknown_never_wrong() -> None:
    clip, u = all_utterances("comp_turns_bbaf2n")[0]
    strict = SpeakerConfig(speaker_min_timing=-1.0, speaker_still=0.0, speaker_margin=2.0)
    speaker = attribute(transcript_of(u), cached()[clip], strict)
    assert speaker.person is None and speaker.method == "unknown"


def test_face_history_prunes_by_source_time_and_resets_when_the_timeline_goes_back() -> None:
    history = FaceHistory(horizon=2.0)
    samples = cached()["comp_turns_bbaf2n_lbbc2a.mp4"]
    for s in samples:
        history.add(s)
    assert 49 <= len(history) <= 51  # 2 s of 25 fps
    assert all(s.stamp >= samples[-1].stamp - 2.0 for s in history.samples)
    kept = len(history)
    assert not history.add(samples[0])  # one stray old stamp is dropped, the buffer stays
    assert len(history) == kept
    for s in samples[:10]:  # the replay restarted: old stamps keep coming, the buffer starts over
        history.add(s)
    assert [s.stamp for s in history.samples] == [s.stamp for s in samples[8:10]]  # the 10th stale in a row


# -- the face stage -------------------------------------------------------------------------------------------


def test_face_tracks_keep_their_ids_over_every_clip() -> None:
    for name, samples in cached().items():
        people = len(clips()[name]["people"])
        ids = {f.id for s in samples for f in s.faces}
        assert len(ids) == people, (name, ids)
        assert all(len(s.faces) == people for s in samples), name  # Face Mesh tracks every face in every frame


def test_tracker_keeps_an_id_through_a_short_miss_and_gives_a_new_one_after() -> None:
    tracker = FaceTracker(keep=0.5)
    a, b = [100.0, 100.0, 80.0, 80.0], [400.0, 100.0, 80.0, 80.0]
    first = tracker.update(1.0, [a, b])
    assert tracker.update(1.04, [[104.0, 101.0, 80.0, 80.0], b]) == first
    assert tracker.update(1.3, [b]) == [first[1]]  # a is missed
    assert tracker.update(1.4, [[130.0, 100.0, 80.0, 80.0], b]) == first  # a back (moved: centre match)
    assert tracker.update(3.0, [a, b]) == first  # no frame for 1.6 s (a slow stage) is no miss
    assert tracker.update(3.1, [b]) == [first[1]]
    assert tracker.update(3.7, [a])[0] not in first  # missed longer than keep: a new face
    assert tracker.update(1.0, [a])[0] not in first  # time went back: start afresh


def test_head_angles_follow_the_turn_of_the_mesh() -> None:
    """A real mesh (first frame of a frontal GRID face) rotated about the vertical axis reads as that yaw."""
    clip = shared_path(f"{TALKING}/grid_single_bbaf2n.mpg")
    import cv2

    from services.gesture.faces import FaceMesher

    cap = cv2.VideoCapture(str(clip))
    ok, img = cap.read()
    cap.release()
    assert ok
    mesher = FaceMesher(1, video=False)
    mesh = mesher.detect(img)[0]
    mesher.close()
    yaw0, pitch0 = head_angles(mesh) or (0.0, 0.0)
    assert abs(yaw0) < 15 and abs(pitch0) < 20
    centre = np.nanmean(mesh, axis=0)
    for degrees in (-50.0, -20.0, 30.0, 60.0):
        r = np.radians(degrees)
        # a turn to the image's right moves the nose to +x: x' = x cos + z sin... with z towards the camera negative
        rot = np.array([[np.cos(r), 0.0, -np.sin(r)], [0.0, 1.0, 0.0], [np.sin(r), 0.0, np.cos(r)]])
        yaw, _ = head_angles((mesh - centre) @ rot.T + centre) or (0.0, 0.0)
        assert yaw == pytest.approx(yaw0 + degrees, abs=3.0)
        assert looking_at(yaw, 0.0, FaceConfig()) is (abs(yaw) <= FaceConfig().look_yaw)


def test_cache_is_what_the_face_stage_gives_now() -> None:
    """The cached series are our face stage's output: recompute one two-person clip and compare."""
    name = "comp_turns_bbaf2n_lbbc2a.mp4"
    fresh = extract(shared_path(f"{TALKING}/{name}"))
    old = cached()[name]
    assert [s.stamp for s in fresh] == [s.stamp for s in old]
    for a, b in zip(fresh, old):
        for fa, fb in zip(a.faces, b.faces):
            assert fa.id == fb.id
            assert fa.mouth_open == pytest.approx(fb.mouth_open, abs=0.01)
            assert fa.yaw == pytest.approx(fb.yaw, abs=1.0)
    assert CACHE.stat().st_size < 200_000
    assert str(shared_dir()) not in CACHE.read_text()
    assert T0 > 0


def test_looking_at_the_camera_on_real_photos_of_several_people() -> None:
    """../shared/data/people_multi: each face the stage finds, matched to a labelled head, against the label "faces
    the camera". A face turned away must never read as looking (a command would then go unconfirmed)."""
    import json

    import cv2

    from services.gesture.faces import FaceStage

    labels = json.loads(shared_path("data/people_multi/people_multi.json").read_text())
    facing: list[tuple[str, str, Face]] = []
    turned: list[tuple[str, str, Face]] = []
    for image in labels["images"]:
        img = cv2.imread(str(shared_dir() / "data/people_multi" / image["file"]))
        assert img is not None
        stage = FaceStage(FaceConfig(), video=False)
        faces = stage.process(img, 1.0)
        stage.close()
        for face in faces:
            cx, cy = face.bbox[0] + face.bbox[2] / 2, face.bbox[1] + face.bbox[3] / 2
            person = next(
                p
                for p in image["people"]
                if p["head_box"]
                and abs(cx - (p["head_box"][0] + p["head_box"][2] / 2)) < p["head_box"][2] / 2
                and abs(cy - (p["head_box"][1] + p["head_box"][3] / 2)) < p["head_box"][3] / 2
            )
            said = person["faces_camera"].split(" ")[0]
            (facing if said == "yes" else turned).append((image["file"], person["id"], face))
    assert len(turned) >= 2 and len(facing) >= 4  # what Face Mesh finds there (faces of 50-80 px)
    assert all(f.looking_at_camera is False for _, _, f in turned), turned
    assert sum(f.looking_at_camera is True for _, _, f in facing) >= len(facing) - 1, facing
    # the sign: intel_headpose_pair_f000's P0 is turned ~40 degrees to the image's left
    yaw = next(f.yaw for name, pid, f in turned if (name, pid) == ("intel_headpose_pair_f000.png", "P0"))
    assert yaw is not None and yaw < -15


def test_faces_are_tied_to_the_person_whose_box_holds_them() -> None:
    from common.schema import Person, Persons
    from services.gesture.faces import link_faces

    sample = cached()["comp_turns_bbaf2n_lbbc2a.mp4"][0]
    left, right = sorted(sample.faces, key=lambda f: f.bbox[0])
    persons = Persons(
        stamp=sample.stamp,
        source="test/g",
        seq=0,
        cam="cam0",
        width=sample.width,
        height=sample.height,
        persons=[
            Person(id="person-7", bbox=[left.bbox[0] - 20, left.bbox[1] - 10, 200, 280], score=0.9),
            Person(id="person-8", bbox=[right.bbox[0] - 30, right.bbox[1] - 5, 190, 283], score=0.9),
        ],
    )
    faces = msgspec.structs.replace(sample, faces=[msgspec.structs.replace(f) for f in sample.faces])
    link_faces(faces, persons)
    by_id = {f.id: f.person for f in faces.faces}
    assert (by_id[left.id], by_id[right.id]) == ("person-7", "person-8")
    assert [p.face for p in persons.persons] == [left.id, right.id]
    link_faces(faces, None)  # no person stage: nothing changes
    assert {f.id: f.person for f in faces.faces} == by_id


def test_a_face_track_keeps_one_speaker_when_the_person_tracker_misses_frames() -> None:
    """Face.person set on most frames, nil on some (the person stage runs every other frame): one track, the
    person's id."""
    clip, u = all_utterances("comp_turns_bbaf2n")[0]  # P0 (left) speaks
    mapping = person_of_face(clips()[clip], cached()[clip])
    faces = [
        msgspec.structs.replace(
            s,
            faces=[
                msgspec.structs.replace(f, person=None if s.seq % 3 == 0 else f"person-{mapping[f.id]}")
                for f in s.faces
            ],
        )
        for s in cached()[clip]
    ]
    speaker = attribute(transcript_of(u), faces)
    assert (speaker.person, speaker.method) == ("person-P0", "mouth_motion")
