"""People in view (issue #33): person regions, the person tracker and whose hand is whose — the pure rules on
boxes, then MediaPipe (face detection, pose per person region, hands) on real photos and clips with several people
(../shared/data/people_multi and ../shared/data/talking; those tests skip when it is absent)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np
import pytest

from services.gesture.landmarks import FaceDetector, HandLandmarker, PoseLandmarker, RegionPose
from services.gesture.persons import (
    Box,
    PersonObs,
    PersonTrack,
    PersonTracker,
    Seen,
    assign_hands,
    crop_int,
    face_region,
    iou,
    observe_people,
)
from testkit.shared import shared_path


# -- pure rules -----------------------------------------------------------------------------------------------
def test_a_face_region_reaches_down_to_the_body_and_stops_half_way_to_the_neighbour() -> None:
    alone = face_region((100.0, 50.0, 40.0, 50.0), [], 640, 480)
    assert alone is not None
    x, y, w, h = alone
    assert x == pytest.approx(20.0) and w == pytest.approx(200.0)  # 2.5 face widths each side of the centre
    assert y == pytest.approx(20.0) and y + h == pytest.approx(450.0)  # 0.6 face above, 7 faces below
    beside = face_region((100.0, 50.0, 40.0, 50.0), [(200.0, 60.0, 40.0, 50.0)], 640, 480)
    assert beside is not None
    assert beside[0] + beside[2] == pytest.approx(170.0)  # half-way between 140 (this face) and 200 (the other)


def _obs(box: Box, face: Box | None = None, face_id: str | None = None) -> PersonObs:
    return PersonObs(box, face, face_id)


def test_a_person_keeps_the_id_through_a_short_occlusion_and_a_new_person_gets_a_new_one() -> None:
    tracker = PersonTracker(keep_s=1.0)
    a, b = (10.0, 10.0, 50.0, 120.0), (200.0, 10.0, 50.0, 120.0)
    first = [t.id for t in tracker.update(0.0, [_obs(a), _obs(b)])]
    assert first == ["person-1", "person-2"]
    assert [t.id for t in tracker.update(0.1, [_obs((14.0, 10.0, 50.0, 120.0))])] == ["person-1"]  # b hidden
    assert [t.id for t in tracker.update(0.8, [_obs(b), _obs(a)])] == ["person-2", "person-1"]  # back in time
    tracker.update(1.6, [_obs(a)])
    tracker.update(2.5, [_obs(a)])  # b unseen for 1.7 s: gone
    assert [t.id for t in tracker.update(2.6, [_obs(a), _obs(b)])] == ["person-1", "person-3"]


def test_the_same_face_id_wins_over_overlap_a_turn_of_the_head_keeps_the_person() -> None:
    tracker = PersonTracker()
    tracker.update(0.0, [_obs((10.0, 10.0, 50.0, 120.0), (20.0, 10.0, 30.0, 30.0), "face-7")])
    moved = tracker.update(0.1, [_obs((40.0, 10.0, 60.0, 120.0), (50.0, 12.0, 30.0, 30.0), "face-7")])
    assert moved[0].id == "person-1" and moved[0].face_id == "face-7"
    assert iou((10.0, 10.0, 50.0, 120.0), (200.0, 10.0, 50.0, 120.0)) == 0.0


def test_a_hand_no_body_reaches_and_no_box_holds_is_nobodys() -> None:
    track = PersonTrack("person-1", (0.0, 0.0, 100.0, 200.0), None, None, None, 1.0, 0.0, 0.0)
    hand_inside = np.full((21, 2), 50.0)
    hand_outside = np.full((21, 2), 400.0)
    assert assign_hands([("left", hand_inside), ("right", hand_outside)], [track]) == ["person-1", None]


# -- MediaPipe on real material ----------------------------------------------------------------------------
Stages = tuple[FaceDetector, RegionPose, PoseLandmarker, HandLandmarker]


@pytest.fixture(scope="module")
def stages() -> Iterator[Stages]:
    made = FaceDetector(), RegionPose(), PoseLandmarker(video=False), HandLandmarker(video=False)
    yield made
    for stage in made:
        stage.close()


def _people_of(img: np.ndarray, stages: Stages, previous: list[Box] | None = None) -> list[PersonObs]:
    faces, regions, main, _ = stages
    h, w = img.shape[:2]
    seen = Seen(w, h, [(b, None) for b, _ in faces.detect(img)], main.detect(img), previous or [])
    return observe_people(seen, lambda r: regions.detect(img, crop_int(r)))


def _read(path: Path) -> np.ndarray:
    img = cv2.imread(str(path))
    assert img is not None, path
    return img


def _inside(point: np.ndarray, box: list[float], margin: float = 0.0) -> bool:
    x, y, w, h = box
    return bool(x - margin * w <= point[0] <= x + w + margin * w and y - margin * h <= point[1] <= y + h + margin * h)


def _people_multi() -> tuple[Path, list[dict]]:
    folder = shared_path("data/people_multi/people_multi.json").parent
    return folder, json.loads((folder / "people_multi.json").read_text())["images"]


def test_every_person_whose_face_is_found_gets_their_own_body(stages: Stages) -> None:
    """people_multi: each face MediaPipe finds becomes a person with a skeleton whose nose is in that person's
    labelled head box (not the neighbour's), and no two persons share a skeleton."""
    folder, images = _people_multi()
    with_faces = 0
    for image in images:
        img = _read(folder / image["file"])
        people = _people_of(img, stages)
        heads = [p["head_box"] for p in image["people"] if p["id"] != "DOG" and p["head_box"]]
        faced = [o for o in people if o.face_box is not None]
        assert len(faced) == len(image["mediapipe_face_detection"]["boxes"]), image["file"]
        for o in faced:
            assert o.body is not None, image["file"]
            holding = [k for k, head in enumerate(heads) if _inside(o.body[0, :2], head, margin=0.2)]
            assert len(holding) == 1, (image["file"], o.body[0, :2].tolist())
        noses = [tuple(np.round(o.body[0, :2])) for o in people if o.body is not None]
        assert len(noses) == len(set(noses))
        with_faces += len(faced)
    assert with_faces >= 9  # 2 + 2 + 3 + 2 faces found in the four photos where faces are seen


def test_each_hand_goes_to_the_person_whose_arm_holds_it(stages: Stages) -> None:
    """coco_..._241: the standing man's left hand (at his hip, in front of the sofa) and the seated man's right
    hand (on his knee), checked by eye: each goes to the person whose head box is that man's."""
    folder, images = _people_multi()
    image = next(i for i in images if i["file"] == "coco_val2014_000000000241.jpg")
    img = _read(folder / image["file"])
    tracks = PersonTracker().update(0.0, _people_of(img, stages))
    hands = stages[3].detect(img)
    owners = assign_hands([(o.hand, o.landmarks) for o in hands], tracks)
    head = {p["id"]: p["head_box"] for p in image["people"]}
    face_of = {t.id: t.face_box for t in tracks}
    standing = next(t.id for t in tracks if t.face_box and _inside(_centre(t.face_box), head["P0"]))
    seated = next(t.id for t in tracks if t.face_box and _inside(_centre(t.face_box), head["P1"]))
    found = {(o.hand, owner) for o, owner in zip(hands, owners) if owner is not None}
    assert ("left", standing) in found and ("right", seated) in found, (found, face_of)
    for o, owner in zip(hands, owners):
        wrist = o.landmarks[0]
        if owner == standing:
            assert wrist[1] > 250  # his hands are at his hips, below the seated man's head
        if owner == seated:
            assert wrist[0] < 180


def _centre(box: Box) -> np.ndarray:
    return np.array([box[0] + box[2] / 2, box[1] + box[3] / 2])


@pytest.mark.parametrize("clip", ["comp_turns_bbaf2n_lbbc2a.mp4", "comp_dub_brbk7n_lbax4n_audioL.mp4"])
def test_two_people_side_by_side_keep_their_ids_and_bodies_over_a_clip(stages: Stages, clip: str) -> None:
    """talking comp_* clips (two real people side by side, every frame): two persons in every frame, each with a
    body, the left one always the same id and the right one always the other."""
    path = shared_path(f"data/talking/{clip}")
    cap = cv2.VideoCapture(str(path))
    tracker = PersonTracker()
    ids: dict[str, set[str]] = {"left": set(), "right": set()}
    frames = 0
    while True:
        ok, img = cap.read()
        if not ok:
            break
        previous = [b for _, b in tracker.bodies()]
        tracks = tracker.update(frames / 25.0, _people_of(img, stages, previous))
        assert len(tracks) == 2 and all(t.body is not None for t in tracks), frames
        middle = img.shape[1] / 2
        for t in tracks:
            ids["left" if t.box[0] + t.box[2] / 2 < middle else "right"].add(t.id)
        frames += 1
    cap.release()
    assert frames >= 70
    assert len(ids["left"]) == 1 and len(ids["right"]) == 1 and ids["left"] != ids["right"], ids


def test_faces_from_a_face_tracker_name_the_persons_face(stages: Stages) -> None:
    """The face stage's faces (box + id) plug into the person stage: each person carries its face id and each face
    id maps to its person (`Face.person`), on a real two-person clip."""
    from services.gesture.people_stage import PeopleStage

    cap = cv2.VideoCapture(str(shared_path("data/talking/comp_turns_bbaf2n_lbbc2a.mp4")))
    stage = PeopleStage(every=1)
    try:
        for i in range(10):
            ok, img = cap.read()
            assert ok
            boxes = [b for b, _ in stages[0].detect(img)]
            named: list[tuple[Box, str | None]] = [
                (b, "face-left" if b[0] < img.shape[1] / 2 else "face-right") for b in boxes
            ]
            seen = stage.update(i / 25.0, img, None, [], faces=named)
            wire = stage.wire(seen)
            assert sorted(p.face for p in wire if p.face) == ["face-left", "face-right"]
            owners = stage.face_owners()
            assert {owners[p.face]: p.id for p in wire if p.face} == {p.id: p.id for p in wire}
            assert all(p.has_body for p in wire)
    finally:
        cap.release()
        stage.close()


def test_a_slow_machine_keeps_the_ids_of_people_seen_in_every_frame_it_processes() -> None:
    """Frames processed 2.5 s apart (a loaded machine): a person seen in each keeps the id; one missed at a frame is
    gone after `keep_s`."""
    tracker = PersonTracker(keep_s=1.0)
    a, b = (10.0, 10.0, 50.0, 120.0), (200.0, 10.0, 50.0, 120.0)
    assert [t.id for t in tracker.update(0.0, [_obs(a), _obs(b)])] == ["person-1", "person-2"]
    assert [t.id for t in tracker.update(2.5, [_obs(a), _obs(b)])] == ["person-1", "person-2"]
    assert [t.id for t in tracker.update(5.0, [_obs(a)])] == ["person-1"]
    assert [t.id for t in tracker.update(7.5, [_obs(a), _obs(b)])] == ["person-1", "person-3"]


def test_the_skeletons_given_to_the_tracker_are_the_other_persons_only() -> None:
    """`other_skeletons`: the persons other than the full-frame skeleton's, with a body; everyone's when the pose saw
    nobody in the full frame; none without the stage."""
    from services.gesture.people_stage import PeopleOfFrame, other_skeletons
    from services.gesture.persons import PersonTrack

    main, other = np.zeros((33, 3)), np.ones((33, 3))
    persons = [
        PersonTrack("person-1", (0.0, 0.0, 10.0, 10.0), None, None, main, 1.0, 0.0, 0.0),
        PersonTrack("person-2", (20.0, 0.0, 10.0, 10.0), None, None, other, 1.0, 0.0, 0.0),
        PersonTrack("person-3", (40.0, 0.0, 10.0, 10.0), (40.0, 0.0, 5.0, 5.0), None, None, 1.0, 0.0, 0.0),
    ]
    seen = PeopleOfFrame(True, persons, [], [], "person-1")
    assert [b is other for b in other_skeletons(seen)] == [True]
    seen.main_person = None
    assert len(other_skeletons(seen)) == 2
    assert other_skeletons(None) == []
