"""Process shell of the voice service: fusion's questions and refusals (and, with --confirm, its commands) spoken
by piper; the audio goes out as AudioChunks on <prefix>/voice/<speaker>/pcm (always: a speaker elsewhere plays
them, and the speech service cancels them as the robot's own echo), and to a WAV folder and a sound device when
asked. Each utterance is announced first as a Spoken sample on <prefix>/voice/<speaker>/spoken."""

from __future__ import annotations

import argparse
import queue
import threading
import time
import wave
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from common.runner import App, Delivery, Service, StartupError, serve, service_parser
from common.schema import Clarification, FusedCommand, Spoken
from common.settings import add_option
from services.speech.audio import RATE
from services.voice.core import SEND_AHEAD_SECONDS, Say, Schedule, audio_chunks, to_pcm16, utterance_for
from services.voice.synth import PiperVoice, VoiceError

EPILOG = """\
examples:
  hri-voice                                   # questions and refusals as AudioChunks on hri/voice/robot/pcm
  hri-voice --device default                  # ... and on the machine's sound device (sounddevice + PortAudio)
  hri-voice --wav-dir var/voice --confirm     # ... and one WAV per utterance; commands confirmed aloud too
"""


def build_parser() -> argparse.ArgumentParser:
    parser = service_parser("voice", "Speak fusion's questions and refusals (piper, offline).", EPILOG)
    add_option(
        parser, "--speaker", "robot", "the voice's id in its keys (voice/<ID>/pcm, voice/<ID>/spoken)", metavar="ID"
    )
    add_option(parser, "--confirm", False, 'also say each command before the robot acts on it ("Picking up …")')
    add_option(
        parser,
        "--wav-dir",
        None,
        "also write each utterance to DIR/NNN-<kind>.wav (16 kHz mono)",
        kind=str,
        metavar="DIR",
        default_text="no files",
    )
    add_option(
        parser,
        "--device",
        None,
        "also play on this sounddevice output device (index or name; 'default' for the system's)",
        kind=str,
        default_text="no device",
    )
    add_option(parser, "--length-scale", 1.0, "piper's speaking pace (> 1 slower)", above=0, metavar="F")
    return parser


@dataclass
class Utterance:
    say: Say
    audio: np.ndarray  # float32, 16 kHz


class Device:
    """A sound device through sounddevice (the `mic` extra, PortAudio): a clear StartupError when there is none."""

    def __init__(self, name: str):
        try:
            import sounddevice as sd
        except (ImportError, OSError) as exc:
            raise StartupError(
                f"cannot use a sound device: {exc}. Install PortAudio (`sudo apt-get install libportaudio2`) and "
                "`pip install 'hri-fusion[mic]'`, or leave out --device (the audio is on the wire and --wav-dir)"
            ) from None
        self.sd = sd
        self.device: Any = None if name == "default" else int(name) if name.isdigit() else name
        try:
            sd.check_output_settings(device=self.device, samplerate=RATE, channels=1, dtype="int16")
        except Exception as exc:
            raise StartupError(
                f"no usable output device {name!r}: {exc}. List them with `python -m sounddevice`"
            ) from None

    def play(self, pcm: np.ndarray) -> None:
        self.sd.play(pcm, RATE, device=self.device)

    def stop(self) -> None:
        self.sd.stop()


