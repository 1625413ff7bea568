"""A spoken colour matched by similarity, relative to the other candidates. Pure.

"The red cup" is the cup that is most plausibly red among the cups (the objects the other words fit):
- each candidate's fit to the term comes from its measured colour (`lab`, vision's colour model:
  common.color.term_fits), else from its colour names (`name_fit`: `colors`, `color`; the term's fit at the
  names' prototypes, so red and orange partly match, red and blue do not);
- when no candidate is plausibly that colour (fit below PLAUSIBLE; from a name alone below PLAUSIBLE_NAME),
  every candidate gets 0: "I can't see the red cup";
- otherwise each gets min(1, fit / (ABOUT_EQUAL × best fit)) ** SHARPNESS: those within ABOUT_EQUAL of the best
  fit the words equally (1: the caller asks which one), the rest fall away fast (one that is half as red is
  0.2, a third as red 0.04);
- a candidate with no colour at all (an old sender's nil) gets 0.5: neither fits nor is excluded.
docs/fusion.md "Colour" has the figures measured on real scenes.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from common.color import name_similarity, term_fits

PLAUSIBLE = 0.2  # a measured colour fits the term this well (ΔE94 ≈ 1.8 σ): plausibly that colour
PLAUSIBLE_NAME = 0.5  # from a name alone: the name's prototype within ≈ 1.2 σ of the term (red/orange, grey/white)
ABOUT_EQUAL = 0.75  # fits within this share of the best one are the same answer to the words
SHARPNESS = 4.0
UNKNOWN = 0.5  # no colour reported: neither fits nor excluded


class Coloured(Protocol):  # read-only: a frozen SceneObject is one
    @property
    def key(self) -> tuple[str, str]: ...
    @property
    def color(self) -> str | None: ...
    @property
    def lab(self) -> tuple[float, float, float] | None: ...
    @property
    def colors(self) -> tuple[tuple[str, float], ...]: ...


def name_fit(term: str, obj: Coloured) -> float | None:
    """Fit of an object known only by colour names to the term: the names' similarity to it (`colors` weighted by
    their probabilities, else `color`); None when the object reports no colour."""
    if obj.colors:
        total = sum(p for _, p in obj.colors) or 1.0
        return sum(p * name_similarity(term, name) for name, p in obj.colors) / total
    if obj.color:
        return name_similarity(term, obj.color)
    return None


def colour_factors(term: str, candidates: list[Coloured]) -> dict[tuple[str, str], float]:
    """Per candidate (the objects the other words fit), the factor the colour word puts on its match."""
    measured = [o for o in candidates if o.lab is not None]
    keys = [o.key for o in measured]
    fits = term_fits(term, np.array([o.lab for o in measured], np.float64)).tolist() if measured else []
    plausible = [f for f in fits if f >= PLAUSIBLE]  # all measured colours in one array operation
    unknown = []
    by_names: dict[object, float | None] = {}  # objects reporting the same names fit alike: once per set of names
    for o in candidates:
        if o.lab is None:
            names = o.colors or o.color
            if names not in by_names:
                by_names[names] = name_fit(term, o)
            f = by_names[names]
            if f is None:
                unknown.append(o.key)
                continue
            keys.append(o.key)
            fits.append(f)
            if f >= PLAUSIBLE_NAME:
                plausible.append(f)
    out = dict.fromkeys(unknown, UNKNOWN)
    if not plausible:
        out.update(dict.fromkeys(keys, 0.0))
    else:
        scale = 1.0 / (ABOUT_EQUAL * max(plausible))
        out.update((k, min(1.0, f * scale) ** SHARPNESS) for k, f in zip(keys, fits))
    return out
