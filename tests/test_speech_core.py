"""Speech service core, no zenoh: grammar, audio, resampling, VAD segmentation, stream clock."""

import wave

import numpy as np
import pytest

from common import language
from services.speech.audio import AudioError, Resampler, pcm_to_mono, read_wav, wav_files
from services.speech.grammar import build_grammar, normalise
from services.speech.pipeline import MicStream
from services.speech.recognizers import RecognisedWord, Recognition, derive_pronunciation
from services.speech.vad import Segmenter, VadConfig, make_segmenter
from testkit.synth import synthesize


# -- grammar -------------------------------------------------------------------
def test_grammar_accepts_commands_built_from_the_language_and_rejects_other_sentences():
    matches = build_grammar().matcher()
    for text in (
        "pick up the red cup",
        "bring me that",
        "put it on the table",
        "go to the kitchen",
        "can you please pick that up",
        "no not that one",
        "the left one",
        "hello robot",
        "give me the one on the right",
        "put the red ball in the box",
    ):
        assert matches(text), text
    for text in ("the weather is nice", "pick up the", "cup red the", "", "bring me that banana cake"):
        assert not matches(text), text


def test_grammar_uses_every_phrase_of_the_language_and_reports_what_it_skips():
    known = {"leftmost"}  # pretend the dictionary lacks one word
    grammar = build_grammar(lambda w: w not in known)
    words = grammar.words()
    for table in (language.INTENT_PHRASES, language.COLOR_PHRASES, language.OBJECT_PHRASES, language.PLACE_PHRASES):
        for phrases in table.values():
            for p in phrases:
                assert set(p.split()) <= words, p
    assert "leftmost" not in words and "leftmost" in grammar.skipped
    assert "<utterance>" in grammar.jsgf() and grammar.jsgf().startswith("#JSGF V1.0;")


def test_fsg_word_graph_accepts_exactly_what_the_matcher_accepts():
    grammar = build_grammar()
    graph = grammar.fsg()
    edges: dict[int, list[tuple[int, str | None]]] = {}
    for a, b, w, _ in graph.words:
        edges.setdefault(a, []).append((b, w))
    for a, b, _ in graph.nulls:
        edges.setdefault(a, []).append((b, None))

    def accepts(words: list[str]) -> bool:
        states = {graph.start}
        for word in [*words, None]:
            closure, todo = set(states), list(states)
            while todo:
                for b, w in edges.get(todo.pop(), []):
                    if w is None and b not in closure:
                        closure.add(b)
                        todo.append(b)
            if word is None:
                return graph.final in closure
            states = {b for s in closure for b, w in edges.get(s, []) if w == word}
        return False

    matches = grammar.matcher()
    for text in (
        "pick up the red cup",
        "stop",
        "put it there",
        "the weather is nice",
        "yes the red one",
        "go to the kitchen please",
        "red the cup",
    ):
        assert accepts(text.split()) == matches(text), text


def test_fsg_word_graph_is_a_probability_model():
    # every state but the final one passes on exactly all of its probability, so no sentence shape
    # gets weight from nowhere (the decoder compares paths by these priors)
    graph = build_grammar().fsg()
    out: dict[int, float] = {}
    for a, _, _, p in graph.words:
        out[a] = out.get(a, 0.0) + p
    for a, _, p in graph.nulls:
        out[a] = out.get(a, 0.0) + p
    assert graph.final not in out
    assert set(out) == set(range(graph.n_states)) - {graph.final}
    for state, total in out.items():
        assert abs(total - 1.0) < 1e-9, (state, total)
    assert all(0.0 < p <= 1.0 for *_, p in graph.words)


def test_normalise_lowercases_and_drops_punctuation():
    assert normalise("  Pick UP, the red cup! ") == "pick up the red cup"
    # typed (--backend text) or heard, an amount keeps its number: the parser reads digits
    assert normalise("Go forward 2.5 meters, then turn 90 degrees.") == "go forward 2.5 meters then turn 90 degrees"
    assert normalise("Don't move 1,000 steps") == "don't move 1000 steps"


