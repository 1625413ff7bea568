"""The robot's voice (services/voice) and the speech service's guard against it (services/speech/echo.py, the gate
in pipeline.py): the rules without Zenoh, then the pipeline on real audio (piper questions played through a room,
real recorded words said over them)."""

from __future__ import annotations

import numpy as np
import pytest

from common.schema import Clarification, ClarificationReason, FusedCommand, Spoken, Target, Weights
from services.ros2 import core as ros2_core
from services.ros2.config import Ros2Config
from services.speech.echo import EchoCanceller, OwnVoice, delayed
from services.voice.core import GAP_SECONDS, LEAD_SECONDS, Schedule, audio_chunks, to_pcm16, utterance_for
from testkit.room import at_level, echo_of, room_response
from testkit.synth import RATE, speech_power

T = 1_800_000_000.0


def clarification(question: str, reason: ClarificationReason = "ambiguous", candidates: int = 2) -> Clarification:
    target = Target(id="o1", label="cup", bbox=[0, 0, 1, 1], center=[0, 0], score=0.9, cam="c")
    return Clarification(
        stamp=T, source="fusion/a", id="q1", reason=reason, question=question, candidates=[target] * candidates
    )


def command(intent: str, color: str | None = "red", label: str = "candy") -> FusedCommand:
    target = Target(id="o1", label=label, color=color, bbox=[0, 0, 1, 1], center=[0, 0], score=0.9, cam="c")
    return FusedCommand(
        stamp=T,
        source="fusion/a",
        id="c1",
        intent=intent,
        target=target if intent != "stop" else None,
        confidence=0.9,
        weights=Weights(speech=0.5, vision=0.5, gesture=0.0),
        inputs={},
        explanation="",
        prompt="",
    )


def test_questions_refusals_and_confirmations_are_said_as_asked():
    asked = utterance_for(clarification("Which cup: the red one or the blue one?"))
    assert asked is not None and (asked.kind, asked.answers) == ("question", "q1")
    refused = utterance_for(clarification("I can't pick up a chair.", "not_found", candidates=0))
    assert refused is not None and refused.kind == "refusal" and refused.text == "I can't pick up a chair."
    where = utterance_for(clarification("Where do you mean? Please point at the place.", "not_found", 0))
    assert where is not None and where.kind == "question"
    assert utterance_for(command("pick_up")) is None  # confirmations only when asked
    confirmed = utterance_for(command("pick_up"), confirm=True)
    assert confirmed is not None and confirmed.text == "Picking up the red candy." and confirmed.answers == "c1"
    stop = utterance_for(command("stop"), confirm=True)
    assert stop is not None and stop.text == "Stopping."


def test_the_robot_says_one_thing_at_a_time_and_a_cut_frees_it():
    s = Schedule()
    assert s.place(T, 2.0) == (T + LEAD_SECONDS, T + LEAD_SECONDS + 2.0)
    start, end = s.place(T + 0.5, 1.0)  # asked while the first is still being said
    assert start == pytest.approx(T + LEAD_SECONDS + 2.0 + GAP_SECONDS) and end == pytest.approx(start + 1.0)
    s.cut(T + 1.0)
    assert s.place(T + 1.0, 1.0)[0] == pytest.approx(T + 1.0 + max(LEAD_SECONDS, GAP_SECONDS))


def test_audio_goes_out_in_chunks_stamped_with_their_play_time():
    pcm = to_pcm16(np.linspace(-1.2, 1.2, RATE + 100))  # clipped, not wrapped
    assert pcm.min() == -32768 or pcm.min() == -32767 and pcm.max() == 32767
    chunks = audio_chunks(pcm, RATE, T, "robot", "voice/a")
    assert len(chunks) == 51 and chunks[1].stamp == pytest.approx(T + 0.02)
    assert b"".join(c.data for c in chunks) == pcm.tobytes() and {c.mic for c in chunks} == {"robot"}


def test_ros2_offers_each_utterance_once():
    said = Spoken(
        stamp=T,
        source="voice/a",
        id="q",
        text="Which cup?",
        kind="question",
        start=T,
        end=T + 1,
        speaker="r",
        voice="v",
    )
    (out,) = ros2_core.spoken_messages(said, Ros2Config())
    assert out.topic.endswith("/robot_speech") and out.message.data == "Which cup?"
    assert ros2_core.spoken_messages(said.__replace__(stamp=T + 0.5, end=T + 0.5), Ros2Config()) == []  # a cut


