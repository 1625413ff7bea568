"""The robot's own voice on its microphone: where it is, and what is left of the microphone once it is taken out.

Pure numpy, no Zenoh. The voice service announces each utterance (a `Spoken` sample: when it plays) and sends
the audio it plays (AudioChunks on voice/<speaker>/pcm, the echo *reference*). `OwnVoice` keeps both: the masked
intervals (the announced span plus `tail` seconds for the room's echo and the output's latency) and the reference
samples by source time. `EchoCanceller` removes the reference from a stretch of microphone audio: the echo path
(speaker -> room -> microphone) is fitted as an FIR filter by least squares (conjugate gradient on the normal
equations, every product an FFT), with the frames where the person talks over the robot (double talk) left out
of the fit, and is kept from one utterance to the next (a robot's speaker and microphone do not move against
each other), so a later fit starts where the last ended. What remains is the person's voice plus a residue of
the robot's; speech decodes it and keeps only a stop (services/speech/pipeline.py, docs/voice.md).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field, replace
from typing import Iterable, Protocol, runtime_checkable

import numpy as np

from common.language import STOP_WORDS, one_word_commands
from services.speech.audio import RATE
from services.speech.grammar import normalise
from services.speech.recognizers import Recognition

ECHO_TAIL = 0.3  # seconds after the announced end that stay masked: the room's reverberation and output latency
ECHO_TAPS = 4096  # the echo path's length, 256 ms at 16 kHz: output latency plus the early reverberation
FIT_ITERATIONS = 30  # conjugate-gradient steps per fit (a warm start needs few)
FIT_PASSES = 2  # fit, find the double talk, fit again without it
FRAME = 320  # 20 ms frames for finding double talk
BARGE_IN_PRIOR = 100.0  # the head start a stop word gets over the one word heard under the robot's voice
BARGE_IN_SECONDS = 2.0  # ... in a cut of at most this much audio (a word said alone, as the short-utterance decode)
DOUBLE_TALK = 4.0  # a frame whose residual power is this many times the quiet frames' is the person talking
# How far the echo's delay may move from one utterance to the next and still be followed (a sound device's output
# latency differs per start; one sample, 62 us, already leaves most of the echo above 1.5 kHz uncancelled)
MAX_DELAY_CHANGE = 0.02  # seconds
DELAY_MATCH = 0.5  # the predicted echo must match the microphone this well (correlation) for its delay to count


def _fft_size(n: int) -> int:
    return 1 << int(np.ceil(np.log2(max(n, 2))))


@dataclass
class EchoCanceller:
    taps: int = ECHO_TAPS
    iterations: int = FIT_ITERATIONS
    passes: int = FIT_PASSES
    path: np.ndarray | None = None  # the fitted echo path, kept across utterances

    def apply(self, mic: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """`mic` less the echo of `reference` through the path fitted so far, moved to the echo's delay in `mic`
        (no fit: `mic` as it is)."""
        if self.path is None or len(mic) == 0:
            return mic.astype(np.float32, copy=True)
        self.follow_delay(mic, reference)
        size = _fft_size(len(mic) + self.taps)
        echo = np.fft.irfft(np.fft.rfft(reference.astype(np.float64), size) * np.fft.rfft(self.path, size), size)
        return (mic - echo[: len(mic)]).astype(np.float32)

    def follow_delay(self, mic: np.ndarray, reference: np.ndarray) -> float:
        """Move the kept path by how much later (or earlier) the echo arrives in `mic` than the path predicts, to
        a fraction of a sample (the peak of their cross-correlation, parabolic); the move in samples, 0 when the
        prediction does not match `mic` well enough to tell (no echo, or mostly another voice)."""
        if self.path is None or len(mic) < FRAME or not np.any(reference):
            return 0.0
        y = mic.astype(np.float64)
        n, max_lag = len(y), int(MAX_DELAY_CHANGE * RATE)
        size = _fft_size(n + self.taps + max_lag)
        mic_spectrum = np.fft.rfft(y, size)
        ref_spectrum = np.fft.rfft(reference.astype(np.float64), size)
        mic_energy = float(y @ y)
        moved = 0.0
        for _ in range(2):  # a second look from the moved path takes out most of the parabola's bias
            predicted = ref_spectrum * np.fft.rfft(self.path, size)
            echo = np.fft.irfft(predicted, size)
            xc = np.fft.irfft(mic_spectrum * np.conj(predicted), size)
            lags = np.concatenate([xc[-max_lag:], xc[: max_lag + 1]])  # lag -max_lag .. +max_lag
            i = int(np.argmax(lags))
            match = lags[i] / (np.sqrt(mic_energy * float(echo @ echo)) + 1e-30)
            if not 0 < i < len(lags) - 1 or match < DELAY_MATCH:
                return moved
            y0, y1, y2 = lags[i - 1], lags[i], lags[i + 1]
            curve = y0 - 2 * y1 + y2
            step = i - max_lag + (0.5 * (y0 - y2) / curve if curve < 0 else 0.0)
            if abs(step) < 0.02:
                break
            self.path = delayed(self.path, step)
            moved += step
        return moved

    def cancel(self, mic: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """`mic` with the echo of `reference` (the same length, the same start time) taken out."""
        n = len(mic)
        if n == 0 or not np.any(reference):
            return mic.astype(np.float32, copy=True)
        y = mic.astype(np.float64)
        size = _fft_size(n + self.taps)
        ref_spectrum = np.fft.rfft(reference.astype(np.float64), size)

        def convolve(h: np.ndarray) -> np.ndarray:
            return np.fft.irfft(ref_spectrum * np.fft.rfft(h, size), size)[:n]

        def correlate(r: np.ndarray) -> np.ndarray:
            return np.fft.irfft(np.conj(ref_spectrum) * np.fft.rfft(r, size), size)[: self.taps]

        self.follow_delay(mic, reference)  # the fit starts from the kept path at this utterance's delay
        h = self.path if self.path is not None else np.zeros(self.taps)
        weights = np.ones(n)
        for _ in range(self.passes):
            h = self._fit(y, h, weights, convolve, correlate)
            weights = talk_free(y - convolve(h), convolve(h))
        self.path = h
        return (y - convolve(h)).astype(np.float32)

    def _fit(self, y: np.ndarray, h: np.ndarray, w: np.ndarray, convolve, correlate) -> np.ndarray:  # noqa: ANN001
        """Weighted least squares from `h` on: min |w (y - reference * h)|², conjugate gradient."""
        h = h.copy()
        r = correlate(w * (y - convolve(h)))
        p = r.copy()
        rs = float(r @ r)
        first = rs
        for _ in range(self.iterations):
            ap = correlate(w * convolve(p))
            alpha = rs / (float(p @ ap) + 1e-30)
            h += alpha * p
            r -= alpha * ap
            rs_new = float(r @ r)
            if rs_new < 1e-10 * first:
                break
            p = r + (rs_new / rs) * p
            rs = rs_new
        return h


def delayed(path: np.ndarray, samples: float) -> np.ndarray:
    """`path` delayed by `samples` (a fraction of a sample too; negative: earlier), the same length."""
    n = len(path)
    size = _fft_size(2 * n)
    turn = np.exp(-2j * np.pi * np.fft.rfftfreq(size) * samples)
    return np.fft.irfft(np.fft.rfft(path, size) * turn, size)[:n]


def talk_free(residual: np.ndarray, echo: np.ndarray) -> np.ndarray:
    """1 for each sample of a frame fit to learn the echo path from, 0 where the residual is far above the quiet
    frames' (the person talking over the robot: left out, or it would bend the path towards their voice)."""
    n = len(residual)
    m = n // FRAME
    if m < 4:
        return np.ones(n)
    power = np.mean(residual[: m * FRAME].reshape(m, FRAME) ** 2, axis=1)
    echo_power = np.mean(echo[: m * FRAME].reshape(m, FRAME) ** 2, axis=1)
    active = echo_power > 1e-3 * (echo_power.max() + 1e-20)
    quiet = np.percentile(power[active] if active.sum() >= 4 else power, 25)
    keep = np.repeat(power <= DOUBLE_TALK * quiet + 1e-12, FRAME).astype(np.float64)
    return np.pad(keep, (0, n - len(keep)), constant_values=1.0)


