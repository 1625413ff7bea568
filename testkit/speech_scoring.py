"""Scoring recognised speech for the speech tests and benchmark: word error rate, and meaning as fusion's
parser reads it (what a robot would act on), plus the synthesised test audio cached per session."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from common.language import NUMBER_WORDS
from services.fusion.parse import parse
from services.speech.audio import read_wav
from testkit.synth import concatenate, synthesize

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "speech"


def lines(name: str) -> list[str]:
    return [line.strip() for line in (DATA / name).read_text().splitlines() if line.strip()]


COMMANDS = lines("commands.txt") + lines("commands_extra.txt")  # 32: the grammar's and motions outside it
NON_COMMANDS = lines("non_commands.txt")
NON_COMMAND_WORDS = lines("non_command_words.txt")  # said alone: ordinary words, none of them a command
_SPELLED = {
    str(int(v)): w
    for w, v in NUMBER_WORDS.items()
    if float(v).is_integer() and w.isalpha() and w not in ("a", "an", "single", "couple", "few")
}


def spelled(words: list[str]) -> list[str]:
    """Numbers as the reference writes them ("10" -> "ten"): Whisper writes digits, fusion reads both."""
    return [_SPELLED.get(w, w) for w in words]


def word_errors(ref: list[str], hyp: list[str]) -> int:
    d = np.arange(len(hyp) + 1)
    for i, r in enumerate(ref, 1):
        prev, d[0] = d.copy(), i
        for j, h in enumerate(hyp, 1):
            d[j] = min(prev[j] + 1, d[j - 1] + 1, prev[j - 1] + (r != h))
    return int(d[-1])


def meaning(text: str) -> tuple:
    """What fusion's parser makes of the words: intent, answer, object, place, motion."""
    u = parse(text)
    motion = None if u.motion is None else (u.intent, u.motion.direction, u.motion.distance, u.motion.angle)
    return u.intent, u.answer, u.obj, u.place, u.deictic_place, u.dest_obj, motion


class AudioCache:
    """Synthesised WAVs, made once per test session (piper and espeak-ng take ~0.1-1 s a sentence)."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.folder.mkdir(parents=True, exist_ok=True)

    def speech(self, text: str, voice: str, snr: float | None = None, seed: int = 0, **kw) -> Path:
        name = f"{voice}-{snr}-{seed}-{'_'.join(text.split())}-{'-'.join(f'{k}{v}' for k, v in sorted(kw.items()))}"
        path = self.folder / (name.replace(":", "_").replace("+", "_")[:180] + ".wav")
        if not path.exists():
            synthesize(text, path, voice=voice, noise_snr_db=snr, noise_seed=seed, **kw)
        return path

    def stream(
        self, texts: list[str], voice: str, snr: float | None, gap: float
    ) -> tuple[Path, list[tuple[float, float]]]:
        """The sentences as one WAV with `gap` s of silence between them, and each one's span (s from the start)."""
        files = [self.speech(t, voice, snr, seed=i) for i, t in enumerate(texts)]
        out = self.folder / f"stream-{voice}-{snr}-{gap}-{abs(hash(tuple(texts)))}.wav".replace(":", "_")
        if not out.exists():
            concatenate(files, out, gap=gap)
        spans, at = [], 0.0
        for path in files:
            length = read_wav(path).seconds
            spans.append((at, at + length))
            at += length + gap
        return out, spans


def score(texts: list[str], spans: list[tuple[float, float]], transcripts: list, t0: float) -> dict:
    """WER over the whole stream and, per sentence, whether the transcripts heard within its span mean
    what it meant. A sentence with no transcript counts as its words deleted and its meaning missed."""
    heard: list[list[str]] = [[] for _ in texts]
    for t in transcripts:
        middle = (t.start + t.end) / 2 - t0
        i = min(
            range(len(spans)),
            key=lambda k: (
                0 if spans[k][0] <= middle <= spans[k][1] else min(abs(middle - spans[k][0]), abs(middle - spans[k][1]))
            ),
        )
        heard[i].append(t.text)
    ref = " ".join(texts).split()
    hyp = spelled(" ".join(" ".join(h) for h in heard).split())
    right = [meaning(" ".join(h)) == meaning(text) for h, text in zip(heard, texts)]
    return {
        "wer": word_errors(ref, hyp) / len(ref),
        "meaning": sum(right) / len(texts),
        "heard": [" ".join(h) for h in heard],
        "wrong": [(t, " ".join(h)) for h, t, ok in zip(heard, texts, right) if not ok],
    }