def speech_like(seconds: float, seed: int) -> np.ndarray:
    """Noise shaped like speech: bursts of band-limited noise (for the canceller's own test, no models)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    noise = np.convolve(rng.standard_normal(n), np.hanning(9), "same")
    envelope = (np.sin(np.arange(n) / RATE * 2 * np.pi * 3) > -0.3).astype(float)
    return 0.1 * noise * envelope


def test_the_echo_canceller_learns_the_room_and_keeps_a_voice_said_over_it():
    ir = room_response()
    reference = speech_like(3.0, 1)
    mic = echo_of(reference, ir)[: len(reference)]
    canceller = EchoCanceller()
    residual = canceller.cancel(mic, reference)
    assert 10 * np.log10(np.mean(mic**2) / np.mean(residual**2)) > 25  # the echo alone: taken out
    # the next utterance, with a person talking over its middle second (double talk)
    reference2 = speech_like(3.0, 2)
    person = np.zeros(len(reference2))
    person[RATE : 2 * RATE] = at_level(speech_like(1.0, 3), echo_of(reference2, ir), -6.0)
    mic2 = echo_of(reference2, ir)[: len(reference2)] + person
    left = canceller.cancel(mic2, reference2)
    echo_left = left - person
    assert 10 * np.log10(speech_power(person) / np.mean(echo_left**2)) > 15  # the person stands out of what is left
    assert np.corrcoef(left[RATE : 2 * RATE], person[RATE : 2 * RATE])[0, 1] > 0.95


@pytest.mark.parametrize("delay", [0.5 / RATE, 1 / RATE, 0.0023, -0.004])
def test_the_echo_canceller_follows_an_echo_that_arrives_later_or_earlier_than_before(delay):
    """A sound device's output latency differs at each start: the path learnt on one utterance, moved to where the
    next one's echo arrives. Unmoved, one sample later already leaves most of the echo (7 dB taken out of 35)."""
    ir = room_response()
    canceller = EchoCanceller()
    reference = speech_like(3.0, 1)
    canceller.cancel(echo_of(reference, ir)[: len(reference)], reference)
    kept = canceller.path.copy()
    reference2 = speech_like(3.0, 2)
    mic2 = delayed(echo_of(reference2, ir)[: len(reference2)], delay * RATE)
    left = canceller.apply(mic2, reference2)
    assert 10 * np.log10(np.mean(mic2**2) / np.mean(left**2)) > 25
    unmoved = EchoCanceller(path=kept.copy())
    unmoved.follow_delay = lambda mic, reference: 0.0
    assert 10 * np.log10(np.mean(mic2**2) / np.mean(unmoved.apply(mic2, reference2) ** 2)) < 15
    # what does not sound like the echo (the robot's speaker muted: only a person) moves nothing
    quiet = EchoCanceller(path=kept.copy())
    assert quiet.follow_delay(speech_like(3.0, 3), reference2) == 0.0 and np.array_equal(quiet.path, kept)


def test_own_voice_masks_the_announced_spans_plus_the_tail_and_a_cut_shortens_them():
    own = OwnVoice(tail=0.3)
    own.announce("a", "Which cup?", T, T + 2.0)
    assert own.masked_until(T - 0.01) is None and own.next_start(T - 1) == T
    assert own.masked_until(T + 2.2) == pytest.approx(T + 2.3) and own.masked_until(T + 2.31) is None
    own.announce("a", "Which cup?", T, T + 1.0)  # cut short by a stop
    assert own.masked_until(T + 1.5) is None and own.texts(T, T + 1) == ["Which cup?"]
    own.add_reference(T + 0.02, np.ones(320, np.float32))
    own.add_reference(T, np.full(320, 0.5, np.float32))
    ref = own.reference(T - 0.01, 1000)
    assert ref[:160].sum() == 0 and ref[160:480].max() == 0.5 and ref[480:800].min() == 1.0 and ref[800:].sum() == 0


# -- the speech pipeline with the robot's voice on its microphone (real models, real recordings) ------------------


@pytest.fixture(scope="module")
def spoken_questions() -> list[np.ndarray]:
    from services.voice.synth import PiperVoice

    voice = PiperVoice()
    return [voice.speak(q) for q in PIPELINE_QUESTIONS]


@pytest.fixture(scope="module")
def whisper():  # noqa: ANN201
    from services.speech.whisper import WhisperRecognizer

    recogniser = WhisperRecognizer()
    recogniser.recognise(np.zeros(8000, np.float32))
    return recogniser


PIPELINE_QUESTIONS = (
    "Which cup: the red one or the blue one?",
    "I can't pick up a chair.",
    "Which candy: the red one on the left, the green one in the middle or the blue one on the right?",
)


def robot_ears(whisper):  # noqa: ANN001, ANN201
    from services.speech.pipeline import MicStream
    from services.speech.vad import make_segmenter

    own = OwnVoice()
    counted: list[str] = []
    stream = MicStream(
        "mic0", "test", whisper, make_segmenter, lambda name, detail: counted.append(name), own_voice=own
    )
    return stream, own, counted


