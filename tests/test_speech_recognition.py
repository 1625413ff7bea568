"""Recognition on real speech made at test time with espeak-ng + sox: WER bounds per condition,
non-commands, one stream split into utterances. The bounds are what was measured on this machine
(docs/speech.md) plus a margin; they catch a broken grammar, VAD or resampler, not small drifts."""

from pathlib import Path

import pytest

from services.fusion.parse import parse
from services.speech.audio import read_wav
from services.speech.pipeline import MicStream
from services.speech.recognizers import PocketsphinxRecognizer
from services.speech.vad import make_segmenter
from testkit.speech_scoring import word_errors
from testkit.synth import concatenate, synthesize

EXPECTED = Path(__file__).parent / "data" / "speech"
COMMANDS = [line.strip() for line in (EXPECTED / "commands.txt").read_text().splitlines() if line.strip()]
NON_COMMANDS = [line.strip() for line in (EXPECTED / "non_commands.txt").read_text().splitlines() if line.strip()]
VOICES = ("en-us+f3", "en-us")
GAP = 0.8  # seconds of silence between the sentences of a test stream
# measured (docs/speech.md) -> bound asserted here. WER counts a rejected command as deleted words; a
# wrong command is one published whose meaning, as fusion's parser reads it, is not what was said
# ("look at to the blue ball" for "look at the blue ball" is right; "look the cup" for "put the cup" is not).
WER_BOUND = {("en-us+f3", None): 0.58, ("en-us+f3", 10): 0.72, ("en-us", None): 0.62, ("en-us", 10): 0.50}
# measured WER 0.51 / 0.65 / 0.56 / 0.42; wrong of published 9/18, 12/17, 8/17, 14/22 (same order), identical in
# 3 more runs on 2026-11-24 (pocketsphinx on this audio is deterministic). Margin: 0.06-0.08 WER (5-7 of 88
# words) and 1.5-2.5 wrong commands (docs/foundation.md, "Tests that cannot flake")
WRONG_PUBLISHED_BOUND = {("en-us+f3", None): 0.6, ("en-us+f3", 10): 0.8, ("en-us", None): 0.6, ("en-us", 10): 0.75}


def meaning(text: str) -> tuple:
    u = parse(text)
    return u.intent, u.answer, u.obj, u.place, u.deictic_place, u.dest_obj


@pytest.fixture(scope="module")
def recogniser():
    return PocketsphinxRecognizer()


def run_stream(recogniser, wav_path: Path, t0: float = 1_700_000_000.0):
    counted: list[str] = []
    stream = MicStream("mic0", "speech/test", recogniser, make_segmenter, lambda name, detail: counted.append(name))
    wav = read_wav(wav_path)
    heard = []
    for off in range(0, len(wav.samples), 320):
        heard += stream.feed(wav.samples[off : off + 320], wav.rate, t0 + off / wav.rate)
    heard += stream.flush()
    return [h.transcript for h in heard], counted, wav.seconds


def test_wer_is_within_the_measured_bound_per_voice_and_noise(recogniser, tmp_path):
    assert len(COMMANDS) >= 20
    results, wrong = {}, {}
    for voice in VOICES:
        for snr in (None, 10):
            files = [
                synthesize(text, tmp_path / f"{voice}-{snr}-{i}.wav", voice=voice, noise_snr_db=snr, noise_seed=i)
                for i, text in enumerate(COMMANDS)
            ]
            stream = concatenate(files, tmp_path / f"{voice}-{snr}.wav", gap=GAP)
            t0 = 1_700_000_000.0
            transcripts, _, seconds = run_stream(recogniser, stream, t0)
            ref = " ".join(COMMANDS).split()
            hyp = " ".join(t.text for t in transcripts).split()
            results[(voice, snr)] = word_errors(ref, hyp) / len(ref)
            # which command each transcript was: the file whose span in the stream holds its middle
            spans, at = [], t0
            for path in files:
                length = read_wav(path).seconds
                spans.append((at, at + length))
                at += length + GAP
            said = [
                next(i for i, (a, b) in enumerate(spans) if a - 0.4 <= (t.start + t.end) / 2 <= b + 0.4)
                for t in transcripts
            ]
            wrong[(voice, snr)] = (
                sum(meaning(t.text) != meaning(COMMANDS[i]) for t, i in zip(transcripts, said)),
                len(transcripts),
            )
            starts = [t.start for t in transcripts]
            assert starts == sorted(starts)
            for t in transcripts:
                assert t0 <= t.start < t.end <= t0 + seconds
                assert t.text == t.text.lower() and t.words and t.backend == "pocketsphinx"
    print("WER per (voice, SNR dB):", {k: round(v, 3) for k, v in results.items()})
    print("wrong of published per (voice, SNR dB):", {k: f"{w}/{n}" for k, (w, n) in wrong.items()})
    for cond, wer in results.items():
        assert wer <= WER_BOUND[cond], f"WER {wer:.3f} for {cond} is above the measured bound {WER_BOUND[cond]}"
        w, n = wrong[cond]
        assert n >= len(COMMANDS) // 2, f"only {n} of {len(COMMANDS)} commands published for {cond}"
        assert w <= WRONG_PUBLISHED_BOUND[cond] * n, f"{w} of {n} published commands were wrong for {cond}"


