"""Short words from real people (issue 23): the 100 real one-second clips of ten command words in
../shared/data/speech_commands/ (Speech Commands v0.02, ten speakers per word) through the service's pipeline
with the default recogniser (VAD -> Whisper tiny.en -> the short-utterance decode), and fusion's stop rules.

Bounds are measured over repeated runs (docs/speech.md: CTranslate2 on two threads is not bit-reproducible)
with a margin below the worst run. Skipped with the reason when ../shared/ is absent."""

from __future__ import annotations

import numpy as np
import pytest

from common.language import ONE_WORD_EXTRAS, STOP_WORDS, one_word_commands
from services.fusion.parse import parse, stop_near_miss
from services.speech.audio import RATE, read_wav
from services.speech.pipeline import MicStream
from services.speech.vad import make_segmenter
from services.speech.whisper import (
    MAX_COMMAND_COPIES,
    SHIFT_SECONDS,
    SPEED_FACTORS,
    WhisperRecognizer,
    choose_command,
    remove_loops,
    resample_speed,
    scoring_copies,
)
from testkit.shared import shared_path

T0 = 1_700_000_000.0
WORDS = ("down", "go", "left", "no", "off", "on", "right", "stop", "up", "yes")
# Measured over 5 runs with the scoring copies (docs/speech.md): 90, 90, 90, 90, 90 of 100 right (89 in each of 4
# runs before them); stop clips stopped 10 of 10 in each; false stops 0 of 90 in each. Asserted with a margin of 3
# clips (another machine's threads may differ by a clip or two); every stop clip must stop (the done-when).
# With Whisper's encoder on a 20 s window (issue #34, docs/speech.md): 89 and 89 of 100 (two runs): the margin is
# now 2 clips; every stop clip still stopped.
MIN_RIGHT = 87
MAX_FALSE_STOPS = 2


# -- pure rules ------------------------------------------------------------------------------------


def test_a_heard_word_outside_the_commands_gives_way_to_a_likely_command():
    commands = {"off": 0.02, "up": 0.01, "stop": 0.0}
    assert choose_command("of", 0.3, commands, prior=20.0).word == "off"  # 0.02 * 20 >= 0.3
    assert choose_command("hello", 0.9, commands, prior=20.0).word == "hello"  # 0.02 * 20 < 0.9: kept
    kept = choose_command("up", 0.6, {"up": 0.6, "off": 0.3}, prior=20.0)  # a command heard is never replaced
    assert kept.word == "up" and not kept.changed


def test_the_scoring_copies_are_the_utterance_shifted_and_speed_perturbed():
    t = np.arange(RATE) / RATE
    audio = (0.3 * np.sin(2 * np.pi * 220 * t)).astype(np.float32)  # one second of a 220 Hz tone
    copies = scoring_copies(audio)
    assert len(copies) == MAX_COMMAND_COPIES and all(c.dtype == np.float32 for c in copies)
    heard, early, slower, faster, late = copies
    assert np.array_equal(heard, audio)
    for shifted, seconds in ((early, SHIFT_SECONDS[0]), (late, SHIFT_SECONDS[1])):
        lead = int(seconds * RATE)
        assert not shifted[:lead].any() and np.array_equal(shifted[lead:], audio)
    for played, factor in ((slower, SPEED_FACTORS[0]), (faster, SPEED_FACTORS[1])):
        assert len(played) == round(RATE / factor)
        spectrum = np.abs(np.fft.rfft(played))
        assert np.argmax(spectrum) / (len(played) / RATE) == pytest.approx(220 * factor, abs=2)  # pitch moves too
    assert [len(c) for c in scoring_copies(audio, 2)] == [len(heard), len(early)]
    assert len(resample_speed(audio[:1], 1.1)) == 1
    with pytest.raises(ValueError, match="1-5"):
        scoring_copies(audio, MAX_COMMAND_COPIES + 1)


def test_the_one_word_commands_come_from_the_language():
    words = one_word_commands()
    assert set(STOP_WORDS) <= set(words) and set(ONE_WORD_EXTRAS) <= set(words)
    assert {"yes", "no", "go", "left", "right"} <= set(words)
    assert all(" " not in w for w in words) and len(words) == len(set(words))


def test_no_no_no_survives_the_loop_guard_but_other_repeats_do_not():
    assert remove_loops("no no no".split(), repeatable={"no"}) == ["no", "no", "no"]
    assert remove_loops("yes yes".split(), repeatable={"no"}) == ["yes"]
    assert remove_loops("turn left turn left".split(), repeatable={"no"}) == ["turn", "left"]


@pytest.mark.parametrize(
    "text",
    [
        "stop",
        "please stop",
        "pick up the red cup and stop",
        "halt",
        "freeze",
        "wait",
        "wait for me",
        "no no no",
        "no wait",
        "stopp",
        "go to the door stop",
        "the red one no stop",
    ],
)
def test_a_stop_word_anywhere_stops(text):
    assert parse(text).intent == "stop", text


@pytest.mark.parametrize(
    "text",
    [
        "i want the red cup",
        "no",
        "no no",
        "no wait the blue one",
        "step forward",
        "put it on top",
        "go left",
        "what is that",
    ],
)
def test_words_near_a_stop_word_do_not_stop(text):
    assert parse(text).intent != "stop", text


def test_a_doubted_near_miss_of_a_stop_word_stops_and_a_sure_one_does_not():
    assert stop_near_miss([("stap", 0.3)]) == ("stap", "stop")
    assert stop_near_miss([("please", 0.9), ("halp", 0.2)]) == ("halp", "halt")
    assert stop_near_miss([("stap", 0.9)]) is None  # the recogniser was sure of what it heard
    # words the language knows, and words that start differently, are never near misses
    assert all(stop_near_miss([(w, 0.1)]) is None for w in ("want", "step", "top", "what", "shop", "start"))


