"""A room around the robot, for the own-voice tests and benchmark: what the robot's microphone hears when its own
speaker plays (its voice through the room: a direct path after a small latency, then reverberation) while a person
talks at a chosen level against it, with a little background noise.

`room_response` is a synthetic impulse response (direct path + exponentially decaying noise, RT60 0.35 s, a living
room's), `echo_of` plays audio through it, `at_level` scales a person's clip to a signal-to-echo ratio measured over
the speech (testkit.synth.speech_power). `LiveRoom` does the same live over Zenoh: it subscribes to the voice's
AudioChunks, plays them through the room into a microphone timeline, adds the person's clips where the test puts
them, and publishes the timeline as the microphone's AudioChunks in real time.
"""

from __future__ import annotations

import threading
import time

import numpy as np

from common.schema import AudioChunk
from services.speech.echo import delayed
from testkit.synth import RATE, pink_noise, speech_power

ROOM_SEED = 1
RT60 = 0.35  # seconds: a furnished living room
OUTPUT_LATENCY = 0.012  # seconds from the announced play time to the direct sound at the microphone
NOISE_LEVEL = 0.003  # background pink noise, ~ -50 dBFS (before the microphone's gain)
# The microphone's gain, set as an installer would so that the robot's own voice does not clip: piper speaks up to
# full scale and this room's reverberation carries ~6x the direct sound's energy, so at gain 1 the echo peaked at
# 2.6x full scale and ~1 % of a question's samples clipped on a 16-bit microphone, which no linear echo canceller
# takes out (the live test's stop heard as "start with", 29 Nov). Everything the microphone hears is scaled alike.
MIC_GAIN = 0.25


def room_response(rt60: float = RT60, latency: float = OUTPUT_LATENCY, seed: int = ROOM_SEED) -> np.ndarray:
    """Speaker -> microphone: the direct path (gain 1) after `latency`, then a diffuse tail decaying 60 dB in
    `rt60` seconds (0.4 s long)."""
    rng = np.random.default_rng(seed)
    n = int(0.4 * RATE)
    t = np.arange(n) / RATE
    ir = rng.standard_normal(n) * np.exp(-6.9 * t / rt60) * 0.15
    direct = int(latency * RATE)
    ir[:direct] = 0.0
    ir[direct] = 1.0
    return ir


def echo_of(audio: np.ndarray, ir: np.ndarray) -> np.ndarray:
    """`audio` as the microphone hears it through the room (its length plus the response's)."""
    return np.convolve(audio.astype(np.float64), ir)


def at_level(clip: np.ndarray, echo: np.ndarray, ratio_db: float) -> np.ndarray:
    """`clip` scaled so that its speech power is `ratio_db` dB against the echo's (0: as loud, -6: half as loud)."""
    gain = np.sqrt(speech_power(echo) / max(speech_power(clip), 1e-12) * 10 ** (ratio_db / 10))
    return clip.astype(np.float64) * gain


