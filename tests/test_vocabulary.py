"""The shared words (common/counters.py, common/schema.py): counter tables cover every word they name, and the
language tags only the contract's intents."""

from typing import get_args

from common.counters import (
    CLARIFICATION_COUNTER,
    GESTURE_COMMAND_COUNTER,
    FusionCounter,
    GestureIntent,
    SpeechCounter,
)
from common.schema import ClarificationReason
from services.speech.__main__ import EXPLAINED_COUNTERS


def test_every_clarification_reason_and_gesture_command_has_its_counter() -> None:
    assert set(CLARIFICATION_COUNTER) == set(get_args(ClarificationReason))
    assert set(GESTURE_COMMAND_COUNTER) == set(get_args(GestureIntent))
    assert set(CLARIFICATION_COUNTER.values()) | set(GESTURE_COMMAND_COUNTER.values()) <= set(get_args(FusionCounter))


def test_counter_names_are_unique_within_their_service() -> None:
    for names in (get_args(FusionCounter), get_args(SpeechCounter)):
        assert len(names) == len(set(names))
    assert set(EXPLAINED_COUNTERS) <= set(get_args(SpeechCounter))


def test_every_intent_the_language_can_tag_is_an_intent_of_the_contract() -> None:
    """parse() turns an intent tag into an Intent (common.schema.as_intent raises otherwise): the language's intent
    phrases name only the contract's intents."""
    from common.schema import INTENTS, as_intent
    from services.fusion.parse import PHRASES

    tagged = {value for kind, value in PHRASES.values() if kind == "intent"}
    assert tagged and tagged <= set(INTENTS)
    assert [as_intent(i) for i in INTENTS] == list(INTENTS)