@dataclass
class Interval:
    id: str
    text: str
    start: float
    end: float  # the announced end, without the tail


@dataclass
class OwnVoice:
    """What the robot said and played, by source time (for one stack: every speaker of it)."""

    tail: float = ECHO_TAIL
    prior: float = BARGE_IN_PRIOR  # barge_in's head start for a stop word
    keep_seconds: float = 120.0  # reference audio older than this is dropped
    intervals: dict[str, Interval] = field(default_factory=dict)
    _ref_starts: list[float] = field(default_factory=list)
    _ref_chunks: list[np.ndarray] = field(default_factory=list)

    def announce(self, id: str, text: str, start: float, end: float) -> None:
        """A Spoken sample; the same id again (an utterance cut short) replaces its interval."""
        self.intervals[id] = Interval(id, text, start, end)
        horizon = end - self.keep_seconds
        for old in [k for k, i in self.intervals.items() if i.end < horizon]:
            del self.intervals[old]

    def add_reference(self, stamp: float, samples16k: np.ndarray) -> None:
        at = bisect.bisect(self._ref_starts, stamp)
        self._ref_starts.insert(at, stamp)
        self._ref_chunks.insert(at, samples16k.astype(np.float32, copy=False))
        while self._ref_starts and self._ref_starts[0] < stamp - self.keep_seconds:
            self._ref_starts.pop(0)
            self._ref_chunks.pop(0)

    def masked_until(self, t: float) -> float | None:
        """If `t` falls in a masked span (an utterance plus the tail), where that span ends; else None."""
        ends = [i.end + self.tail for i in self.intervals.values() if i.start <= t < i.end + self.tail]
        return max(ends) if ends else None

    def next_start(self, t: float) -> float | None:
        """The start of the first masked span after `t`, if any."""
        starts = [i.start for i in self.intervals.values() if i.start > t]
        return min(starts) if starts else None

    def texts(self, start: float, end: float) -> list[str]:
        return [i.text for i in self.intervals.values() if i.start < end and start < i.end + self.tail]

    def reference(self, start: float, n: int) -> np.ndarray:
        """The reference (what the robot played) over [start, start + n / RATE), zeros where nothing played."""
        out = np.zeros(n, np.float32)
        for stamp, chunk in zip(self._ref_starts, self._ref_chunks):
            offset = int(round((stamp - start) * RATE))
            if offset >= n or offset + len(chunk) <= 0:
                continue
            lo, hi = max(0, offset), min(n, offset + len(chunk))
            out[lo:hi] = chunk[lo - offset : hi - offset]
        return out