def test_the_robot_hears_neither_its_question_nor_its_refusal_but_a_stop_said_over_it(spoken_questions, whisper):
    from testkit.room import hear, scene
    from testkit.shared import shared_path

    stop = read_clip(shared_path("data/speech_commands/stop_2c6d3924_nohash_0.wav"))
    stream, own, counted = robot_ears(whisper)
    ir = room_response()
    question, refusal, _ = spoken_questions
    assert hear(stream, own, scene(question, None, 0, 0, ir), question, T, PIPELINE_QUESTIONS[0], 0) == []
    assert hear(stream, own, scene(refusal, None, 0, 0, ir), refusal, T + 20, PIPELINE_QUESTIONS[1], 1) == []
    assert counted.count("own_voice_spans") == 2 and "barge_in" not in counted
    # a person says "stop" over the question, as loud as the robot's echo
    heard = hear(stream, own, scene(question, stop, 0.5, 0.0, ir), question, T + 40, PIPELINE_QUESTIONS[0], 2)
    assert [t.text for t in heard] == ["stop"] and counted.count("barge_in") == 1
    assert "own_voice_clipped" not in counted
    assert T + 40 + 0.5 + 0.3 < heard[0].end < T + 40 + 0.5 + 0.5 + 1.3  # stamped when it was said (LEAD 0.5)


@pytest.mark.parametrize("delay", [1 / RATE, 0.0023])
def test_a_stop_over_the_robot_is_heard_when_its_echo_comes_later_than_at_the_last_question(
    spoken_questions, whisper, delay
):
    """The echo path learnt on one question, the next one's echo a sample (or 2.3 ms) later: the live test's
    failure (a stop over the second question heard as 'start with'); with the path unmoved, 0 of 12 stops here."""
    from testkit.room import hear, scene
    from testkit.shared import shared_path

    stop = read_clip(shared_path("data/speech_commands/stop_47d01978_nohash_0.wav"))
    stream, own, counted = robot_ears(whisper)
    ir = room_response()
    question, _, long_question = spoken_questions
    assert hear(stream, own, scene(question, None, 0, 0, ir), question, T, PIPELINE_QUESTIONS[0], 0) == []
    mic = scene(long_question, stop, 0.6, 0.0, ir, delay=delay)
    heard = hear(stream, own, mic, long_question, T + 20, PIPELINE_QUESTIONS[2], 1)
    assert [t.text for t in heard] == ["stop"], counted


def test_a_microphone_that_clips_under_the_robots_voice_is_reported(spoken_questions, whisper):
    """The live room's old fault (the echo at 2.6x full scale): no linear canceller takes a clipped echo out, so
    the pipeline says so, with what to do."""
    from testkit.room import MIC_GAIN, hear, scene

    question, ir = spoken_questions[0], room_response()
    for gain, reported in ((1.0, 1), (MIC_GAIN, 0)):  # the microphone at gain 1 (as the live room was), as now
        stream, own, counted = robot_ears(whisper)
        room = scene(question, None, 0, 0, ir, gain=gain)
        mic = np.clip(np.round(room * 32767), -32768, 32767) / 32768
        hear(stream, own, mic, question, T, PIPELINE_QUESTIONS[0], 0)
        assert counted.count("own_voice_clipped") == reported, gain


def test_an_answer_after_the_question_is_heard_as_usual(spoken_questions, whisper, tmp_path):
    from testkit.room import LEAD, hear, scene
    from testkit.synth import PIPER_VOICE, synthesize

    answer = read_clip(synthesize("the red one", tmp_path / "a.wav", voice=PIPER_VOICE, lead_silence=0))
    stream, own, _ = robot_ears(whisper)
    question = spoken_questions[0]
    seconds = len(question) / RATE
    mic = scene(question, None, 0, 0, room_response())
    mic = np.concatenate([mic, np.zeros(3 * RATE)])
    at = int((LEAD + seconds + 0.8) * RATE)  # 0.8 s after the robot finished (0.5 s past the masked tail)
    mic[at : at + len(answer)] += 0.5 * answer
    heard = hear(stream, own, mic, question, T, PIPELINE_QUESTIONS[0], 0)
    assert [t.text for t in heard] == ["the red one"]


def read_clip(path) -> np.ndarray:  # noqa: ANN001
    from testkit.synth import read_wav_int16

    return read_wav_int16(path).astype(np.float64) / 32768.0


def test_a_sound_device_that_cannot_be_used_stops_the_voice_with_a_clear_error():
    import subprocess
    import sys

    try:
        import sounddevice  # noqa: F401

        pytest.skip("PortAudio is installed here: the device may well work")
    except (ImportError, OSError):
        pass  # no sounddevice, or it without PortAudio: what this test is about
    res = subprocess.run(
        [sys.executable, "-m", "services.voice", "--device", "default"], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 2 and "libportaudio2" in res.stderr and "--wav-dir" in res.stderr, res.stderr
