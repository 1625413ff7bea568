"""One microphone's stream: stamped PCM -> resample -> VAD -> recogniser -> checked Transcripts.

No zenoh: the service shell feeds it and publishes what it returns. Time is the audio's own
clock: the stamp of the first sample plus sample offsets. A chunk whose stamp disagrees with that
clock by more than `resync_after` (a gap, a restart) ends the utterance in progress and restarts
the clock from the new stamp.

With `partial_every` set, the utterance heard so far is also decoded every that many seconds of
speech while the person speaks and published as a `final=false` Transcript (only when the worker is
idle, and never after the final one).

Every decode runs on one worker thread per recogniser (`RecognitionWorker`; a model is used by one
thread at a time). A slow recogniser (Whisper) decodes *speculatively*: when the VAD sees the first
window of silence, the utterance so far goes to the worker while the VAD keeps listening; when the
VAD confirms the end (`min_silence` later) that result is used, and if the person spoke again the
utterance is decoded anew at its next pause.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from common.counters import SpeechCounter
from common.schema import Transcript, Word
from services.speech.audio import RATE, AudioError, Resampler, check_rate
from services.speech.loudness import loudness_of
from services.speech.recognizers import Recognition
from services.speech.vad import Segmenter, VoicedSegment


class Recogniser(Protocol):
    name: str
    min_confidence: float
    speculative: bool  # decode at the first silence, before the VAD confirms the end

    @property
    def matches(self) -> Callable[[str], bool] | None:
        """A grammar the text must be a sentence of (pocketsphinx), or None: publish whatever was heard (whisper)."""

    def recognise(self, audio: np.ndarray) -> Recognition | None: ...


class RecognitionWorker:
    """The one thread that runs a recogniser's decodes, shared by every mic stream using it."""

    def __init__(self, recogniser: Recogniser):
        self.recogniser = recogniser
        self._executor = ThreadPoolExecutor(1, thread_name_prefix=f"recognise-{recogniser.name}")

    def submit(self, audio: np.ndarray) -> Future:
        return self._executor.submit(self.recogniser.recognise, audio)

    def close(self) -> None:
        self._executor.shutdown(wait=False, cancel_futures=True)


_workers_lock = threading.Lock()


def worker_for(recogniser: Recogniser) -> RecognitionWorker:
    """The recogniser's worker, made on first use and kept on the recogniser (so it goes when it goes)."""
    with _workers_lock:
        worker = getattr(recogniser, "_recognition_worker", None)
        if worker is None:
            worker = RecognitionWorker(recogniser)
            # setattr: an attribute the Recogniser protocol does not declare (any recogniser object can carry it)
            setattr(recogniser, "_recognition_worker", worker)  # noqa: B010
        return worker


Count = Callable[[SpeechCounter, str], None]  # (counter name, detail for the log)


@dataclass
class Heard:
    transcript: Transcript
    decided_at: int  # stream sample index at which the VAD closed the utterance
    recognition: Recognition


