"""The open language: utterances as Whisper prints them (capitals, punctuation, digits or number words),
each with the meaning it must have. Pure: parser only (grounding cases are in test_fusion_grounding_real.py
and the scenario suite)."""

from __future__ import annotations

from typing import get_args

import pytest

from common import language as L
from common.schema import MotionDirection
from services.fusion.parse import parse

# (utterance, meaning). Meaning keys: intent, answer, color, label, noun, spatial, deictic, place, other,
# motion = (kind, direction, distance m | None, angle deg | None). Keys not given are not checked, except
# that an object-less meaning must not invent an object (label None) when "label" is given as None.
CASES: list[tuple[str, dict]] = [
    # -- intents and objects the camera can name (COCO-80), synonyms, plurals, multi-word labels --
    ("Pick up the cup.", dict(intent="pick_up", label="cup")),
    ("Bring me the banana.", dict(intent="bring", label="banana")),
    ("Pick up the laptop.", dict(intent="pick_up", label="laptop")),
    ("Hand me the cell phone, please.", dict(intent="bring", label="cell phone")),
    ("Give me the teddy bear.", dict(intent="bring", label="teddy bear")),
    ("Grab the wine glass.", dict(intent="pick_up", label="wine glass")),
    ("Fetch the sports ball.", dict(intent="bring", label="sports ball")),
    ("Pick up the ball.", dict(intent="pick_up", label="sports ball")),
    ("Bring me my phone.", dict(intent="bring", label="cell phone")),
    ("Can you get me the mug?", dict(intent="pick_up", label="cup")),
    ("Get the remote control.", dict(intent="pick_up", label="remote")),
    ("Look at the TV.", dict(intent="look_at", label="tv")),
    ("Look at the television.", dict(intent="look_at", label="tv")),
    ("Bring me the scissors.", dict(intent="bring", label="scissors")),
    ("Pick up the toothbrush.", dict(intent="pick_up", label="toothbrush")),
    ("Grab the bottles.", dict(intent="pick_up", label="bottle")),
    ("Pick up the cups.", dict(intent="pick_up", label="cup")),
    ("Bring me the wine glasses.", dict(intent="bring", label="wine glass")),
    ("Pick up the knives.", dict(intent="pick_up", label="knife")),
    ("Look at the people.", dict(intent="look_at", label="person")),
    ("Follow that man.", dict(intent="follow", label="person", deictic=True)),
    ("Look at the person on the left.", dict(intent="look_at", label="person", spatial=("left",))),
    ("Bring me the book.", dict(intent="bring", label="book")),
    ("Pick up the apple.", dict(intent="pick_up", label="apple")),
    ("Give me the orange.", dict(intent="bring", label="orange")),
    ("Pick up the orange cup.", dict(intent="pick_up", label="cup", color="orange")),
    ("Pick up the orange one.", dict(intent="pick_up", label="object", color="orange")),
    ("Get me a hot dog.", dict(intent="pick_up", label="hot dog")),
    ("Bring me the potted plant.", dict(intent="bring", label="potted plant")),
    ("Pick up the plant.", dict(intent="pick_up", label="potted plant")),
    ("Grab the computer mouse.", dict(intent="pick_up", label="mouse")),
    # -- categories --
    ("Bring me the fruit.", dict(intent="bring", label="fruit")),
    ("Hand me a drink.", dict(intent="bring", label="drink")),
    ("Give me the glass.", dict(intent="bring", label="glass")),
    ("Pick up the toy.", dict(intent="pick_up", label="toy")),
    ("Bring me something to eat, some food.", dict(intent="bring", label="food")),
    ("Pick up that thing.", dict(intent="pick_up", deictic=True)),
    ("Grab the object on the right.", dict(intent="pick_up", label="object", spatial=("right",))),
    # -- colours, positions --
    ("Pick up the red cup.", dict(intent="pick_up", label="cup", color="red")),
    ("Grab the crimson mug.", dict(intent="pick_up", label="cup", color="crimson")),
    ("Take the blue one on the left.", dict(intent="pick_up", color="blue", spatial=("left",))),
    ("Bring me the biggest box.", dict(intent="bring", label="box", spatial=("biggest",))),
    ("Pick up the bottle in the middle.", dict(intent="pick_up", label="bottle", spatial=("middle",))),
    # -- unknown nouns are kept --
    ("Hand me the blue pitcher, please.", dict(intent="bring", noun="pitcher", color="blue", label=None)),
    ("Pick up the stapler.", dict(intent="pick_up", noun="stapler", label=None)),
    ("Bring me the keys.", dict(intent="bring", noun="key", label=None)),
    ("Pick up the coffee pot.", dict(intent="pick_up", noun="coffee pot", label=None)),
    ("Give me the red thermos.", dict(intent="bring", noun="thermos", color="red", label=None)),
    # -- motions --
    ("Go forward ten meters.", dict(intent="move", motion=("move", "forward", 10.0, None))),
    ("Go forward 10 meters.", dict(intent="move", motion=("move", "forward", 10.0, None))),
    ("Move back a bit.", dict(intent="move", motion=("move", "back", 0.25, None))),
    ("Turn left.", dict(intent="turn", motion=("turn", "left", None, 90.0))),
    ("Turn right.", dict(intent="turn", motion=("turn", "right", None, 90.0))),
    ("Turn around.", dict(intent="turn", motion=("turn", "around", None, 180.0))),
    ("Go left two steps.", dict(intent="move", motion=("move", "left", 2 * L.STEP_M, None))),
    ("Turn left 45 degrees.", dict(intent="turn", motion=("turn", "left", None, 45.0))),
    ("Turn right 90°.", dict(intent="turn", motion=("turn", "right", None, 90.0))),
    ("Rotate 180 degrees.", dict(intent="turn", motion=("turn", "around", None, 180.0))),
    ("Move forward 50 centimeters.", dict(intent="move", motion=("move", "forward", 0.5, None))),
    ("Drive forward 2.5 m.", dict(intent="move", motion=("move", "forward", 2.5, None))),
    ("Go back one and a half meters.", dict(intent="move", motion=("move", "back", 1.5, None))),
    ("Move back half a meter.", dict(intent="move", motion=("move", "back", 0.5, None))),
    ("Back up.", dict(intent="move", motion=("move", "back", None, None))),
    ("Step back.", dict(intent="move", motion=("move", "back", None, None))),
    ("Go straight ahead for three meters.", dict(intent="move", motion=("move", "forward", 3.0, None))),
    ("Move twenty-five centimeters to the right.", dict(intent="move", motion=("move", "right", 0.25, None))),
    ("Go forward a couple of steps.", dict(intent="move", motion=("move", "forward", 2 * L.STEP_M, None))),
    ("Turn left a little.", dict(intent="turn", motion=("turn", "left", None, 15.0))),
    ("Go forward, no, back two meters.", dict(intent="move", motion=("move", "back", 2.0, None))),
    # motion verbs with an object or a place stay go_to
    ("Go to the kitchen.", dict(intent="go_to", place="kitchen", motion=None)),
    ("Go to the red cup.", dict(intent="go_to", label="cup", color="red", motion=None)),
    ("Go there.", dict(intent="go_to", motion=None)),
    # -- dialogue words --
    ("No, the other one.", dict(intent=None, answer="deny", other=True)),
    ("The other one.", dict(intent=None, other=True)),
    ("Not that one.", dict(intent=None, other=True)),
    ("Yes.", dict(intent=None, answer="confirm")),
    ("Yeah, that's right.", dict(intent=None, answer="confirm")),
    ("No.", dict(intent=None, answer="deny", other=False)),
    ("No, the blue one.", dict(intent=None, answer="deny", color="blue")),
    ("Pick up the red, no, the blue cup.", dict(intent="pick_up", label="cup", color="blue")),
    ("Bring me the apple, sorry, the banana.", dict(intent="bring", label="banana")),
    ("Pick up the red cup, no, the blue one.", dict(intent="pick_up", label="cup", color="blue")),
    ("Grab the cup, I mean the bottle.", dict(intent="pick_up", label="bottle")),
    # -- disfluencies and politeness never change the meaning --
    ("Uh, pick up the red cup.", dict(intent="pick_up", label="cup", color="red")),
    ("Um, could you please bring me the banana for me?", dict(intent="bring", label="banana")),
    ("Could you, uh, hand me the bottle, please?", dict(intent="bring", label="bottle")),
    ("Would you mind picking up the cup? Thanks.", dict(intent="pick_up", label="cup")),
    ("Hey robot, pick up the cup.", dict(intent="pick_up", label="cup")),
    ("Okay, so, uh, just turn left, thank you.", dict(intent="turn", motion=("turn", "left", None, 90.0))),
    ("I'd like the banana, please.", dict(intent="bring", label="banana")),
    ("Can I have a bottle?", dict(intent="bring", label="bottle")),
    ("I want you to pick up the cup.", dict(intent="pick_up", label="cup")),
    ("No, not that one, the blue one.", dict(intent=None, other=True, color="blue")),
    ("Bring me the bottle. No, wait, the cup.", dict(intent="bring", label="cup")),
    ("Please move forward by 1 meter.", dict(intent="move", motion=("move", "forward", 1.0, None))),
    ("Could you turn to the left?", dict(intent="turn", motion=("turn", "left", None, 90.0))),
    ("Please stop.", dict(intent="stop")),
    ("Stop!", dict(intent="stop")),
    ("Hello.", dict(intent="greet")),
    ("Follow me, please.", dict(intent="follow")),
    ("Come here.", dict(intent="come_here")),
    ("Put it on the table.", dict(intent="put_down", place="table", deictic=True)),
    ("What a nice day.", dict(intent=None, answer=None)),
]


