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
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from common.counters import SpeechCounter
from common.schema import Transcript, Word
from services.speech.audio import RATE, AudioError, Resampler, check_rate
from services.speech.echo import EchoCanceller, OwnVoice, barge_in
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
        # told (True, mic) when a decode starts and (False, mic) when it ends, on the worker's thread (the shell
        # publishes it: speech first, issue #42)
        self.on_busy: Callable[[bool, str], None] | None = None

    def submit(self, audio: np.ndarray, mic: str = "") -> Future:
        return self._executor.submit(self._recognise, audio, mic)

    def _recognise(self, audio: np.ndarray, mic: str) -> Recognition | None:
        tell = self.on_busy
        if tell is not None:
            tell(True, mic)
        try:
            return self.recogniser.recognise(audio)
        finally:
            if tell is not None:
                tell(False, mic)

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

CHECK_SECONDS = 0.5  # under the robot's voice, the masked audio is checked for a stop every this many seconds
FULL_SCALE = 32767 / 32768  # a 16-bit sample at its limit
CLIPPED_SHARE = 0.001  # a robot's utterance with this share of its microphone samples at full scale is reported


@dataclass
class MaskedSpan:
    """Microphone audio under the robot's voice: from stream index `first` until source time `until`."""

    first: int
    until: float
    parts: list[np.ndarray] = field(default_factory=list)
    samples: int = 0
    checked: int = 0  # samples of the span at its last check
    decided_until: int = 0  # span index up to which its cuts have been decided


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
        own_voice: OwnVoice | None = None,
    ):
        self.mic, self.source = mic, source
        # the robot's own voice: masked from the VAD; the masked audio, echo cancelled, is checked for a stop
        self.own_voice = own_voice
        self._make_segmenter = make_segmenter
        self._canceller = EchoCanceller()
        self._masking: MaskedSpan | None = None  # the span of the robot's voice being heard
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
        if self._masking is not None:
            heard += self._end_mask()
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
        heard: list[Heard] = []
        if self.own_voice is not None:
            samples16k, heard = self._mask(samples16k)
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

    def _mask(self, samples: np.ndarray) -> tuple[np.ndarray, list[Heard]]:
        """The chunk with the robot's own voice (its announced spans plus the echo tail) silenced for the VAD; the
        silenced audio is kept and checked for a person's stop as it comes (`_check_span`)."""
        assert self.own_voice is not None
        heard: list[Heard] = []
        out = samples.copy()
        pos, n, base = 0, len(samples), self._out_samples
        while pos < n:
            t = self.stamp_of(base + pos)
            until = self.own_voice.masked_until(t)
            if self._masking is None and until is None:
                nxt = self.own_voice.next_start(t)
                pos = n if nxt is None else max(pos + 1, min(n, int(np.ceil((nxt - self._t0) * RATE)) - base))
                continue
            if self._masking is None:
                assert until is not None
                self._masking = MaskedSpan(base + pos, until)
            span = self._masking
            span.until = max(span.until, until or span.until)  # an utterance that follows within the tail
            end = min(n, max(pos + 1, int(np.ceil((span.until - self._t0) * RATE)) - base))
            span.parts.append(samples[pos:end].copy())
            span.samples += end - pos
            out[pos:end] = 0.0
            pos = end
            if self.stamp_of(base + pos) >= span.until:
                heard += self._end_mask()
            elif span.samples - span.checked >= CHECK_SECONDS * RATE and self._canceller.path is not None:
                # (before the echo path is first learnt, what is left is the robot's whole voice: checked at the end)
                heard += self._check_span(span, final=False)
        return out, heard

    def _end_mask(self) -> list[Heard]:
        assert self._masking is not None
        span, self._masking = self._masking, None
        self.count("own_voice_spans", "")
        return self._check_span(span, final=True)

    def _check_span(self, span: MaskedSpan, final: bool) -> list[Heard]:
        """The robot's echo taken out of the masked audio so far (with the echo path known from before; refitted
        when the span ends), cut by the VAD; each new cut is decoded and published only if it is a stop."""
        assert self.own_voice is not None
        mic = np.concatenate(span.parts)
        span.parts, span.checked = [mic], len(mic)
        start = self.stamp_of(span.first)
        clipped = float(np.mean(np.abs(mic) >= FULL_SCALE)) if final and len(mic) else 0.0
        if clipped >= CLIPPED_SHARE:
            self.count(
                "own_voice_clipped",
                f"{self.mic}: {clipped:.1%} of the samples under the robot's voice at {start:.2f} are at full scale: "
                "lower the microphone's gain or the speaker's volume (a clipped echo cannot be taken out, and a stop "
                "said over the robot may be missed)",
            )
        reference = self.own_voice.reference(start, len(mic))
        residual = self._canceller.cancel(mic, reference) if final else self._canceller.apply(mic, reference)
        own_texts = self.own_voice.texts(start, start + len(mic) / RATE)
        segmenter = self._make_segmenter()
        heard: list[Heard] = []
        for utt in segmenter.feed(residual) + (segmenter.flush() if final else []):
            if utt.speech_start < span.decided_until:
                continue  # decided at an earlier check
            span.decided_until = utt.speech_end
            result = self.worker.submit(utt.audio).result()
            stop = barge_in(result, utt.audio, self.recogniser, own_texts, self.own_voice.prior)
            at = f"{self.stamp_of(span.first + utt.speech_start):.2f}"
            if stop is None:
                said = result.text if result is not None else ""
                self.count("own_voice_dropped", f"{self.mic}: over the robot's voice at {at}: {said!r} (not a stop)")
                continue
            self.count("barge_in", f"{self.mic}: a stop over the robot's voice at {at} ({stop.detail})")
            shifted = VoicedSegment(
                utt.audio, span.first + utt.audio_start, span.first + utt.speech_start, span.first + utt.speech_end
            )
            heard.append(self._heard(shifted, stop, final=True))
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
            self._partial = (so_far, self.worker.submit(so_far.audio, self.mic))
        return out

    def _speculate(self, tentative: VoicedSegment) -> None:
        if tentative.speech_seconds < self.segmenter.config.min_speech:
            return  # would be dropped as too short unless speech resumes; then the next pause speculates
        if self._speculation is not None:
            self._speculation[2].cancel()  # the person spoke again before it started: not needed any more
            self.count("speculation_wasted", "")
        self._speculation = (tentative.audio_start, tentative.speech_end, self.worker.submit(tentative.audio, self.mic))

    def _decode(self, utt: VoicedSegment) -> Recognition | None:
        spec, self._speculation = self._speculation, None
        if spec is not None and spec[:2] == (utt.audio_start, utt.speech_end) and not spec[2].cancelled():
            self.count("speculation_used", "")
            return spec[2].result()
        if spec is not None:
            spec[2].cancel()
            self.count("speculation_wasted", "")
        return self.worker.submit(utt.audio, self.mic).result()

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
