"""The names of what services count: each is a key of their Stats (`hri stats`, the view's panel, the tests'
assertions), so each is declared here once, as a Literal the type checker holds every `counters.add` to: a
misspelt counter fails `make typecheck` instead of starting a new, silent count. Rejected samples are counted
by the contract's reasons instead (common.schema.REASONS); gauges such as fusion's clock offsets are set by name.
"""

from __future__ import annotations

from typing import Literal

from common.schema import ClarificationReason, SpeakerMethod

# the runner's own, for every service (common/runner.py)
RunnerCounter = Literal["received", "published", "skipped", "dropped_overflow", "handler_error", "timeline_reset"]

# speech: why an utterance was not published (or was changed), and how the recogniser was used
SpeechCounter = Literal[
    "utterances",
    "partials",
    "speculation_used",
    "speculation_wasted",
    "format_changed",
    "clock_resync",
    "too_short",
    "utterance_cut",
    "repeats_removed",
    "tail_removed",
    "short_command",
    "no_speech",
    "no_words",
    "not_a_command",
    "low_confidence",
    "mic_overflow",
    "empty_line",
    # the robot's own voice (issue #43, docs/voice.md): spans masked, what was heard in them and dropped, stops kept
    "own_voice_spans",
    "own_voice_dropped",
    "barge_in",
    "own_voice_clipped",  # the microphone at full scale under the robot's voice: the echo cannot be taken out
]
# what a recogniser may give as the reason an utterance has no text (Recognition.dropped)
NoTextReason = Literal["no_speech", "no_words"]

# gesture
GestureCounter = Literal["depth_unmatched", "ended_idle_stream", "skipped_building_graphs"]

# ros2 (the ROS 2 bridge, services/ros2)
Ros2Counter = Literal["ros_published", "ros_topics_retired", "held_while_busy"]

# fusion: inputs it did not use, and what became of utterances, gestures and questions
FusionCounter = Literal[
    "late",
    "duplicate",
    "timeline_reset",
    "partial_ignored",
    "duplicate_of_gesture",
    "ignored_no_intent",
    "bare_reference",
    "unknown_noun",
    "refused_affordance",
    "deixis_unresolved",
    "speaker_side",
    "persons_as_candidates",
    "person_target",
    "recipient_unknown",
    "cancelled_by_stop_gesture",
    "stop_gesture_conflict",
    "palm_during_utterance",
    "gesture_stop",
    "gesture_come_here",
    "clarification_ambiguous",
    "clarification_conflict",
    "clarification_not_found",
    "clarification_low_confidence",
    "dialogue_expired",
    "dialogue_unresolved",
    "dialogue_cancelled",
    "dialogue_doubted_confirm",
    "corrected_by_speech",
    "speaker_mouth_motion",
    "speaker_only_face",
    "speaker_unknown",
    "unaddressed_confirm",
    # the robot (issue #43, docs/robot.md)
    "robot_states",
    "refused_ability",
    "refused_not_holding",
    "asked_while_busy",
    "queued_while_busy",
    "released_after_busy",
    "queue_dropped_by_stop",
    "robot_failure_announced",
    "question_spoken",  # the voice said the open question: its answer window counts from its end (docs/voice.md)
    "answer_before_spoken",  # words begun before the robot finished asking: not taken as the answer
]
GestureIntent = Literal["stop", "come_here"]  # the commands a gesture alone gives
GESTURE_COMMAND_COUNTER: dict[GestureIntent, FusionCounter] = {"stop": "gesture_stop", "come_here": "gesture_come_here"}
# how each utterance's speaker was attributed (services/fusion/speaker.py)
SPEAKER_COUNTER: dict[SpeakerMethod, FusionCounter] = {
    "mouth_motion": "speaker_mouth_motion",
    "only_face": "speaker_only_face",
    "unknown": "speaker_unknown",
}
CLARIFICATION_COUNTER: dict[ClarificationReason, FusionCounter] = {
    "ambiguous": "clarification_ambiguous",
    "conflict": "clarification_conflict",
    "not_found": "clarification_not_found",
    "low_confidence": "clarification_low_confidence",
}

# voice (services/voice): utterances synthesised, played to the end, cut short by a stop
VoiceCounter = Literal["synthesised", "spoken", "interrupted"]

CounterName = RunnerCounter | SpeechCounter | GestureCounter | FusionCounter | Ros2Counter | VoiceCounter