def test_non_command_speech_is_mostly_not_published(recogniser, tmp_path):
    files = [synthesize(text, tmp_path / f"non-{i}.wav", voice="en-us+f3") for i, text in enumerate(NON_COMMANDS)]
    transcripts, counted, _ = run_stream(recogniser, concatenate(files, tmp_path / "non.wav", gap=GAP))
    rejected = counted.count("not_a_command") + counted.count("low_confidence")
    print(
        f"non-commands: {len(transcripts)} published, {rejected} rejected of {len(NON_COMMANDS)}:",
        [t.text for t in transcripts],
    )
    assert rejected >= 5 and len(transcripts) <= 1  # measured: 5 of 6 rejected (docs/speech.md)


def test_an_utterance_decodes_the_same_whatever_was_decoded_before(recogniser, tmp_path):
    # each utterance gets its own cepstral mean and fresh noise tracking, and its own seeded dither
    first, other = (
        read_wav(synthesize(t, tmp_path / f"{i}.wav", voice="en-us")).samples
        for i, t in enumerate(["put the ball on the shelf", "the weather is really nice today"])
    )
    before = recogniser.recognise(first)
    recogniser.recognise(other)
    recogniser.recognise(other[::-1].copy())
    after = recogniser.recognise(first)
    assert before is not None and after is not None
    assert (after.text, after.confidence, [(w.start, w.end) for w in after.words]) == (
        before.text,
        before.confidence,
        [(w.start, w.end) for w in before.words],
    )


def test_a_stream_of_utterances_splits_into_one_transcript_each(recogniser, tmp_path):
    texts = ["bring me the yellow book", "stop", "pick up the red cup", "follow me", "put it there"]
    files = [synthesize(t, tmp_path / f"u{i}.wav", voice="en-us+f3", speed=140) for i, t in enumerate(texts)]
    transcripts, counted, seconds = run_stream(recogniser, concatenate(files, tmp_path / "stream.wav", gap=1.0))
    assert counted.count("utterances") == len(texts)  # the VAD found exactly five utterances
    assert len(transcripts) + counted.count("not_a_command") + counted.count("low_confidence") == len(texts)
    ends = [t.end for t in transcripts]
    assert all(a.end < b.start for a, b in zip(transcripts, transcripts[1:])) and ends == sorted(ends)


def test_silence_only_gives_no_transcript(recogniser, tmp_path):
    silent = tmp_path / "silence.wav"
    concatenate([], silent, gap=3.0)
    transcripts, counted, _ = run_stream(recogniser, silent)
    assert transcripts == [] and "utterances" not in counted


def test_a_closed_command_list_recognises_every_sentence_of_it(tmp_path):
    """--commands: the demo's command list (data/demo/commands.txt), every sentence spoken in both voices.
    Measured here: 29/29 in each voice (against 50-60 % WER with the open grammar)."""
    commands_file = Path(__file__).resolve().parent.parent / "data" / "demo" / "commands.txt"
    rec = PocketsphinxRecognizer(commands=commands_file.read_text().splitlines())
    assert len(rec.commands) >= 25 and "pick up that one" in rec.commands
    wrong = []
    for voice in VOICES:
        for i, text in enumerate(rec.commands):
            heard, _, _ = run_stream(rec, synthesize(text, tmp_path / f"{voice}-{i}.wav", voice=voice))
            if [t.text for t in heard] != [text]:
                wrong.append((voice, text, [t.text for t in heard]))
    assert len(wrong) <= 2, wrong  # at most one slip per voice


def test_a_command_list_refuses_sentences_outside_the_language():
    logged = []
    rec = PocketsphinxRecognizer(
        commands=["pick up the red one", "launch the rockets", "# a comment", ""], log=logged.append
    )
    assert rec.commands == ["pick up the red one"]
    assert any("launch the rockets" in line for line in logged)
    assert rec.matches("pick up the red one") and not rec.matches("pick up the blue one")
