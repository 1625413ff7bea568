"""Recognition backends: one utterance of 16 kHz float audio in, words with times and confidences out.

- `PocketsphinxRecognizer` (default): the command grammar compiled to a word graph, decoded with the
  US-English model shipped in the pocketsphinx wheel. A grammar decoder forces any speech into
  *some* command, so each result gets a confidence from how well its words fit the audio (per-frame
  acoustic score relative to the best state of each frame); below the threshold it is rejected.
- `WhisperRecognizer`: faster-whisper with a local CTranslate2 model folder (optional extra).
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from services.speech.audio import RATE
from services.speech.grammar import Grammar, build_grammar, normalise

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

    def __init__(self, min_confidence: float = 0.5, model_dir: str | None = None,
                 log: Callable[[str], None] = lambda msg: None, commands: list[str] | None = None):
        """`commands`: a closed list of sentences (each must be in the command language) to recognise
        instead of the whole open grammar — far more robust when a deployment knows its commands."""
        try:
            import pocketsphinx
        except ImportError as exc:
            raise BackendError("pocketsphinx is not installed: `pip install 'hri-fusion[speech]'` "
                               f"(or run `make setup`) ({exc})") from None
        self._ps = pocketsphinx
        hmm = Path(model_dir) if model_dir else Path(pocketsphinx.get_model_path("en-us/en-us"))
        if not (hmm / "mdef").exists():
            raise BackendError(f"{hmm} is not a pocketsphinx acoustic model folder (no mdef file); "
                               "leave --model unset to use the US-English model shipped in the wheel")
        dict_path = pocketsphinx.get_model_path("en-us/cmudict-en-us.dict")
        # dither: digital silence (exact zeros) otherwise turns into words
        # maxhmmpf: the grammar fans out to ~1,900 words per state; capping active HMMs per frame took
        # decoding from ~1x to ~0.07x real time here at no loss of accuracy (docs/speech.md)
        # seed: dither is random noise; a fixed seed makes the same audio decode the same way every time
        common = dict(hmm=str(hmm), dict=dict_path, loglevel="FATAL", dither=True, seed=1, samprate=RATE,
                      maxhmmpf=2000)
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
        self.decoder.activate_search("commands")

    def _decode(self, decoder, pcm: bytes) -> list:
        decoder.start_utt()
        for i in range(0, len(pcm), 4096):  # fed in pieces: one full_utt call decodes worse
            decoder.process_raw(pcm[i:i + 4096], False, False)
        decoder.end_utt()
        return list(decoder.seg() or [])

    def recognise(self, audio: np.ndarray) -> Recognition | None:
        pcm = (np.clip(audio, -1.0, 1.0) * 32767.0).astype("<i2").tobytes()
        words = [s for s in self._decode(self.decoder, pcm) if not _is_filler(s.word)]
        if not words:
            return None  # no grammar path reached the end: certainly not a command

        def fit(seg_list: list) -> float:
            # the words' acoustic likelihood relative to the best-scoring state of each frame
            # (pocketsphinx normalises per frame), as mean log per frame: 0 is a perfect fit
            frames = sum(s.end_frame - s.start_frame + 1 for s in seg_list)
            return sum(math.log(max(s.ascore, 1e-300)) for s in seg_list) / max(frames, 1)

        utterance_fit = fit(words)
        out = [RecognisedWord(_base_word(s.word), s.start_frame / FRAME_RATE, (s.end_frame + 1) / FRAME_RATE,
                              self._confidence(fit([s]))) for s in words]
        return Recognition(" ".join(w.word for w in out), self._confidence(utterance_fit), out,
                           detail=f"acoustic fit {utterance_fit:.2f}/frame")

    def _confidence(self, fit_per_frame: float) -> float:
        """Logistic map of the per-frame fit: FIT_CENTRE -> 0.5. Measured on espeak-ng speech: commands
        mostly -3.4 to -6.0, forced non-commands -6.0 to -6.8 (docs/speech.md)."""
        return float(1.0 / (1.0 + math.exp(-(fit_per_frame - FIT_CENTRE) / FIT_SCALE)))


def closed_list(sentences: list[str], in_language: Callable[[str], bool], lookup: Callable[[str], str | None],
                log: Callable[[str], None]) -> list[str]:
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


FIT_CENTRE = -6.3
FIT_SCALE = 0.3


def _is_filler(word: str) -> bool:
    return word.startswith(("<", "[", "+")) or word == "</s>"


def _base_word(word: str) -> str:
    """'that(2)' (an alternative pronunciation) -> 'that'."""
    return word.split("(", 1)[0]


def _language_words() -> set[str]:
    from common.language import vocabulary
    return vocabulary()


class WhisperRecognizer:
    """faster-whisper on CPU, int8, English, word timestamps, from a local CTranslate2 model folder."""

    name = "whisper"

    def __init__(self, model_path: str | None, min_confidence: float = 0.5):
        if not model_path:
            raise BackendError(_WHISPER_HELP.format(problem="--backend whisper needs --model PATH"))
        if not (Path(model_path) / "model.bin").is_file():
            raise BackendError(_WHISPER_HELP.format(
                problem=f"{model_path} is not a CTranslate2 whisper model folder (no model.bin there)"))
        try:
            from faster_whisper import WhisperModel
        except ImportError as exc:
            raise BackendError(f"faster-whisper is not installed ({exc}): `pip install 'hri-fusion[whisper]'`") \
                from None
        from common.language import vocabulary
        self.model = WhisperModel(model_path, device="cpu", compute_type="int8", local_files_only=True)
        self.prompt = "Robot commands: " + ", ".join(sorted(vocabulary())) + "."
        self.min_confidence = min_confidence
        self.matches = build_grammar().matcher()

    def recognise(self, audio: np.ndarray) -> Recognition | None:
        segments, _ = self.model.transcribe(audio.astype(np.float32), language="en", word_timestamps=True,
                                            initial_prompt=self.prompt, beam_size=5, vad_filter=False)
        words: list[RecognisedWord] = []
        for seg in segments:
            for w in seg.words or []:
                for token in normalise(w.word).split():
                    words.append(RecognisedWord(token, float(w.start), float(w.end), float(w.probability)))
        if not words:
            return None
        confidence = float(np.exp(np.mean(np.log(np.clip([w.confidence for w in words], 1e-6, 1.0)))))
        return Recognition(" ".join(w.word for w in words), confidence, words, detail="mean word probability")


_WHISPER_HELP = """{problem}.
Download a CTranslate2 conversion of a Whisper model once, on a machine with internet access, e.g.:
  pip install huggingface_hub && huggingface-cli download Systran/faster-whisper-base.en --local-dir models/whisper-base.en
then run with --backend whisper --model models/whisper-base.en (nothing is downloaded at run time)."""
