"""People in fusion (issue #33, services/fusion/people.py): whose pointing counts for an utterance, competing
pointing with the speaker unknown, a stop palm from anyone, and "bring it to me" going to the speaker."""

from __future__ import annotations

from typing import Any, Callable, Sequence

from common.schema import (
    Clarification,
    FusedCommand,
    GestureEvent,
    GestureName,
    Hand,
    Handedness,
    Hands,
    Person,
    Persons,
    Ray,
    Sample,
)
from services.fusion.core import Config, FusionCore
from services.fusion.people import PersonRef, resolve, split_recipient
from testkit.scenarios import BASE_STAMP, H, Obj, W, landmarks_at, ray_towards, say, scene

RED = Obj("cup_red", "cup", "red", (150, 300))
BLUE = Obj("cup_blue", "cup", "blue", (500, 300))
ALICE_HAND = (250.0, 420.0)  # person-1 stands left of the middle, points at the red cup
BOB_HAND = (420.0, 420.0)  # person-2 stands right of it, points at the blue cup
PEOPLE = [
    Person(id="person-1", bbox=[180.0, 60.0, 140.0, 400.0], score=1.0, position=[-0.4, 0.1, 2.0], frame_id="cam0"),
    Person(id="person-2", bbox=[380.0, 60.0, 140.0, 400.0], score=1.0, position=[0.5, 0.1, 2.2], frame_id="cam0"),
]


def _hand(
    person: str, origin: tuple[float, float], at: tuple[float, float] | None, show: GestureName = "point"
) -> Hand:
    ray = None if at is None else Ray(origin=list(origin), direction=list(ray_towards(origin, at)), confidence=0.9)
    side: Handedness = "right" if person == "person-1" else "left"
    return Hand(hand=side, score=0.95, landmarks=landmarks_at(*origin), gesture=show, ray=ray, person=person)


def _frames(make: list[Hand]) -> list[tuple[str, Sample]]:
    out: list[tuple[str, Sample]] = []
    for i in range(41):
        t = -1.5 + 0.1 * i
        out.append(
            (
                "hri/gesture/cam0/hands",
                Hands(
                    stamp=BASE_STAMP + t, source="gesture/cam0", seq=5000 + i, cam="cam0", width=W, height=H, hands=make
                ),
            )
        )
        out.append(
            (
                "hri/gesture/cam0/persons",
                Persons(
                    stamp=BASE_STAMP + t,
                    source="gesture/cam0",
                    seq=5000 + i,
                    cam="cam0",
                    width=W,
                    height=H,
                    persons=PEOPLE,
                ),
            )
        )
    return out


def run(text: str, hands: list[Hand], speaker: str | None, events: Sequence[GestureEvent] = ()) -> list[Sample]:
    """One utterance over a scene of two cups and two people, their hands (and gesture events) as given, the speaker
    as the attribution would say (None = unknown)."""
    core = FusionCore(Config(), "fusion/test")
    core.speaker_of = lambda p: speaker
    for modality in ("vision", "gesture"):
        core.on_liveliness(modality, "test", True)
    steps = [s.build(BASE_STAMP) for s in scene([RED, BLUE])] + _frames(hands) + [say(0.0, 1.5, text).build(BASE_STAMP)]
    steps += [("hri/gesture/cam0/event", ev) for ev in events]
    feed: dict[str, Callable[..., Any]] = {
        "Detections": core.on_detections,
        "Hands": core.on_hands,
        "Persons": core.on_persons,
        "Transcript": core.on_transcript,
        "GestureEvent": core.on_gesture_event,
    }
    out: list[Sample] = []
    wall = 1000.0
    for key, sample in sorted(steps, key=lambda ks: ks[1].stamp):
        out.extend(o.sample for o in feed[type(sample).__name__](key, sample, wall))
        out.extend(o.sample for o in core.tick(wall))
        wall += 0.002
    out.extend(o.sample for o in core.tick(wall + 100.0))
    return out


BOTH_POINT = [_hand("person-1", ALICE_HAND, RED.center), _hand("person-2", BOB_HAND, BLUE.center)]


def test_with_two_people_pointing_the_speakers_target_is_chosen() -> None:
    for speaker, target in (("person-1", "cup_red"), ("person-2", "cup_blue")):
        (out,) = run("Pick up that one.", BOTH_POINT, speaker)
        assert isinstance(out, FusedCommand) and out.target is not None and out.target.id == target, speaker


def test_with_the_speaker_unknown_competing_pointing_is_a_question() -> None:
    (out,) = run("Pick up that one.", BOTH_POINT, None)
    assert isinstance(out, Clarification) and out.reason == "ambiguous"
    assert {c.id for c in out.candidates} == {"cup_red", "cup_blue"}