def test_missing_pronunciations_are_derived_from_known_words():
    dictionary = {"left": "L EH F T", "most": "M OW S T", "smarties": "S M AA R T IY Z"}
    assert derive_pronunciation("leftmost", dictionary.get) == "L EH F T M OW S T"
    assert derive_pronunciation("smartie", dictionary.get) == "S M AA R T IY"
    assert derive_pronunciation("qwzx", dictionary.get) is None


# -- audio ----------------------------------------------------------------------
def _tone(rate: int, seconds: float, hz: float) -> np.ndarray:
    t = np.arange(int(rate * seconds)) / rate
    return (0.5 * np.sin(2 * np.pi * hz * t)).astype(np.float32)


@pytest.mark.parametrize("rate", [8000, 22050, 44100, 48000])
def test_streaming_resampler_keeps_a_tone_and_the_sample_clock(rate):
    tone = _tone(rate, 1.0, 440.0)
    rs = Resampler(rate)
    parts = [rs.process(tone[i : i + 333]) for i in range(0, len(tone), 333)]
    out = np.concatenate(parts + [rs.process(np.zeros(0, np.float32), final=True)])
    assert abs(len(out) - 16000) <= 1  # one second in, one second out
    ref = _tone(16000, 1.0, 440.0)[: len(out)]
    middle = slice(200, len(out) - 200)
    assert np.max(np.abs(out[middle] - ref[middle])) < 0.02


def test_resampler_removes_content_above_the_new_nyquist():
    out = Resampler(48000).process(_tone(48000, 0.5, 12000.0), final=True)  # 12 kHz cannot exist at 16 kHz
    assert np.sqrt(np.mean(out[200:-200] ** 2)) < 0.02


def test_pcm_to_mono_averages_channels_and_refuses_partial_frames():
    stereo = np.array([1000, 3000, -2000, 0], dtype="<i2").tobytes()
    assert np.allclose(pcm_to_mono(stereo, 2), [2000 / 32768, -1000 / 32768])
    with pytest.raises(AudioError):
        pcm_to_mono(stereo[:6], 2)