def test_there_are_at_least_80_utterances():
    assert len(CASES) >= 80


@pytest.mark.parametrize("text,meaning", CASES, ids=[c[0] for c in CASES])
def test_utterance_means(text, meaning):
    u = parse(text)
    got = {
        "intent": u.intent,
        "answer": u.answer,
        "color": u.obj.color,
        "label": u.obj.label,
        "noun": u.obj.noun,
        "spatial": u.obj.spatial,
        "deictic": u.obj.deictic,
        "place": u.place,
        "other": u.other,
        "motion": (u.intent, u.motion.direction, u.motion.distance, u.motion.angle) if u.motion else None,
    }
    for key, want in meaning.items():
        if key == "motion" and want is not None:
            kind, direction, distance, angle = got["motion"] or (None,) * 4
            assert (kind, direction) == want[:2], (text, got)
            for value, expected in ((distance, want[2]), (angle, want[3])):
                assert (value is None) == (expected is None) and (value is None or abs(value - expected) < 1e-6), (
                    text,
                    got,
                )
        else:
            assert got[key] == want, f"{text!r}: {key} = {got[key]!r}, expected {want!r} ({got})"


@pytest.mark.parametrize(
    "plain,noisy",
    [
        ("pick up the red cup", "Uh, um, could you please pick up the, uh, red cup for me? Thanks."),
        ("bring me the banana", "Well, would you mind bringing... I mean, bring me the banana, please."),
        ("turn left", "Okay, so, like, turn left, please."),
        ("go forward two meters", "Um, go forward, uh, 2 meters, please."),
    ],
)
def test_disfluencies_and_politeness_never_change_the_meaning(plain, noisy):
    def meaning(u):
        return u.intent, u.obj, u.motion

    assert meaning(parse(plain)) == meaning(parse(noisy))