@runtime_checkable
class FirstWordScorer(Protocol):
    def first_word_probabilities(self, audio: np.ndarray, words: Iterable[str], copies: int = 1) -> dict[str, float]:
        """The model's probability that the transcript of `audio` starts with each word."""
        ...


def barge_in(
    result: Recognition | None,
    audio: np.ndarray,
    recogniser: object,
    own_texts: Iterable[str] = (),
    prior: float = BARGE_IN_PRIOR,
) -> Recognition | None:
    """What a cut of the echo-cancelled audio under the robot's voice may say: a stop, or nothing.

    A stop word in the decode counts unless the robot said that word itself (its residue). A cut of about a second
    heard as one word that is no command word ("store", "stuff": a stop under the robot's residue) is scored
    against the stop words with the model's own probabilities (the short-utterance decode, docs/speech.md) and
    becomes the likeliest stop word when its probability times `prior` is at least the heard word's. Under the
    robot's voice nothing but a stop is published, so the head start is larger than the free decode's (20)."""
    if result is None or not result.words:
        return None
    said = {w for text in own_texts for w in normalise(text).split()}
    stops = [w for w in result.words if w.word in STOP_WORDS and w.word not in said]
    if stops:
        w = stops[0]
        return Recognition(w.word, w.confidence, [w], detail=f"{w.word!r} in {result.text!r}")
    heard = result.words[0]
    scorer = recogniser if isinstance(recogniser, FirstWordScorer) else None
    if len(result.words) != 1 or heard.word in one_word_commands() or scorer is None:
        return None
    if len(audio) > BARGE_IN_SECONDS * RATE:
        return None
    candidates = [w for w in STOP_WORDS if w not in said]
    p = scorer.first_word_probabilities(audio, [*candidates, heard.word], 5)
    heard_p = p.pop(heard.word, 0.0)
    best = max(p, key=lambda w: p[w], default=None)
    if best is None or p[best] * prior < heard_p:
        return None
    detail = f"{heard.word!r} p {heard_p:.3f} -> {best!r} p {p[best]:.3f} (prior {prior:g})"
    return Recognition(best, p[best], [replace(heard, word=best, confidence=p[best])], detail=detail)
