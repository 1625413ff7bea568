"""Audio in: WAV files, s16le PCM to float, and streaming resampling to 16 kHz mono. Pure numpy."""

from __future__ import annotations

import wave
from dataclasses import dataclass
from pathlib import Path

import numpy as np

RATE = 16000  # what VAD and recognisers take
MIN_RATE = 8000  # below this there is no speech band left to recognise


class AudioError(ValueError):
    """Audio the service cannot use. `reason` is the counter key; the message says what to do."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


def pcm_to_mono(data: bytes, channels: int) -> np.ndarray:
    """s16le interleaved bytes -> float32 mono in [-1, 1] (channels averaged)."""
    if len(data) % (2 * channels):
        raise AudioError("bad_format", f"{len(data)} bytes is not a whole number of {channels}-channel s16le frames")
    pcm = np.frombuffer(data, dtype="<i2").astype(np.float32) / 32768.0
    if channels > 1:
        pcm = pcm.reshape(-1, channels).mean(axis=1)
    return pcm


def check_rate(rate: int) -> None:
    if rate < MIN_RATE:
        raise AudioError(
            "unsupported_rate",
            f"sample rate {rate} Hz is below {MIN_RATE} Hz; speech needs at least 8 kHz (16 kHz or more recommended)",
        )


class Resampler:
    """Streaming band-limited resampler (windowed sinc), exact in time: output sample k is the input
    signal at time k / out_rate, so sample counts stay a clock."""

    HALF_TAPS = 16  # kernel half-width in input samples at the narrower band; quality vs speed

    def __init__(self, in_rate: int, out_rate: int = RATE):
        self.in_rate, self.out_rate = in_rate, out_rate
        self.step = in_rate / out_rate  # input samples per output sample
        self.cutoff = min(1.0, out_rate / in_rate)  # low-pass below the lower Nyquist
        self.half = int(np.ceil(self.HALF_TAPS / self.cutoff))
        self._buf = np.zeros(0, dtype=np.float64)  # unread input, starting at input index _buf_start
        self._buf_start = 0
        self._produced = 0  # output samples so far

    @property
    def passthrough(self) -> bool:
        return self.in_rate == self.out_rate

    def process(self, samples: np.ndarray, final: bool = False) -> np.ndarray:
        if self.passthrough:
            return samples.astype(np.float32, copy=False)
        self._buf = np.concatenate([self._buf, samples.astype(np.float64)])
        available_end = self._buf_start + len(self._buf)  # one past the last input index we hold
        if final:
            # the input has ended: let the kernel run over zeros after it
            self._buf = np.concatenate([self._buf, np.zeros(self.half + 1)])
            last_t = available_end - 1
        else:
            last_t = available_end - 1 - self.half
        n_out = int(np.floor(last_t / self.step)) - self._produced + 1 if last_t >= 0 else 0
        if n_out <= 0:
            return np.zeros(0, dtype=np.float32)
        t = (self._produced + np.arange(n_out)) * self.step  # input-time of each output sample
        base = np.floor(t).astype(np.int64)
        offsets = np.arange(-self.half + 1, self.half + 1)
        idx = base[:, None] + offsets[None, :]
        dist = t[:, None] - idx
        kernel = self.cutoff * np.sinc(self.cutoff * dist) * (0.5 + 0.5 * np.cos(np.pi * dist / (self.half + 1)))
        local = idx - self._buf_start
        valid = (local >= 0) & (local < len(self._buf))
        values = np.where(valid, self._buf[np.clip(local, 0, len(self._buf) - 1)], 0.0)
        out = (values * kernel).sum(axis=1)
        self._produced += n_out
        # keep only what the next outputs can still reach
        keep_from = int(np.floor(self._produced * self.step)) - self.half
        drop = max(0, keep_from - self._buf_start)
        if drop:
            self._buf = self._buf[drop:]
            self._buf_start += drop
        return out.astype(np.float32)


@dataclass
class WavAudio:
    path: Path
    rate: int
    channels: int
    samples: np.ndarray  # float32 mono at `rate`

    @property
    def seconds(self) -> float:
        return len(self.samples) / self.rate


def read_wav(path: str | Path) -> WavAudio:
    """A PCM WAV file as float32 mono. Raises AudioError with what is wrong and what to do."""
    path = Path(path)
    try:
        with wave.open(str(path), "rb") as w:
            rate, channels, width, n = w.getframerate(), w.getnchannels(), w.getsampwidth(), w.getnframes()
            data = w.readframes(n)
    except FileNotFoundError:
        raise AudioError("missing_file", f"{path}: no such file") from None
    except (wave.Error, EOFError) as exc:
        raise AudioError(
            "unreadable_wav",
            f"{path}: not a PCM WAV file we can read ({exc}); convert it with `sox IN -r 16000 -c 1 -b 16 OUT.wav`",
        ) from None
    if width != 2:
        raise AudioError(
            "bad_format", f"{path}: {8 * width}-bit samples; only 16-bit PCM is supported (`sox IN -b 16 OUT.wav`)"
        )
    frame_bytes = 2 * channels
    if len(data) < n * frame_bytes:
        usable = len(data) - len(data) % frame_bytes
        if usable == 0:
            raise AudioError("truncated_wav", f"{path}: header promises {n} frames but the file holds no audio")
        raise AudioError(
            "truncated_wav",
            f"{path}: truncated, {len(data) // frame_bytes} of {n} frames present; re-record or re-export the file",
        )
    check_rate(rate)
    return WavAudio(path, rate, channels, pcm_to_mono(data, channels))


def wav_files(paths: list[str]) -> list[Path]:
    """Files as given, folders expanded to their .wav files in name order."""
    found: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found += sorted(f for f in p.iterdir() if f.suffix.lower() == ".wav" and f.is_file())
        else:
            found.append(p)
    return found