def test_with_the_speaker_unknown_one_pointing_person_is_followed() -> None:
    (out,) = run("Pick up that one.", [_hand("person-2", BOB_HAND, BLUE.center)], None)
    assert isinstance(out, FusedCommand) and out.target is not None and out.target.id == "cup_blue"


def test_another_persons_pointing_alone_is_no_evidence_for_the_speaker() -> None:
    """Bob points at the blue cup while Alice says "pick up that one": nothing she showed says which: a question."""
    (out,) = run("Pick up that one.", [_hand("person-2", BOB_HAND, BLUE.center)], "person-1")
    assert isinstance(out, Clarification)


def test_a_stop_palm_from_someone_who_is_not_the_speaker_still_stops() -> None:
    """Bob holds a stop to the robot while Alice speaks: the robot stops and her command is cancelled. Bob's palm
    seen without a stop shown (issue #40: a palm that is not held still, a beat) cancels nothing."""
    palm = _hand("person-2", BOB_HAND, None, show="open_palm")
    stop = GestureEvent(
        stamp=BASE_STAMP + 0.6,
        source="gesture/cam0",
        cam="cam0",
        width=W,
        height=H,
        gesture="open_palm",
        phase="hold",
        start=BASE_STAMP + 0.1,
        end=BASE_STAMP + 0.6,
        score=0.95,
        hand="left",
        person="person-2",
        still=0.5,
        raised=True,
    )
    (out,) = run("Pick up the red cup.", [palm], "person-1", [stop])  # the stop; the utterance is cancelled
    assert isinstance(out, FusedCommand) and out.intent == "stop" and out.text is None
    for hands in ([palm], []):
        (out,) = run("Pick up the red cup.", hands, "person-1")
        assert isinstance(out, FusedCommand) and out.target is not None and out.target.id == "cup_red"


def test_bring_it_to_me_goes_to_the_speaker() -> None:
    for speaker, person in (("person-1", PEOPLE[0]), ("person-2", PEOPLE[1])):
        (out,) = run("Bring the red cup to me.", [], speaker)
        assert isinstance(out, FusedCommand) and out.intent == "bring" and out.location is not None
        assert out.location.position == person.position and out.target is not None and out.target.id == "cup_red"
        assert out.location.x == person.bbox[0] + person.bbox[2] / 2
    (unknown,) = run("Bring the red cup to me.", [], None)  # nobody known to be "me": no place made up
    assert isinstance(unknown, FusedCommand) and unknown.location is None


def test_people_named_in_words_resolve_to_person_ids() -> None:
    assert split_recipient("bring it to me")[1] == PersonRef("speaker", said="me")
    assert split_recipient("give me the red cup") == ("give the red cup", PersonRef("speaker", said="me"))
    text, ref = split_recipient("hand the cup to the man on the left")
    assert text == "hand the cup" and ref is not None and ref.who == "side" and ref.side == "left"
    talking = split_recipient("give it to the person who is talking")[1]
    assert talking is not None and talking.who == "speaker"
    assert resolve(PersonRef("speaker"), PEOPLE, "person-2") == PEOPLE[1]
    assert resolve(PersonRef("other"), PEOPLE, "person-2") == PEOPLE[0]  # "her": the one who is not speaking
    assert resolve(PersonRef("other"), PEOPLE, None) is None  # two people, nobody known to speak: cannot tell
    assert resolve(PersonRef("side", "right"), PEOPLE, None) == PEOPLE[1]
    assert split_recipient("pick up the red cup") == ("pick up the red cup", None)


def test_follow_me_and_look_at_him_target_persons_by_their_part_in_the_talk() -> None:
    (out,) = run("Follow me.", [], "person-2")
    assert isinstance(out, FusedCommand) and out.intent == "follow" and out.target is not None
    assert out.target.id == "person-2" and out.target.position == PEOPLE[1].position
    (other,) = run("Look at him.", [], "person-2")
    assert isinstance(other, FusedCommand) and other.target is not None and other.target.id == "person-1"
    for said in run("Follow me.", [], None):  # nobody known to be "me": never a person picked at random
        assert not (isinstance(said, FusedCommand) and said.target is not None and said.target.id.startswith("person-"))


def test_the_man_on_the_left_is_a_person_in_view_when_vision_finds_no_people() -> None:
    """The colour backend detects no people: "look at the man on the left" picks among the persons of `Persons`."""
    (out,) = run("Look at the man on the left.", [], None)
    assert isinstance(out, FusedCommand) and out.target is not None and out.target.id == "person-1"
    (right,) = run("Look at the man on the right.", [], None)
    assert isinstance(right, FusedCommand) and right.target is not None and right.target.id == "person-2"
    assert right.target.position == PEOPLE[1].position