class MicStream:
    def __init__(
        self,
        mic: str,
        source: str,
        recogniser: Recogniser,
        make_segmenter: Callable[[], Segmenter],
        count: Count,
        resync_after: float = 0.25,
        partial_every: float | None = None,
    ):
        self.mic, self.source = mic, source
        self.recogniser = recogniser
        self.worker = worker_for(recogniser)
        self.segmenter = make_segmenter()
        # (audio_start, speech_end, decode started at the pause) of the utterance in progress
        self._speculation: tuple[int, int, Future] | None = None
        self.partial_every = partial_every
        self._partial: tuple[VoicedSegment, Future] | None = None
        self._partial_at = 0  # segmenter position when the last partial decode was started
        if getattr(recogniser, "speculative", False):
            self.segmenter.on_pause = self._speculate
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
            self.count(
                "format_changed",
                f"{self.mic}: sample rate changed from {self._format[0]} to {rate} Hz; restarting the stream",
            )
            heard += self.flush()
            self._start(rate, stamp)
        else:
            drift = stamp - self.clock
            if abs(drift) > self.resync_after:
                self.count(
                    "clock_resync",
                    f"{self.mic}: chunk stamp is {drift:+.3f} s off the audio clock "
                    "(gap or restart); ending the utterance and resyncing",
                )
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
        if self._speculation is not None:  # its utterance ended as too short: nothing to wait for
            self._speculation[2].cancel()
            self._speculation = None
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
        if self.partial_every:
            heard += self._partials()
        return heard

    def _partials(self) -> list[Heard]:
        """A finished partial decode to publish, and a new one started if it is time and the worker is idle."""
        out: list[Heard] = []
        if self._partial is not None and self._partial[1].done():
            utt, future = self._partial
            self._partial = None
            result = None if future.cancelled() or future.exception() else future.result()
            if result is not None and result.text:
                out.append(self._heard(utt, result, final=False))
                self.count("partials", "")
        so_far = self.segmenter.in_progress()
        every = self.partial_every or 0.0  # (set: feed() calls this only then)
        if (
            so_far is not None
            and self._partial is None
            and self._speculation is None
            and so_far.speech_seconds >= every
            and self.segmenter.position - self._partial_at >= every * RATE
        ):
            self._partial_at = self.segmenter.position
            self._partial = (so_far, self.worker.submit(so_far.audio))
        return out

    def _speculate(self, tentative: VoicedSegment) -> None:
        if tentative.speech_seconds < self.segmenter.config.min_speech:
            return  # would be dropped as too short unless speech resumes; then the next pause speculates
        if self._speculation is not None:
            self._speculation[2].cancel()  # the person spoke again before it started: not needed any more
            self.count("speculation_wasted", "")
        self._speculation = (tentative.audio_start, tentative.speech_end, self.worker.submit(tentative.audio))

    def _decode(self, utt: VoicedSegment) -> Recognition | None:
        spec, self._speculation = self._speculation, None
        if spec is not None and spec[:2] == (utt.audio_start, utt.speech_end) and not spec[2].cancelled():
            self.count("speculation_used", "")
            return spec[2].result()
        if spec is not None:
            spec[2].cancel()
            self.count("speculation_wasted", "")
        return self.worker.submit(utt.audio).result()

    def _recognise(self, utt: VoicedSegment) -> Heard | None:
        if self._partial is not None:  # the final result supersedes it
            self._partial[1].cancel()
            self._partial = None
        self.count("utterances", "")
        if utt.forced:
            self.count("utterance_cut", f"{self.mic}: speech longer than the maximum utterance was cut")
        result = self._decode(utt)
        at = f"{self.stamp_of(utt.speech_start):.2f}"
        if result is not None and result.repeats_removed:
            self.count(
                "repeats_removed", f"{self.mic}: {result.repeats_removed} repeated word(s) dropped as a loop at {at}"
            )
        if result is not None and result.tail_removed:
            self.count("tail_removed", f"{self.mic}: {result.tail_removed} doubted last word(s) dropped at {at}")
        if result is not None and result.short_command:
            self.count(
                "short_command",
                f"{self.mic}: one word heard as a command ({result.short_command}; {result.detail}) at {at}",
            )
        if result is None or not result.text:
            if result is not None and result.dropped:
                self.count(result.dropped, f"{self.mic}: no words in the utterance at {at} ({result.dropped})")
            else:
                self.count("not_a_command", f"{self.mic}: nothing in the grammar matched an utterance at {at}")
            return None
        if self.recogniser.matches is not None and not self.recogniser.matches(result.text):
            self.count("not_a_command", f"{self.mic}: {result.text!r} is not a sentence of the command language")
            return None
        if result.confidence < self.recogniser.min_confidence:
            self.count(
                "low_confidence",
                f"{self.mic}: {result.text!r} rejected, confidence "
                f"{result.confidence:.2f} < {self.recogniser.min_confidence:.2f} "
                f"({result.detail})",
            )
            return None
        return self._heard(utt, result, final=True)

    def _heard(self, utt: VoicedSegment, result: Recognition, final: bool) -> Heard:
        audio_t0 = self.stamp_of(utt.audio_start)
        words = [
            Word(
                word=w.word, start=audio_t0 + w.start, end=audio_t0 + w.end, confidence=min(1.0, max(0.0, w.confidence))
            )
            for w in result.words
        ]
        start, end = self.stamp_of(utt.speech_start), self.stamp_of(utt.speech_end)
        if words:
            start, end = min(start, words[0].start), max(end, words[-1].end)
        transcript = Transcript(
            stamp=end,
            source=self.source,
            mic=self.mic,
            start=start,
            end=end,
            text=result.text,
            confidence=min(1.0, max(0.0, result.confidence)),
            words=words,
            final=final,
            backend=self.recogniser.name,
            # the sound over time, for fusion to match against the mouths in view (issue #40): final ones only
            loudness=loudness_of(utt.audio, RATE, audio_t0) if final else None,
        )
        return Heard(transcript, utt.speech_end, result)


__all__ = ["MicStream", "Heard", "AudioError"]