def test_every_label_of_the_detector_and_its_plural_is_a_noun():
    for label in L.COCO_LABELS:
        for said in (label, L.plural(label)):
            u = parse(f"Look at the {said}.")
            assert u.obj.label == label and u.obj.noun is None, (said, u.obj)


def test_a_users_own_label_in_view_is_a_noun():
    assert parse("Pick up the widget.").obj.noun == "widget"
    u = parse("Pick up the widgets.", labels=("widget", "cup"))
    assert u.obj.label == "widget" and u.obj.noun is None


def test_specific_words_beat_their_category():
    assert L.label_matches("banana", "banana") and not L.label_matches("banana", "apple")
    assert L.label_matches("fruit", "banana") and L.label_matches("fruit", "apple")
    assert L.label_matches("object", "laptop") and L.label_matches(None, "laptop")


def test_the_speech_vocabulary_and_the_parser_read_the_same_tables():
    words = L.vocabulary()
    for needed in ("banana", "laptop", "teddy", "forward", "meters", "degrees", "turn", "other", "fruit"):
        assert needed in words, needed
    for word in ("backward", "centimeters", "giraffe"):  # a word added to a table is understood at once
        assert parse(f"go {word}").tokens  # tokenised
    assert parse("turn left").motion is not None and parse("Look at the giraffe.").obj.label == "giraffe"


