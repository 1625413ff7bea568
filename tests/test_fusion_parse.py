"""Unit tests of fusion's parser (services/fusion/parse.py): intents, object phrases, deixis, answers, ASR slips."""

from __future__ import annotations

import pytest

from common import language as L
from services.fusion.parse import ObjectPhrase, parse


@pytest.mark.parametrize(
    "text,intent",
    [
        ("pick up the red cup", "pick_up"),
        ("grab it", "pick_up"),
        ("give me that", "bring"),
        ("hand me the bottle", "bring"),
        ("put it there", "put_down"),
        ("place the cup on the table", "put_down"),
        ("go there", "go_to"),
        ("come here", "come_here"),
        ("stop", "stop"),
        ("look at that", "look_at"),
        ("follow me", "follow"),
        ("hello robot", "greet"),
        ("please stop now", "stop"),
        ("could you bring me the yellow ball please", "bring"),
        ("pickup the ball", "pick_up"),
    ],
)
def test_parser_finds_the_intent(text, intent):
    assert parse(text).intent == intent


def test_parser_every_intent_phrase_of_the_language_is_understood():
    for intent, phrases in L.INTENT_PHRASES.items():
        for phrase in phrases:
            assert parse(phrase).intent == intent, phrase


@pytest.mark.parametrize(
    "text,color,label,spatial",
    [
        ("pick up the crimson mug", "crimson", "cup", ()),  # its own term, matched to red by similarity
        ("bring me the navy bottle", "navy", "bottle", ()),
        ("bring me the light blue bowl", "light blue", "bowl", ()),
        ("the dark grey sofa", "dark grey", "couch", ()),
        ("the pale pink bottle", "light pink", "bottle", ()),
        ("take the blue one on the left", "blue", "object", ("left",)),
        ("the leftmost ball", None, "sports ball", ("left",)),
        ("grab the biggest box", None, "box", ("biggest",)),
        ("pick up the candy in the middle", None, "candy", ("middle",)),
        ("pick the nearest cup", None, "cup", ("nearest",)),
    ],
)
def test_parser_reads_the_object_phrase(text, color, label, spatial):
    obj = parse(text).obj
    assert (obj.color, obj.label, obj.spatial) == (color, label, spatial)


def test_parser_deixis_places_and_answers():
    u = parse("put it on the red box")
    assert u.obj.deictic and u.dest_obj == ObjectPhrase(color="red", label="box")
    assert parse("put the cup on the table").place == "table"
    assert parse("go there").deictic_place == "there"
    assert parse("pick up that cup").obj == ObjectPhrase(label="cup", deictic=True)
    assert parse("that one").obj.deictic and not parse("that one").obj.specific
    assert parse("yes").answer == "confirm" and parse("that is right").answer == "confirm"
    assert parse("no, the blue one").answer == "deny" and parse("no, the blue one").obj.color == "blue"
    assert parse("what a nice day").intent is None and not parse("what a nice day").has_content


def test_parser_corrects_asr_slips_but_not_into_a_stop():
    u = parse("grabb the bluue bottel")
    assert (u.intent, u.obj.color, u.obj.label) == ("pick_up", "blue", "bottle")
    assert len(u.corrections) == 3
    assert parse("I want the red cup").intent == "bring"  # a request, and "want" is not "wait" (= stop)
    assert parse("I want you to pick up the cup").intent == "pick_up"
