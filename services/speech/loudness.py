"""The utterance's sound level over time (issue #40): what fusion correlates with each visible mouth's opening to
tell which of two moving mouths made the sound. Pure numpy.

RMS per `step` (20 ms: shorter than a syllable, longer than a pitch period, so a voiced sound reads as one level) in
dB full scale, rounded to whole dB: 50 small ints a second on the wire (`Transcript.loudness`, docs/wire.md).
"""

from __future__ import annotations

import numpy as np

from common.schema import Loudness

STEP = 0.02  # s per value
FLOOR_DB = -120  # silence (digital zero) reads as this, the wire's lower bound


def loudness_db(audio: np.ndarray, rate: int, step: float = STEP) -> list[int]:
    """RMS level of each whole `step` of `audio` (float samples in [-1, 1]) in dBFS, rounded; a last partial step
    is left out."""
    n = max(1, int(round(rate * step)))
    whole = len(audio) // n
    if whole == 0:
        return []
    frames = np.asarray(audio[: whole * n], dtype=np.float64).reshape(whole, n)
    rms = np.sqrt(np.mean(frames * frames, axis=1))
    db = 20.0 * np.log10(np.maximum(rms, 10.0 ** (FLOOR_DB / 20.0)))
    return [int(v) for v in np.clip(np.round(db), FLOOR_DB, 0)]


MAX_VALUES = 6000  # the wire's cap: 2 minutes at 20 ms


def loudness_of(audio: np.ndarray, rate: int, start: float, step: float = STEP) -> Loudness:
    """The wire's `Loudness` of `audio` whose first sample is at source time `start`; an utterance longer than
    `MAX_VALUES` steps gets longer steps (at most 0.1 s, the wire's cap; beyond 10 minutes its start only)."""
    step = min(max(step, len(audio) / rate / MAX_VALUES), 0.1)
    return Loudness(start=start, step=step, db=loudness_db(audio, rate, step)[:MAX_VALUES])