def test_truncated_and_garbage_wavs_raise_clear_errors(tmp_path):
    good = synthesize("stop", tmp_path / "stop.wav")
    truncated = tmp_path / "truncated.wav"
    truncated.write_bytes(good.read_bytes()[: len(good.read_bytes()) // 2])
    with pytest.raises(AudioError, match="truncated") as err:
        read_wav(truncated)
    assert err.value.reason == "truncated_wav"
    garbage = tmp_path / "garbage.wav"
    garbage.write_bytes(b"this is not audio at all" * 10)
    with pytest.raises(AudioError, match="sox") as err:
        read_wav(garbage)
    assert err.value.reason == "unreadable_wav"
    low = tmp_path / "low.wav"
    with wave.open(str(low), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(4000), w.writeframes(b"\0\0" * 4000)
    with pytest.raises(AudioError) as err:
        read_wav(low)
    assert err.value.reason == "unsupported_rate"


def test_wav_folders_play_in_name_order(tmp_path):
    for name in ("b.wav", "a.wav", "c.txt", "10.wav"):
        (tmp_path / name).write_bytes(b"")
    assert [p.name for p in wav_files([str(tmp_path)])] == ["10.wav", "a.wav", "b.wav"]


# -- VAD ---------------------------------------------------------------------
def _scripted(voiced: list[bool]):
    """A fake VAD speaking per window: the state machine alone, no model."""
    it = iter(voiced)
    return lambda window: 0.9 if next(it) else 0.05


def test_segmenter_pads_splits_and_drops_short_bursts():
    window = 512
    pattern = [False] * 20 + [True] * 30 + [False] * 20 + [True] * 2 + [False] * 20 + [True] * 40 + [False] * 20
    seg = Segmenter(_scripted(pattern), window, VadConfig())
    utts = seg.feed(np.zeros(len(pattern) * window, np.float32)) + seg.flush()
    assert len(utts) == 2 and seg.too_short == 1  # the 64 ms burst is noise
    first, second = utts
    assert first.speech_start == 20 * window and first.speech_end == 50 * window
    assert first.audio_start < first.speech_start  # pre-padding
    assert first.audio_start + len(first.audio) > first.speech_end  # post-padding
    assert second.speech_start == 92 * window and second.speech_end == 132 * window


def test_segmenter_cuts_endless_speech_at_the_maximum_length():
    window = 512
    pattern = [True] * 400
    seg = Segmenter(_scripted(pattern), window, VadConfig(max_utterance=3.0))
    utts = seg.feed(np.zeros(len(pattern) * window, np.float32)) + seg.flush()
    assert len(utts) >= 4 and all(u.forced for u in utts[:-1])
    assert all(u.speech_seconds <= 3.0 + window / 16000 for u in utts)


def test_silero_finds_nothing_in_silence_and_noise_only():
    seg = make_segmenter()
    rng = np.random.default_rng(0)
    silence = np.zeros(16000 * 3, np.float32)
    hiss = (0.01 * rng.standard_normal(16000 * 3)).astype(np.float32)
    assert seg.feed(silence) + seg.feed(hiss) + seg.flush() == []


# -- stream clock ----------------------------------------------------------------
class FakeRecogniser:
    name = "fake"
    min_confidence = 0.5

    def __init__(self):
        self.calls = 0

    def matches(self, text):
        return text == "stop"

    def recognise(self, audio):
        self.calls += 1
        n = len(audio) / 16000
        return Recognition("stop", 0.9, [RecognisedWord("stop", 0.1, n - 0.1, 0.9)])


def test_stream_stamps_come_from_the_audio_clock_and_gaps_resync(tmp_path):
    wav = read_wav(synthesize("stop", tmp_path / "stop.wav", voice="en-us"))
    counted: list[str] = []
    stream = MicStream("mic0", "speech/test", FakeRecogniser(), make_segmenter, lambda n, d: counted.append(n))
    t0 = 1_000_000.0
    heard = []
    step = 320
    for off in range(0, len(wav.samples), step):
        heard += stream.feed(wav.samples[off : off + step], wav.rate, t0 + off / wav.rate)
    # the same audio again, 30 s later: a gap in the stream
    t1 = t0 + 30.0
    for off in range(0, len(wav.samples), step):
        heard += stream.feed(wav.samples[off : off + step], wav.rate, t1 + off / wav.rate)
    heard += stream.flush()
    assert len(heard) == 2 and "clock_resync" in counted
    for h, base in zip(heard, (t0, t1)):
        t = h.transcript
        assert base <= t.start < t.end <= base + wav.seconds
        assert t.stamp == t.end and t.final and t.backend == "fake"
        assert all(base <= w.start < w.end <= base + wav.seconds for w in t.words)


def test_stream_restarts_when_the_sample_rate_changes():
    counted: list[str] = []
    stream = MicStream("mic0", "speech/test", FakeRecogniser(), make_segmenter, lambda n, d: counted.append(n))
    stream.feed(np.zeros(1600, np.float32), 16000, 100.0)
    stream.feed(np.zeros(4800, np.float32), 48000, 100.1)
    assert "format_changed" in counted
    with pytest.raises(AudioError):
        stream.feed(np.zeros(100, np.float32), 2000, 100.2)


# -- speculative decoding ----------------------------------------------------------
class SpeculativeRecogniser:
    """Records each decode's audio length; says 'stop' with word times inside the audio."""

    name = "fake-whisper"
    min_confidence = 0.0
    speculative = True
    matches = None  # no grammar gate

    def __init__(self):
        self.decoded: list[int] = []

    def recognise(self, audio):
        self.decoded.append(len(audio))
        n = len(audio) / 16000
        return Recognition("stop", 0.8, [RecognisedWord("stop", 0.2, n - 0.1, 0.8)])


def energy_segmenter():
    return Segmenter(lambda w: 1.0 if float(np.sqrt(np.mean(w**2))) > 0.01 else 0.0, 512, VadConfig())


def test_decoding_starts_when_silence_begins_and_is_redone_only_if_speech_resumes():
    t = np.arange(int(0.6 * 16000)) / 16000
    tone = (0.2 * np.sin(2 * np.pi * 300 * t)).astype(np.float32)
    pause, silence = np.zeros(int(0.15 * 16000), np.float32), np.zeros(16000, np.float32)
    audio = np.concatenate([silence[:8000], tone, pause, tone, silence])  # a 150 ms pause inside one utterance
    rec, counted = SpeculativeRecogniser(), []
    stream = MicStream("mic0", "speech/test", rec, energy_segmenter, lambda n, d: counted.append(n))
    heard = []
    for off in range(0, len(audio), 320):
        heard += stream.feed(audio[off : off + 320], 16000, 100.0 + off / 16000)
    heard += stream.flush()
    assert len(heard) == 1 and heard[0].transcript.text == "stop"
    # one decode at the pause (wasted: speech resumed), one at the end (used: no decode after the VAD decided)
    assert counted.count("speculation_wasted") == 1 and counted.count("speculation_used") == 1
    assert len(rec.decoded) == 2 and rec.decoded[1] >= 2 * len(tone) + len(pause)
    t_ = heard[0].transcript
    assert 100.45 <= t_.start and t_.end <= 100.5 + (2 * len(tone) + len(pause)) / 16000 + 0.2


def test_partials_come_while_the_person_speaks_and_never_after_the_final_result():
    t = np.arange(int(2.5 * 16000)) / 16000
    audio = np.concatenate(
        [
            np.zeros(8000, np.float32),
            (0.2 * np.sin(2 * np.pi * 300 * t)).astype(np.float32),
            np.zeros(16000, np.float32),
        ]
    )
    rec, counted = SpeculativeRecogniser(), []
    stream = MicStream("mic0", "speech/test", rec, energy_segmenter, lambda n, d: counted.append(n), partial_every=0.5)
    heard = []
    for off in range(0, len(audio), 320):
        heard += stream.feed(audio[off : off + 320], 16000, 100.0 + off / 16000)
        while stream._partial is not None and not stream._partial[1].done():
            pass  # the fake decodes at once; wait so the test does not depend on thread timing
    heard += stream.flush()
    finals = [h.transcript.final for h in heard]
    assert finals[-1] and finals.count(True) == 1 and 3 <= finals.count(False) <= 5, finals
    ends = [h.transcript.end for h in heard]
    assert ends == sorted(ends)  # each partial covers more of the utterance; the final covers it all
    # without partials: the same audio gives the final alone
    plain = MicStream("mic0", "speech/test", SpeculativeRecogniser(), energy_segmenter, lambda n, d: None)
    alone = [
        h for off in range(0, len(audio), 320) for h in plain.feed(audio[off : off + 320], 16000, 100.0 + off / 16000)
    ]
    alone += plain.flush()
    assert [h.transcript.final for h in alone] == [True]


def test_the_final_transcript_carries_the_sound_level_on_the_audio_clock():
    """Transcript.loudness (issue #40): the level of the decoded audio every 20 ms from its first sample, so fusion
    can match it against the mouths in view; partials carry none."""
    t = np.arange(int(1.0 * 16000)) / 16000
    tone = (0.2 * np.sin(2 * np.pi * 300 * t)).astype(np.float32)  # RMS 0.141: -17 dBFS
    audio = np.concatenate([np.zeros(8000, np.float32), tone, np.zeros(16000, np.float32)])
    stream = MicStream("mic0", "speech/test", SpeculativeRecogniser(), energy_segmenter, lambda n, d: None)
    heard = [
        h for off in range(0, len(audio), 320) for h in stream.feed(audio[off : off + 320], 16000, 100.0 + off / 16000)
    ]
    heard += stream.flush()
    (final,) = [h.transcript for h in heard if h.transcript.final]
    loud = final.loudness
    assert loud is not None and loud.step == 0.02 and loud.start <= final.start
    centres = [loud.start + (k + 0.5) * loud.step for k in range(len(loud.db))]
    inside = [db for c, db in zip(centres, loud.db) if 100.55 <= c <= 101.45]
    outside = [db for c, db in zip(centres, loud.db) if c < 100.48 or c > 101.52]
    assert inside and set(inside) == {-17}
    assert outside and max(outside) <= -100  # the padding around the tone: silence
    assert centres[-1] >= 101.45  # the level covers the whole tone
