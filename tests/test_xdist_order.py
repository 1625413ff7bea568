"""The order `make test` hands modules to its xdist workers (testkit/xdist_order.py)."""

from __future__ import annotations

from testkit.harness import ROOT
from testkit.xdist_order import MODULE_SECONDS, WHISPER_UNIT, WHISPER_UNIT_NAME, longest_first, unit_of


def test_the_long_modules_go_first_longest_first_and_the_rest_keep_their_order():
    ids = [
        "tests/test_a.py::t1",
        "tests/test_intent_clips.py::t1",
        "tests/test_speech_whisper.py::t1",
        "tests/test_a.py::t2",
        "tests/test_b.py::t1",
        "tests/test_speech_commands.py::t1",
        "tests/test_intent_clips.py::t2",
        "tests/test_speech_whisper.py::t2",
    ]
    got = [ids[i] for i in longest_first(ids)]
    assert got == [
        # the Whisper unit: its modules in the order collected, each module's tests in order
        "tests/test_speech_whisper.py::t1",
        "tests/test_speech_whisper.py::t2",
        "tests/test_speech_commands.py::t1",
        "tests/test_intent_clips.py::t1",
        "tests/test_intent_clips.py::t2",
        "tests/test_a.py::t1",
        "tests/test_a.py::t2",
        "tests/test_b.py::t1",
    ]


def test_the_whisper_modules_are_one_unit_and_others_their_own():
    assert {unit_of(m) for m in WHISPER_UNIT} == {WHISPER_UNIT_NAME}
    assert unit_of("tests/test_intent_clips.py") == "tests/test_intent_clips.py"


def test_every_module_named_exists():
    """A renamed module would silently lose its place (the run only gets slower): name it here again."""
    named = set(WHISPER_UNIT) | {m for m in MODULE_SECONDS if m != WHISPER_UNIT_NAME}
    missing = sorted(m for m in named if not (ROOT / m).is_file())
    assert not missing, f"testkit/xdist_order.py names modules that do not exist: {missing}"