@pytest.mark.parametrize("conf, stops", [(0.3, True), (0.9, False)])
def test_fusion_stops_at_once_on_a_doubted_near_miss_and_says_why(conf, stops):
    from services.fusion.core import Config, FusionCore
    from testkit.scenarios import BASE_STAMP, say

    core = FusionCore(Config(), "fusion/test")
    key, t = say(0.2, 0.6, "stap", conf=conf).build(BASE_STAMP)
    out = core.on_transcript(key, t, 1000.0)
    if stops:
        (output,) = out
        command = output.sample
        assert command.intent == "stop" and output.realtime
        assert "'stap'" in command.explanation and "'stop'" in command.explanation
    else:
        assert all(getattr(o.sample, "intent", None) != "stop" for o in out + core.tick(1010.0))


# -- the real clips -----------------------------------------------------------------------------------


def clips() -> list[tuple[str, np.ndarray, int]]:
    folder = shared_path("data/speech_commands")
    out = []
    for path in sorted(folder.glob("*.wav")):
        wav = read_wav(path)
        out.append((path.name.split("_")[0], wav.samples, wav.rate))
    return out


def hear(recogniser, samples: np.ndarray, rate: int) -> tuple[list[str], list[str]]:
    """One clip, with 0.6 s of silence either side (a person pausing), as 20 ms chunks through the pipeline."""
    counted: list[str] = []
    stream = MicStream("mic0", "speech/test", recogniser, make_segmenter, lambda name, detail: counted.append(name))
    pad = np.zeros(int(0.6 * rate), np.float32)
    samples = np.concatenate([pad, samples.astype(np.float32), pad])
    heard, step = [], rate // 50
    for off in range(0, len(samples), step):
        heard += stream.feed(samples[off : off + step], rate, T0 + off / rate)
    heard += stream.flush()
    return [h.transcript.text for h in heard], counted


@pytest.fixture(scope="module")
def recogniser() -> WhisperRecognizer:
    """One model for the module: a decode keeps no state from the one before (speech tests load it once each)."""
    return WhisperRecognizer()


@pytest.fixture(scope="module")
def heard_clips(recogniser):
    material = clips()
    assert len(material) == 100 and sorted(set(w for w, _, _ in material)) == list(WORDS)
    return [(word, *hear(recogniser, samples, rate)) for word, samples, rate in material]


# 100 decodes: ~1.5 min on a quiet 2-core machine, 5+ min on a loaded one (the fixture runs in the first test)
@pytest.mark.timeout(1800)
def test_real_one_word_commands_are_heard_right(heard_clips):
    right = [w for w, texts, _ in heard_clips if texts == [w]]
    wrong = [
        (w, texts, [c for c in counted if c not in ("utterances", "speculation_used")])
        for w, texts, counted in heard_clips
        if texts != [w]
    ]
    print(f"{len(right)} of {len(heard_clips)} right; wrong: {wrong}")
    assert len(right) >= MIN_RIGHT, wrong
    for word in WORDS:  # no word is lost altogether (measured: 7 to 10 of 10 per word; "off" the worst)
        assert sum(w == word for w in right) >= 6, (word, wrong)


@pytest.mark.timeout(1800)
def test_every_real_stop_stops_and_other_words_rarely_do(heard_clips):
    def stops(texts: list[str]) -> bool:
        return any(parse(t).intent == "stop" for t in texts)

    missed = [texts for w, texts, _ in heard_clips if w == "stop" and not stops(texts)]
    false = [(w, texts) for w, texts, _ in heard_clips if w != "stop" and stops(texts)]
    print(f"stops missed {missed}; false stops {false}")
    assert missed == []
    assert len(false) <= MAX_FALSE_STOPS, false


# -- one-word utterances that are not commands ------------------------------------------------------------------


# 96 decodes: 144 s on a quiet 2-core machine, 276 s beside two busy loops (fresh clone, 29 Nov): over half of
# pytest's default 300 s. A hang guard, not a speed check: the same as the one-word tests above
@pytest.mark.timeout(1800)
def test_a_word_the_short_decode_makes_a_command_is_too_doubtful_to_act_on(recogniser, tmp_path):
    """Favouring the command words turns some ordinary single words into one ("chair" -> "sure"; docs/speech.md,
    13 of 48 with the decode, 2 without). What keeps that from moving the robot: the replaced word carries the
    command's own probability as its confidence, below fusion's --low-speech-confidence, so fusion asks first and
    a doubted "yes" does not confirm (measured 0.00-0.17 over 2 runs of all 48; the bound is fusion's 0.3)."""
    from services.fusion.core import Config
    from testkit.speech_scoring import NON_COMMAND_WORDS, AudioCache
    from testkit.synth import PIPER_VOICE

    cache = AudioCache(tmp_path)
    segmenter = make_segmenter()
    replaced = []
    for voice in (PIPER_VOICE, "en-us"):
        for word in NON_COMMAND_WORDS:
            samples = read_wav(cache.speech(word, voice)).samples
            for utt in segmenter.feed(samples) + segmenter.flush():
                result = recogniser.recognise(utt.audio)
                if result is not None and result.short_command:
                    replaced.append((word, voice, result.short_command, round(result.confidence, 3)))
    print("replaced:", replaced)
    assert replaced, "the short-utterance decode replaced no word: this test no longer checks anything"
    doubtful = Config().low_speech_confidence
    assert all(conf < doubtful for *_, conf in replaced), replaced
