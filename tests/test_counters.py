"""The counter names of common/counters.py: the tables that name a counter after a contract word cover every word."""

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