def test_the_direction_words_are_the_wires_motion_directions():
    # the parser hands a direction tag's value to the wire's Motion as it is
    assert set(L.DIRECTION_PHRASES) == set(get_args(MotionDirection))


def test_motion_on_the_wire_is_optional_and_checked():
    import msgpack

    from common.codec import decode, encode
    from common.schema import FusedCommand, InvalidSample, Motion, Weights

    cmd = FusedCommand(
        stamp=1.0,
        source="fusion/a",
        id="c",
        intent="move",
        text="Go forward ten meters.",
        confidence=0.9,
        weights=Weights(speech=1.0, vision=0.0, gesture=0.0),
        inputs={},
        explanation="",
        prompt="",
        motion=Motion(direction="forward", distance=10.0),
    )
    assert decode(encode(cmd), FusedCommand).motion == Motion(direction="forward", distance=10.0)
    data = cmd.to_dict()
    old_style = {k: v for k, v in data.items() if k != "motion"}  # a v1 producer from before the extension
    assert decode(msgpack.packb(old_style), FusedCommand).motion is None
    with pytest.raises(InvalidSample) as err:
        decode(msgpack.packb({**data, "motion": {"direction": "forward", "distance": -1.0}}), FusedCommand)
    assert err.value.reason == "out_of_range"
    with pytest.raises(InvalidSample) as err:
        decode(msgpack.packb({**data, "motion": {"direction": "up"}}), FusedCommand)
    assert err.value.reason == "bad_value"


def test_every_word_the_recogniser_is_primed_with_is_understood():
    words = L.prompt_words()
    assert 50 <= len(words) <= 120 and "banana" in words and "forward" in words
    for phrase in words:
        assert not parse(phrase).unknown, phrase


def test_whisper_words_with_spaces_and_punctuation_count_for_speech_reliability():
    from common.schema import Transcript, Word
    from services.fusion.evidence import speech_reliability

    words = [
        Word(word=w, start=i * 0.2, end=i * 0.2 + 0.2, confidence=0.2 if w.strip(" .") == "cup" else 0.9)
        for i, w in enumerate([" Pick", " up", " the", " cup."])
    ]
    t = Transcript(
        stamp=1.0,
        source="speech/m",
        mic="m",
        start=0.0,
        end=0.8,
        text="Pick up the cup.",
        confidence=0.9,
        words=words,
        final=True,
        backend="whisper",
    )
    assert speech_reliability(t, parse(t.text)) < 0.6  # the weak " cup." limits it: it was read as "cup"


def test_a_motion_reaches_the_planner_prompt_and_the_command():
    from testkit.scenarios import check, run_in_process
    from testkit.scenarios.suite import SCENARIOS

    scenario = next(s for s in SCENARIOS if s.name == "motion: go left 2 steps")
    (cmd,) = run_in_process(scenario)
    assert not check(scenario, [cmd])
    assert cmd.intent == "move" and cmd.target is None and cmd.location is None
    assert (
        "Motion: move left 1 m (robot frame: forward = the way it faces, left/right = its own left/right, "
        'said as "2 steps")' in cmd.prompt
    ), cmd.prompt
