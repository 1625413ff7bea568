"""Unit tests of fusion's dialogue (services/fusion/dialogue.py) as a state machine, without the join: asking opens
the question, an answer resolves it into the drafted command, "no" withdraws it, time closes it, a correction
re-does the last command. (The scenario suite's dialogue group runs the same through the whole core.)"""

from __future__ import annotations

import logging

from common.schema import Clarification, FusedCommand, Spoken
from services.fusion.decision import Draft
from services.fusion.dialogue import Dialogue
from services.fusion.ground import Choice
from services.fusion.outputs import Outputs
from services.fusion.window import Context
from testkit.fusion import utterance, window
from testkit.scenarios import BASE_STAMP, scene_of
from testkit.scenarios.suite import TWO_CUPS


def asked_which_cup(counts: list[str]) -> tuple[Dialogue, Context, Clarification]:
    dialogue = Dialogue(Outputs("fusion/test"), timeout=10.0, count=counts.append, log=logging.getLogger("test"))
    ctx = window(scene_of(TWO_CUPS))
    t, u = utterance(0.0, "pick up the cup")
    choice = ctx.choose(u.obj, ctx.objects, None, ctx.ref)
    assert choice.kind == "ambiguous"
    out = dialogue.clarify(t, u, ctx, choice, Draft("pick_up", t.text))
    assert dialogue.question is not None and dialogue.question.clarification_id == out.sample.id
    assert isinstance(out.sample, Clarification)
    return dialogue, ctx, out.sample


def test_an_answer_resolves_the_question_into_the_drafted_command():
    counts: list[str] = []
    dialogue, ctx, asked = asked_which_cup(counts)
    assert asked.reason == "ambiguous" and {c.id for c in asked.candidates} == {"cup_red", "cup_blue"}
    (out,) = dialogue.reply(*utterance(2.0, "the blue one"), ctx)
    assert isinstance(out.sample, FusedCommand) and out.sample.intent == "pick_up"
    assert out.sample.target.id == "cup_blue" and asked.id in out.sample.explanation
    assert dialogue.question is None and dialogue.last.target.id == "cup_blue"  # "no, the other one" may follow
    assert counts == ["clarification_ambiguous"]


def test_no_withdraws_the_question_and_time_closes_it():
    counts: list[str] = []
    dialogue, ctx, _ = asked_which_cup(counts)
    assert dialogue.reply(*utterance(2.0, "no"), ctx) == [] and dialogue.question is None
    dialogue, ctx, _ = asked_which_cup(counts)
    dialogue.expire(5.0 + BASE_STAMP)
    assert dialogue.question is not None
    dialogue.expire(12.0 + BASE_STAMP)  # more than 10 s after the question's utterance ended
    assert dialogue.question is None and dialogue.reply(*utterance(12.0, "the blue one"), ctx) is None
    assert counts == ["clarification_ambiguous", "dialogue_cancelled", "clarification_ambiguous", "dialogue_expired"]


def test_an_answer_that_does_not_decide_asks_again_and_a_correction_redoes_the_last_command():
    counts: list[str] = []
    dialogue, ctx, asked = asked_which_cup(counts)
    (again,) = dialogue.reply(*utterance(2.0, "yes"), ctx)  # a yes to a which-question says nothing
    assert isinstance(again.sample, Clarification) and again.sample.id != asked.id
    assert dialogue.question.clarification_id == again.sample.id
    (cmd,) = dialogue.reply(*utterance(3.0, "the red one"), ctx)
    assert cmd.sample.target.id == "cup_red"
    (fixed,) = dialogue.reply(*utterance(4.0, "no, the other one"), ctx)
    assert fixed.sample.intent == "pick_up" and fixed.sample.target.id == "cup_blue"
    assert counts == ["clarification_ambiguous", "dialogue_unresolved", "corrected_by_speech"]


def test_a_place_question_has_no_candidates():
    dialogue = Dialogue(Outputs("fusion/test"), timeout=10.0, count=lambda n: None, log=logging.getLogger("test"))
    t, u = utterance(0.0, "go there")
    out = dialogue.clarify_place(t, u, Draft("go_to", t.text))
    assert out.sample.reason == "not_found" and out.sample.candidates == [] and "point" in out.sample.question
    assert dialogue.question.reason == "not_found" and dialogue.question.candidates == []


def test_a_doubted_yes_does_not_confirm_a_command_it_asks_again():
    """A one-word utterance the speech service only guessed to be "sure" (docs/speech.md: 'chair' was) must not
    set the robot moving: below the doubt level the confirmation question is asked again, saying why."""
    counts: list[str] = []
    dialogue = Dialogue(Outputs("fusion/test"), 10.0, counts.append, logging.getLogger("test"), doubt=0.3)
    ctx = window(scene_of(TWO_CUPS))
    t, u = utterance(0.0, "pick up the red cup")
    found = ctx.choose(u.obj, ctx.objects, None, ctx.ref)
    assert found.kind == "target" and found.winner is not None
    unsure = Choice("low_confidence", found.winner, (found.winner,))
    asked = dialogue.clarify(t, u, ctx, unsure, Draft("pick_up", t.text, target=found.winner.obj), heard=True)
    (again,) = dialogue.reply(*utterance(2.0, "sure"), window(scene_of(TWO_CUPS), speech=0.05))
    assert isinstance(again.sample, Clarification) and "not sure I heard 'sure'" in again.sample.question
    assert asked.sample.question in again.sample.question and dialogue.question is not None
    (done,) = dialogue.reply(*utterance(3.0, "yes"), window(scene_of(TWO_CUPS), speech=0.6))
    assert isinstance(done.sample, FusedCommand) and done.sample.target.id == "cup_red"
    assert counts == ["clarification_low_confidence", "dialogue_doubted_confirm", "dialogue_unresolved"]