class VoiceApp(App):
    node = "voice"

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self.queue: queue.Queue[Utterance] = queue.Queue()
        self.schedule = Schedule()
        self.interrupt = threading.Event()
        self.said = 0
        self.device: Device | None = None

    def open(self, service: Service) -> None:
        self.service = service
        if self.args.device is not None:  # before the voice loads: a missing device fails at once
            self.device = Device(self.args.device)
        started = time.monotonic()
        try:
            self.voice = PiperVoice(self.args.length_scale)
            self.voice.speak("Ready.")  # the first synthesis allocates; not on a person's time
        except VoiceError as exc:
            raise StartupError(str(exc)) from None
        if self.args.wav_dir:
            Path(self.args.wav_dir).mkdir(parents=True, exist_ok=True)
        service.log.info("voice %s ready in %.1f s", self.voice.name, time.monotonic() - started)

    def wire(self, service: Service) -> None:
        service.subscribe_input("clarification", self.on_sample)
        service.subscribe_input("command", self.on_sample)
        player = threading.Thread(target=self.play_all, name="voice-player", daemon=True)
        player.start()

    def on_sample(self, delivery: Delivery) -> None:
        sample = delivery.sample
        assert isinstance(sample, (Clarification, FusedCommand))
        if isinstance(sample, FusedCommand) and sample.intent == "stop":
            self.interrupt.set()  # the person said stop: the robot stops talking too
        say = utterance_for(sample, self.args.confirm)
        if say is None:
            return
        started = time.monotonic()
        audio = self.voice.speak(say.text)
        self.service.counters.add("synthesised")
        self.service.log.info("synthesised %s %r in %.2f s", say.kind, say.text, time.monotonic() - started)
        self.queue.put(Utterance(say, audio))

    def play_all(self) -> None:
        stop = self.service.stop_event
        while not stop.is_set():
            try:
                utterance = self.queue.get(timeout=0.2)
            except queue.Empty:
                continue
            self.interrupt.clear()
            self.play(utterance)

    def spoken(self, u: Utterance, start: float, end: float) -> Spoken:
        return Spoken(
            stamp=start,
            source=self.service.source,
            id=f"{u.say.kind}-{u.say.answers or self.said}",
            text=u.say.text,
            kind=u.say.kind,
            answers=u.say.answers,
            start=start,
            end=end,
            speaker=self.args.speaker,
            voice=self.voice.name,
        )

    def play(self, u: Utterance) -> None:
        """Announce, then send the audio chunk by chunk at its play time; a stop command cuts it short."""
        service, speaker = self.service, self.args.speaker
        pcm = to_pcm16(u.audio)
        start, end = self.schedule.place(time.time(), len(pcm) / RATE)
        self.said += 1
        announced = self.spoken(u, start, end)
        service.publish_output("spoken", announced, speaker=speaker)
        service.log.info("saying %s %r (%.2f-%.2f)", u.say.kind, u.say.text, start, end)
        if self.args.wav_dir:
            write_wav(Path(self.args.wav_dir) / f"{self.said:03d}-{u.say.kind}.wav", pcm)
        playing = self.device is None  # a local device starts at the announced start, the wire runs ahead of it
        for chunk in audio_chunks(pcm, RATE, start, speaker, service.source):
            delay = chunk.stamp - SEND_AHEAD_SECONDS - time.time()
            if not self.wait(delay):
                self.cut(announced, time.time())
                return
            playing = playing or self.start_device(pcm, start)
            service.publish_output("voice_audio", chunk, speaker=speaker)
        if not playing and self.device is not None:  # every chunk sent before the start: the device starts on time
            if not self.wait(start - time.time()):
                self.cut(announced, time.time())
                return
            self.device.play(pcm)
        service.counters.add("spoken")

    def wait(self, delay: float) -> bool:
        """Wait `delay` s; False when interrupted (a stop) or the service stops."""
        if delay > 0 and self.interrupt.wait(delay):
            return False
        return not (self.interrupt.is_set() or self.service.stop_event.is_set())

    def start_device(self, pcm: np.ndarray, start: float) -> bool:
        """Start the local device once the utterance's start has come (True: it plays)."""
        if self.device is None or time.time() < start:
            return False
        self.device.play(pcm)
        return True

    def cut(self, announced: Spoken, at: float) -> None:
        """Stopped before the end: the same Spoken again with the end it had, so speech unmasks at once."""
        if self.device is not None:
            self.device.stop()
        at = max(announced.start, min(at, announced.end))
        self.schedule.cut(at)
        self.service.publish_output(
            "spoken", msgspec.structs.replace(announced, stamp=at, end=at), speaker=self.args.speaker
        )
        self.service.counters.add("interrupted")
        self.service.log.info("stopped saying %r at %.2f", announced.text, at)


def write_wav(path: Path, pcm: np.ndarray) -> None:
    with wave.open(str(path), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(RATE)
        w.writeframes(pcm.astype("<i2").tobytes())


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    serve(VoiceApp(args), args)


if __name__ == "__main__":
    main()