class LiveRoom:
    """The microphone of a robot whose voice is live on Zenoh (see the module docstring). `put(t, clip)` adds a
    person's audio at source time t; `start()` publishes the microphone from now on, `stop()` ends it."""

    CHUNK = 320  # 20 ms
    HOLD = 0.08  # a chunk is published this long after its time: the robot's echo for it has arrived by then

    def __init__(  # noqa: ANN001
        self,
        client,
        mic: str = "mic0",
        seconds: float = 120.0,
        ir: np.ndarray | None = None,
        output_delays: tuple[float, ...] = (0.0,),
    ):
        """`output_delays`: how much later than `ir` says each utterance's echo arrives, in turn (a real sound
        device's output latency differs at each start)."""
        self.client, self.mic = client, mic
        self.ir = room_response() if ir is None else ir
        self.output_delays = output_delays
        self.utterances = 0
        self._voice_until = -1.0  # the end of the last voice chunk heard (a gap after it: a new utterance)
        self.t0 = time.time() + 0.5
        n = int(seconds * RATE)
        self.timeline = NOISE_LEVEL * pink_noise(seconds, seed=3)[:n]
        self.lock = threading.Lock()
        self.late_echo = 0
        self.clipped = 0  # samples published at full scale
        self.published_until = 0  # samples
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        client.session.declare_subscriber("hri/voice/*/pcm", self._on_voice)

    def index(self, t: float) -> int:
        return int(round((t - self.t0) * RATE))

    def put(self, t: float, audio: np.ndarray) -> None:
        at = self.index(t)
        with self.lock:
            end = min(len(self.timeline), at + len(audio))
            self.timeline[at:end] += audio[: end - at]

    def _on_voice(self, s) -> None:  # noqa: ANN001
        from common.codec import decode

        chunk = decode(s.payload.to_bytes(), AudioChunk)
        pcm = np.frombuffer(chunk.data, "<i2").astype(np.float64) / 32768.0
        if chunk.stamp > self._voice_until + 0.01:
            self.utterances += 1
        self._voice_until = chunk.stamp + len(pcm) / RATE
        stamp = chunk.stamp + self.output_delays[(self.utterances - 1) % len(self.output_delays)]
        if self.index(stamp) < self.published_until:
            self.late_echo += 1
        self.put(stamp, echo_of(pcm, self.ir))

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _run(self) -> None:
        i = max(0, self.index(time.time()))
        while not self._stop.is_set() and i + self.CHUNK <= len(self.timeline):
            stamp = self.t0 + i / RATE
            delay = stamp + self.CHUNK / RATE + self.HOLD - time.time()
            if delay > 0:
                self._stop.wait(delay)
            with self.lock:
                level = np.round(self.timeline[i : i + self.CHUNK] * MIC_GAIN * 32767)
                self.clipped += int(np.count_nonzero(np.abs(level) > 32767))
                data = np.clip(level, -32768, 32767).astype("<i2")
                self.published_until = i + self.CHUNK
            chunk = AudioChunk(
                stamp=stamp,
                source="test/room",
                mic=self.mic,
                rate=RATE,
                channels=1,
                format="s16le",
                data=data.tobytes(),
            )
            self.client.publish(f"hri/audio/{self.mic}/pcm", chunk)
            i += self.CHUNK


LEAD = 0.5  # seconds of room before the robot starts speaking


def scene(
    question: np.ndarray,
    clip: np.ndarray | None,
    at: float,
    ratio_db: float,
    ir: np.ndarray,
    delay: float = 0.0,
    gain: float = MIC_GAIN,
) -> np.ndarray:
    """The microphone over one question of the robot's: LEAD s of room, the question through the room, the
    person's `clip` (if any) starting `at` s into the question at `ratio_db` against the echo, 1.5 s after.
    `delay`: the echo arrives this much later than `ir` says (a sound device's output latency differs per start);
    `gain`: the microphone's."""
    echo = delayed(echo_of(question, ir), delay * RATE) if delay else echo_of(question, ir)
    n = int((LEAD + len(question) / RATE + 1.5) * RATE)
    mic = NOISE_LEVEL * pink_noise(n / RATE, seed=5)[:n]
    lead = int(LEAD * RATE)
    mic[lead : lead + len(echo)] += echo[: n - lead]
    if clip is not None:
        person = at_level(clip, echo, ratio_db)
        i = lead + int(at * RATE)
        mic[i : i + len(person)] += person[: max(0, n - i)]
    return gain * mic


def hear(stream, own_voice, mic: np.ndarray, question: np.ndarray, t0: float, text: str, n: int) -> list:  # noqa: ANN001
    """Feed `mic` (starting at source time t0, the question at t0 + LEAD) to a speech MicStream whose OwnVoice
    knows the question as utterance `n`; the Transcripts it publishes."""
    start = t0 + LEAD
    own_voice.announce(f"q{n}", text, start, start + len(question) / RATE)
    step = 320
    for i in range(0, len(question), step):
        own_voice.add_reference(start + i / RATE, question[i : i + step].astype(np.float32))
    heard = []
    for i in range(0, len(mic), step):
        heard += stream.feed(mic[i : i + step].astype(np.float32), RATE, t0 + i / RATE)
    heard += stream.flush()
    return [h.transcript for h in heard]
