"""What the robot says and when: pure rules, no Zenoh, no synthesiser.

`utterance_for` turns a Clarification (a question or a refusal) or, when asked, a FusedCommand (a confirmation)
into the words to say; `Schedule` places each utterance on the source-time line after the one before (the robot
says one thing at a time); `audio_chunks` cuts the spoken audio into the AudioChunks the wire carries (the speech
service's remote-microphone format), stamped with when each is played.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from common.schema import AudioChunk, Clarification, FusedCommand, SpokenKind

CHUNK_SECONDS = 0.02  # 20 ms chunks, as the speech service's own WAV and microphone input
LEAD_SECONDS = 0.1  # the first chunk is stamped this far ahead: the Spoken sample reaches speech before the audio
GAP_SECONDS = 0.3  # silence between two utterances of the robot's
# each chunk is sent this long before its play time (its stamp): a speaker on the wire buffers it and plays it on
# time, and speech has its echo reference before the microphone hears it, though the sender is descheduled for a
# moment (sent at its play time, on a loaded machine the reference came >0.1 s after the microphone's audio)
SEND_AHEAD_SECONDS = 0.25

# How the robot confirms a command (--confirm): the verb in the progressive ("Picking up the red candy.")
CONFIRM_VERBS = {
    "pick_up": "Picking up",
    "bring": "Bringing",
    "put_down": "Putting down",
    "go_to": "Going to",
    "come_here": "Coming",
    "stop": "Stopping",
    "look_at": "Looking at",
    "follow": "Following",
    "greet": "Hello",
    "move": "Moving",
    "turn": "Turning",
}


@dataclass(frozen=True)
class Say:
    text: str
    kind: SpokenKind
    answers: str | None  # the id of the sample it speaks


def is_refusal(question: Clarification) -> bool:
    """A refusal ("I can't pick up a couch."): fusion sends it as a `not_found` Clarification without candidates
    (docs/wire.md); what tells it from a question without candidates ("Where do you mean? …") is that it asks
    nothing (no "?" anywhere: "Where do you mean? Please point at the place." asks)."""
    return question.reason == "not_found" and not question.candidates and "?" not in question.question


def confirmation_text(command: FusedCommand) -> str:
    """A short sentence that says what the robot is about to do: "Picking up the red candy."."""
    verb = CONFIRM_VERBS.get(command.intent, command.intent.replace("_", " ").capitalize())
    what = ""
    if command.target is not None:
        what = " the " + " ".join(w for w in (command.target.color, command.target.label) if w)
    elif command.place:
        what = " the " + command.place
    return f"{verb}{what}."


def utterance_for(sample: Clarification | FusedCommand, confirm: bool = False) -> Say | None:
    """The words the robot says for a sample, or None (a command when confirmations are off)."""
    if isinstance(sample, Clarification):
        return Say(sample.question, "refusal" if is_refusal(sample) else "question", sample.id)
    if confirm:
        return Say(confirmation_text(sample), "confirmation", sample.id)
    return None


@dataclass
class Schedule:
    """When the next utterance starts: now (plus the lead), or after the one being said and a gap."""

    busy_until: float = 0.0

    def place(self, now: float, seconds: float) -> tuple[float, float]:
        start = max(now + LEAD_SECONDS, self.busy_until + GAP_SECONDS)
        self.busy_until = start + seconds
        return start, self.busy_until

    def cut(self, at: float) -> None:
        """The utterance under way was stopped at `at`: the next may start sooner."""
        self.busy_until = min(self.busy_until, at)


def to_pcm16(samples: np.ndarray) -> np.ndarray:
    """Float samples in [-1, 1] -> int16 (clipped)."""
    return np.clip(np.round(np.asarray(samples, dtype=np.float64) * 32767.0), -32768, 32767).astype("<i2")


def audio_chunks(pcm: np.ndarray, rate: int, start: float, speaker: str, source: str) -> list[AudioChunk]:
    """Mono int16 audio cut into CHUNK_SECONDS AudioChunks; chunk i is stamped with its first sample's play time."""
    step = max(1, int(rate * CHUNK_SECONDS))
    return [
        AudioChunk(
            stamp=start + offset / rate,
            source=source,
            mic=speaker,
            rate=rate,
            channels=1,
            format="s16le",
            data=pcm[offset : offset + step].astype("<i2").tobytes(),
        )
        for offset in range(0, len(pcm), step)
    ]