# ---------------------------------------------------------------------------
# A question said aloud (the voice's Spoken, docs/voice.md): answered by what is said after the robot finished it
# ---------------------------------------------------------------------------
def said_aloud(asked: Clarification, start: float, end: float, answers: str | None = None) -> Spoken:
    """The voice's Spoken for `asked`, said from `start` to `end` s after the base stamp."""
    return Spoken(
        stamp=BASE_STAMP + start,
        source="voice/robot",
        id="spk-1",
        text=asked.question,
        kind="question",
        answers=asked.id if answers is None else answers,
        start=BASE_STAMP + start,
        end=BASE_STAMP + end,
        speaker="robot",
        voice="piper:joe",
    )


def test_an_answer_begun_while_the_robot_still_asks_is_not_taken_one_after_it_is():
    counts: list[str] = []
    dialogue, ctx, asked = asked_which_cup(counts)  # the words end at 1.0 s
    assert dialogue.spoken(said_aloud(asked, 3.0, 6.0))  # a slow synthesis: said from 3 to 6 s
    assert dialogue.reply(*utterance(5.5, "the blue one"), ctx) == []  # begun before the question ended
    assert dialogue.question is not None and dialogue.question.clarification_id == asked.id  # still open
    (out,) = dialogue.reply(*utterance(6.2, "the blue one"), ctx)
    assert isinstance(out.sample, FusedCommand) and out.sample.target.id == "cup_blue"
    assert counts == ["clarification_ambiguous", "answer_before_spoken"]


def test_the_question_stays_open_for_the_timeout_from_the_end_of_its_spoken_words():
    counts: list[str] = []
    dialogue, ctx, asked = asked_which_cup(counts)
    dialogue.spoken(said_aloud(asked, 3.0, 6.0))
    dialogue.expire(BASE_STAMP + 12.0)  # 11 s after the words that raised it (closed without a voice), 6 s after said
    assert dialogue.question is not None
    (out,) = dialogue.reply(*utterance(15.5, "the red one"), ctx)
    assert out.sample.target.id == "cup_red"
    dialogue, ctx, asked = asked_which_cup(counts)
    dialogue.spoken(said_aloud(asked, 3.0, 6.0))
    dialogue.expire(BASE_STAMP + 16.5)  # more than 10 s after the robot finished asking
    assert dialogue.question is None and counts[-1] == "dialogue_expired"


def test_a_question_cut_short_opens_its_window_at_the_cut():
    dialogue, ctx, asked = asked_which_cup([])
    dialogue.spoken(said_aloud(asked, 3.0, 6.0))
    dialogue.spoken(said_aloud(asked, 3.0, 4.0))  # the voice stopped at 4 s and said so (the same Spoken, new end)
    (out,) = dialogue.reply(*utterance(4.5, "the blue one"), ctx)
    assert out.sample.target.id == "cup_blue"


def test_without_its_own_spoken_the_question_is_open_from_when_it_was_asked():
    """Another utterance's Spoken, or free text (no `answers`), says nothing of this question: as without a voice."""
    counts: list[str] = []
    dialogue, ctx, asked = asked_which_cup(counts)
    assert not dialogue.spoken(said_aloud(asked, 3.0, 6.0, answers="clr-another"))
    free = said_aloud(asked, 3.0, 6.0)
    free.answers = None
    assert not dialogue.spoken(free)
    assert dialogue.question.opens is None
    (out,) = dialogue.reply(*utterance(2.0, "the blue one"), ctx)  # taken, as before
    assert out.sample.target.id == "cup_blue"
    dialogue, ctx, asked = asked_which_cup(counts)
    dialogue.expire(BASE_STAMP + 12.0)  # 11 s after the words that raised it
    assert dialogue.question is None


def test_fusion_takes_the_spoken_question_from_the_wire_sample():
    """Through the core (as the service's worker feeds it): the voice's Spoken for fusion's own Clarification."""
    from services.fusion.core import Config, FusionCore
    from testkit.scenarios import KEYS, Step, deliver, say, see
    from testkit.scenarios.suite import TWO_CUPS

    counts: list[str] = []
    core = FusionCore(Config(), "fusion/test", count=counts.append)
    for modality in ("vision", "gesture"):
        core.on_liveliness(modality, "test", True)
    wall = 1000.0

    def feed(*steps: Step) -> list:
        nonlocal wall
        out: list = []
        for one in steps:
            key, sample = one.build(BASE_STAMP)
            out += [o.sample for o in deliver(core, key, sample, wall)]
            wall += 0.002
        wall += 100.0
        return out + [o.sample for o in core.tick(wall)]

    scene = [see(t / 10, TWO_CUPS) for t in range(-10, 100, 5)]
    (asked,) = feed(*scene[:6], say(0.0, 0.9, "pick up the cup"))
    assert isinstance(asked, Clarification)
    assert core.on_spoken(KEYS.key("spoken", speaker="robot"), said_aloud(asked, 2.0, 5.0), wall) == []
    assert counts.count("question_spoken") == 1
    assert feed(*scene[6:12], say(4.0, 4.8, "the blue one")) == []  # said over the robot's question
    assert counts.count("answer_before_spoken") == 1
    (cmd,) = feed(*scene[12:], say(5.3, 6.0, "the blue one"))
    assert isinstance(cmd, FusedCommand) and cmd.target.id == "cup_blue" and asked.id in cmd.explanation
