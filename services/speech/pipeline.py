"""One microphone's stream: stamped PCM -> resample -> VAD -> recogniser -> checked Transcripts.

Pure (no zenoh): the service shell feeds it and publishes what it returns. Time is the audio's own
clock: the stamp of the first sample plus sample offsets. A chunk whose stamp disagrees with that
clock by more than `resync_after` (a gap, a restart) ends the utterance in progress and restarts
the clock from the new stamp.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from common.schema import Transcript, Word
from services.speech.audio import RATE, AudioError, Resampler, check_rate
from services.speech.recognizers import Recognition
from services.speech.vad import Segmenter, Utterance


class Recogniser(Protocol):
    name: str
    min_confidence: float

    def matches(self, text: str) -> bool: ...

    def recognise(self, audio: np.ndarray) -> Recognition | None: ...


Count = Callable[[str, str], None]  # (counter name, detail for the log)


@dataclass
class Heard:
    transcript: Transcript
    decided_at: int  # stream sample index at which the VAD closed the utterance
    recognition: Recognition


class MicStream:
    def __init__(self, mic: str, source: str, recogniser: Recogniser, make_segmenter: Callable[[], Segmenter],
                 count: Count, resync_after: float = 0.25):
        self.mic, self.source = mic, source
        self.recogniser = recogniser
        self.segmenter = make_segmenter()
        self.count = count
        self.resync_after = resync_after
        self._format: tuple[int, int] | None = None
        self._resampler: Resampler | None = None
        self._t0 = 0.0  # stamp of stream sample 0
        self._in_samples = 0  # input samples since t0 (at the input rate)
        self._out_samples = 0  # 16 kHz samples since t0

    def stamp_of(self, sample_index: int) -> float:
        return self._t0 + sample_index / RATE

    @property
    def clock(self) -> float:
        """Stamp just after the last sample fed."""
        return self._t0 + (self._in_samples / self._format[0] if self._format else 0.0)

    def feed(self, samples: np.ndarray, rate: int, stamp: float) -> list[Heard]:
        """Mono float samples at `rate` whose first sample was captured at `stamp` (UNIX seconds)."""
        check_rate(rate)
        heard: list[Heard] = []
        if self._format is None:
            self._start(rate, stamp)
        elif self._format[0] != rate:
            self.count("format_changed", f"{self.mic}: sample rate changed from {self._format[0]} to {rate} Hz; "
                                         "restarting the stream")
            heard += self.flush()
            self._start(rate, stamp)
        else:
            drift = stamp - self.clock
            if abs(drift) > self.resync_after:
                self.count("clock_resync", f"{self.mic}: chunk stamp is {drift:+.3f} s off the audio clock "
                                           "(gap or restart); ending the utterance and resyncing")
                heard += self.flush()
                self._start(rate, stamp)
        assert self._resampler is not None
        self._in_samples += len(samples)
        heard += self._segment(self._resampler.process(samples))
        return heard

    def flush(self) -> list[Heard]:
        """End of stream (file end, gap): finish the utterance in progress."""
        heard: list[Heard] = []
        if self._resampler is not None:
            heard += self._segment(self._resampler.process(np.zeros(0, dtype=np.float32), final=True))
        for utt in self.segmenter.flush():
            h = self._recognise(utt)
            if h is not None:
                heard.append(h)
        self._format = None
        self._resampler = None
        return heard

    def _start(self, rate: int, stamp: float) -> None:
        self._format = (rate, 1)
        self._resampler = Resampler(rate, RATE)
        self._t0, self._in_samples, self._out_samples = stamp, 0, 0

    def _segment(self, samples16k: np.ndarray) -> list[Heard]:
        heard = []
        self._out_samples += len(samples16k)
        before = self.segmenter.too_short
        for utt in self.segmenter.feed(samples16k):
            h = self._recognise(utt)
            if h is not None:
                heard.append(h)
        if self.segmenter.too_short > before:
            self.count("too_short", f"{self.mic}: a burst shorter than the minimum utterance was ignored")
        return heard

    def _recognise(self, utt: Utterance) -> Heard | None:
        self.count("utterances", "")
        if utt.forced:
            self.count("utterance_cut", f"{self.mic}: speech longer than the maximum utterance was cut")
        result = self.recogniser.recognise(utt.audio)
        if result is None or not result.text:
            self.count("not_a_command", f"{self.mic}: nothing in the grammar matched an utterance at "
                                        f"{self.stamp_of(utt.speech_start):.2f}")
            return None
        if not self.recogniser.matches(result.text):
            self.count("not_a_command", f"{self.mic}: {result.text!r} is not a sentence of the command language")
            return None
        if result.confidence < self.recogniser.min_confidence:
            self.count("low_confidence", f"{self.mic}: {result.text!r} rejected, confidence "
                                         f"{result.confidence:.2f} < {self.recogniser.min_confidence:.2f} "
                                         f"({result.detail})")
            return None
        audio_t0 = self.stamp_of(utt.audio_start)
        words = [Word(word=w.word, start=audio_t0 + w.start, end=audio_t0 + w.end,
                      confidence=min(1.0, max(0.0, w.confidence))) for w in result.words]
        start, end = self.stamp_of(utt.speech_start), self.stamp_of(utt.speech_end)
        if words:
            start, end = min(start, words[0].start), max(end, words[-1].end)
        transcript = Transcript(stamp=end, source=self.source, mic=self.mic, start=start, end=end,
                                text=result.text, confidence=min(1.0, max(0.0, result.confidence)), words=words,
                                final=True, backend=self.recogniser.name)
        return Heard(transcript, utt.speech_end, result)


def chunk_to_samples(data: bytes, channels: int) -> np.ndarray:
    from services.speech.audio import pcm_to_mono
    return pcm_to_mono(data, channels)


__all__ = ["MicStream", "Heard", "AudioError", "chunk_to_samples"]
