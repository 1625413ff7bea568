"""Fusion attaches who said it (issue #33), in process: the faces of a real two-person turn-taking clip (cached face
series of ../shared/data/talking/comp_turns_bbaf2n_lbbc2a.mp4, tests/data/talking_faces.json) with commands said in
its two speech intervals over a scene of two cups; a command said facing away is asked about, and a yes acts."""

from __future__ import annotations

import functools

import msgspec

from common.schema import Clarification, Detections, Faces, FusedCommand, Sample, Transcript
from services.fusion.core import Config, FusionCore
from testkit.scenarios import Step, say, scene
from testkit.scenarios.suite import TWO_CUPS
from testkit.talking import T0, load_cache

CLIP = "comp_turns_bbaf2n_lbbc2a.mp4"  # left person (P0) speaks 0.95-2.56 s, right person (P1) 3.44-5.41 s


@functools.cache
def faces() -> list[Faces]:
    return load_cache()[CLIP]


def ids() -> tuple[str, str]:
    """The face ids of the left and the right person."""
    first = faces()[0].faces
    left, right = sorted(first, key=lambda f: f.bbox[0])
    return left.id, right.id


def facing_away(samples: list[Faces], face_id: str) -> list[Faces]:
    return [
        msgspec.structs.replace(
            s,
            faces=[
                msgspec.structs.replace(f, looking_at_camera=False, yaw=60.0) if f.id == face_id else f for f in s.faces
            ],
        )
        for s in samples
    ]


def run(steps: list[Step], face_samples: list[Faces], config: Config | None = None) -> list[Sample]:
    """Faces first (the gesture service publishes them with every frame), then the scene and the words."""
    core = FusionCore(config or Config(), "fusion/test")
    core.on_liveliness("vision", "test", True)
    core.on_liveliness("gesture", "test", True)
    wall, out = 1000.0, list[Sample]()
    for face_sample in face_samples:
        core.on_faces("hri/gesture/cam0/faces", face_sample, wall)
    for step in sorted(steps, key=lambda s: s.t):
        key, sample = step.build(T0)
        if isinstance(sample, Detections):
            out.extend(o.sample for o in core.on_detections(key, sample, wall))
        elif isinstance(sample, Transcript):
            out.extend(o.sample for o in core.on_transcript(key, sample, wall))
        out.extend(o.sample for o in core.tick(wall))
        wall += 0.002
    out.extend(o.sample for o in core.tick(wall + 100.0))
    return out


def commands_in_turns() -> list[Step]:
    return [
        *scene(TWO_CUPS, 0.0, 6.0, 0.2),
        say(0.95, 2.56, "pick up the red cup", lag=0.3),
        say(3.44, 5.41, "pick up the blue cup", lag=0.3),
    ]


def test_each_command_carries_the_person_who_said_it() -> None:
    left, right = ids()
    out = run(commands_in_turns(), faces())
    assert [type(o) for o in out] == [FusedCommand, FusedCommand]
    first, second = out
    assert isinstance(first, FusedCommand) and isinstance(second, FusedCommand)
    assert first.target is not None and first.target.id == "cup_red"
    assert first.speaker is not None and (first.speaker.person, first.speaker.method) == (left, "mouth_motion")
    assert second.speaker is not None and (second.speaker.person, second.speaker.method) == (right, "mouth_motion")
    assert first.speaker.addressed is True and second.speaker.addressed is True


def test_without_a_face_stage_the_speaker_stays_nil() -> None:
    out = run(commands_in_turns(), [])
    assert len(out) == 2 and all(isinstance(o, FusedCommand) and o.speaker is None for o in out)


def test_a_command_said_facing_away_is_asked_about_and_a_yes_acts() -> None:
    left, right = ids()
    steps = [*commands_in_turns(), say(6.4, 6.8, "yes", lag=0.3)]
    out = run(steps, facing_away(faces(), right))
    assert [type(o) for o in out] == [FusedCommand, Clarification, FusedCommand]
    _, question, confirmed = out
    assert isinstance(question, Clarification) and isinstance(confirmed, FusedCommand)
    assert question.speaker is not None and question.speaker.person == right and question.speaker.addressed is False
    assert "facing away" in question.question and "pick up the blue cup" in question.question
    assert confirmed.intent == "pick_up" and confirmed.target is not None and confirmed.target.id == "cup_blue"


def test_confirming_unaddressed_commands_can_be_turned_off() -> None:
    _, right = ids()
    out = run(commands_in_turns(), facing_away(faces(), right), Config(confirm_unaddressed=False))
    assert [type(o) for o in out] == [FusedCommand, FusedCommand]
    assert out[1].speaker is not None and out[1].speaker.addressed is False  # type: ignore[attr-defined]


def test_with_two_people_pointing_the_attributed_speakers_target_is_chosen() -> None:
    """Whose gesture counts (tests/test_fusion_people.py) with the real attribution instead of a given speaker: the
    clip's left face is person-1 (pointing at the red cup), the right face person-2 (at the blue cup); both point
    all along; "pick up that one" said in each person's turn picks that person's cup."""
    from common.schema import Hands, Persons
    from testkit.scenarios import H, W
    from tests.test_fusion_people import BLUE, BOTH_POINT, PEOPLE, RED

    left, right = ids()
    named = [
        msgspec.structs.replace(
            s, faces=[msgspec.structs.replace(f, person="person-1" if f.id == left else "person-2") for f in s.faces]
        )
        for s in faces()
    ]
    core = FusionCore(Config(), "fusion/test")
    for modality in ("vision", "gesture"):
        core.on_liveliness(modality, "test", True)
    for s in named:
        core.on_faces("hri/gesture/cam0/faces", s, 1000.0)
    people_frames = [
        (T0 + 0.1 * i, Hands(stamp=T0 + 0.1 * i, source="g", seq=i, cam="cam0", width=W, height=H, hands=BOTH_POINT))
        for i in range(60)
    ]
    steps = [s.build(T0) for s in scene([RED, BLUE], 0.0, 6.0, 0.2)]
    steps += [("hri/gesture/cam0/hands", h) for _, h in people_frames]
    steps += [
        ("hri/gesture/cam0/persons", Persons(stamp=t, source="g", seq=i, cam="cam0", width=W, height=H, persons=PEOPLE))
        for i, (t, _) in enumerate(people_frames)
    ]
    steps += [say(0.95, 2.56, "Pick up that one.").build(T0), say(3.44, 5.41, "Pick up that one.").build(T0)]
    out: list[Sample] = []
    wall = 1000.0
    for key, sample in sorted(steps, key=lambda ks: ks[1].stamp):
        feed = {
            "Detections": core.on_detections,
            "Hands": core.on_hands,
            "Persons": core.on_persons,
            "Transcript": core.on_transcript,
        }[type(sample).__name__]
        out.extend(o.sample for o in feed(key, sample, wall))  # type: ignore[operator]
        out.extend(o.sample for o in core.tick(wall))
        wall += 0.002
    out.extend(o.sample for o in core.tick(wall + 100.0))
    assert [type(o) for o in out] == [FusedCommand, FusedCommand], out
    first, second = out
    assert isinstance(first, FusedCommand) and isinstance(second, FusedCommand)
    assert first.speaker is not None and first.speaker.person == "person-1"
    assert first.target is not None and first.target.id == "cup_red"
    assert second.speaker is not None and second.speaker.person == "person-2"
    assert second.target is not None and second.target.id == "cup_blue"
