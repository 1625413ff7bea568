"""Colour terms as regions of CIELAB: how plausibly a person would call a measured colour by a word. Pure.

Shared by vision (naming an object's measured colour: `name_distribution`) and fusion (matching a spoken colour:
`term_fit`), so both read the same words the same way. The words and their prototypes are in
common.language (COLOR_PHRASES, COLOR_PROTOTYPES, COLOR_MODIFIERS).

Distance: CIE94 colour difference with lightness weighted half (kL = 2, the textile setting): an object's
lightness varies with shading and exposure far more than its hue does, and a term spans a wide lightness range.
Chroma and hue differences are scaled down for saturated colours (CIE94's S_C, S_H), so a dull real object still
sits near a vivid prototype of its hue. A term's fit is exp(-d²/2σ²) to its nearest prototype.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from common.language import BASIC_COLORS, COLOR_MODIFIERS, COLOR_PHRASES, COLOR_PROTOTYPES

Lab = tuple[float, float, float]

SIGMA = 12.0  # ΔE94 at which a term's fit falls to exp(-1/2) ≈ 0.61
K_L = 2.0  # lightness weight 1/K_L
LIGHTNESS_ONLY = {"dark": 1.0, "light": -1.0}  # terms that say nothing about hue: darker (lighter) than their L fits
LIGHT_SHIFT = 0.45  # "light X": lightness moves this share of the way to 100, chroma × LIGHT_CHROMA
LIGHT_CHROMA = 0.7
DARK_SCALE = 0.55  # "dark X": lightness × this, chroma × DARK_CHROMA
DARK_CHROMA = 0.6


def delta_e94_grid(labs: np.ndarray, refs: np.ndarray, k_l: float = K_L) -> np.ndarray:
    """CIE94 colour difference of every colour in `labs` (N×3) to every one in `refs` (P×3): N×P. Symmetric form
    (S_C, S_H from the geometric mean chroma)."""
    labs, refs = np.asarray(labs, np.float64).reshape(-1, 3), np.asarray(refs, np.float64).reshape(-1, 3)
    c1 = np.hypot(labs[:, 1], labs[:, 2])[:, None]
    c2 = np.hypot(refs[:, 1], refs[:, 2])[None, :]
    dl = labs[:, None, 0] - refs[None, :, 0]
    dc = c1 - c2
    dh2 = np.maximum(
        0.0, (labs[:, None, 1] - refs[None, :, 1]) ** 2 + (labs[:, None, 2] - refs[None, :, 2]) ** 2 - dc * dc
    )
    c = np.sqrt(c1 * c2)
    return np.sqrt((dl / k_l) ** 2 + (dc / (1 + 0.045 * c)) ** 2 + dh2 / (1 + 0.015 * c) ** 2)


def delta_e94(x: Lab, y: Lab, k_l: float = K_L) -> float:
    """CIE94 colour difference of two colours (delta_e94_grid)."""
    return float(delta_e94_grid(np.asarray(x), np.asarray(y), k_l)[0, 0])


def modified(lab: Lab, modifier: str) -> Lab:
    """A prototype made light or dark (chroma shrinks a little either way: pale and deep colours are duller)."""
    lightness, a, b = lab
    if modifier == "light":
        return (lightness + (100 - lightness) * LIGHT_SHIFT, a * LIGHT_CHROMA, b * LIGHT_CHROMA)
    if modifier == "dark":
        return (lightness * DARK_SCALE, a * DARK_CHROMA, b * DARK_CHROMA)
    raise ValueError(f"unknown colour modifier {modifier!r}: use one of {', '.join(COLOR_MODIFIERS)}")


@lru_cache(maxsize=None)
def prototypes(term: str) -> tuple[Lab, ...]:
    """The prototypes of a colour term of COLOR_PHRASES ("red", "light blue", "dark grey")."""
    if term in COLOR_PROTOTYPES:
        return COLOR_PROTOTYPES[term]
    modifier, _, base = term.partition(" ")
    if modifier in COLOR_MODIFIERS and base in COLOR_PROTOTYPES:
        return tuple(modified(p, modifier) for p in COLOR_PROTOTYPES[base])
    raise ValueError(f"unknown colour term {term!r}: the terms are the keys of common.language.COLOR_PHRASES")


def term_fits(term: str, labs: np.ndarray) -> np.ndarray:
    """How plausibly a person calls each measured colour (N×3) `term`, in (0, 1]: exp(-d²/2σ²), d the ΔE94 to the
    term's nearest prototype (lightness alone for "dark" and "light"); 1 at a prototype, 0.61 at σ, 0.14 at 2σ.
    A light or dark term is a claim about lightness: its lightness difference counts in full (k_L = 1). One array
    operation for all, so one decision over a thousand objects stays cheap."""
    labs = np.asarray(labs, np.float64).reshape(-1, 3)
    if term in LIGHTNESS_ONLY:
        d = np.maximum(0.0, LIGHTNESS_ONLY[term] * (labs[:, 0] - COLOR_PROTOTYPES[term][0][0])) / K_L
    else:
        k_l = 1.0 if term.partition(" ")[0] in COLOR_MODIFIERS else K_L
        d = delta_e94_grid(labs, np.asarray(prototypes(term)), k_l).min(axis=1)
    return np.exp(-0.5 * (d / SIGMA) ** 2)


def term_fit(term: str, lab: Lab) -> float:
    """term_fits of one measured colour."""
    return float(term_fits(term, np.asarray(lab))[0])


def name_distribution(lab: Lab, names: tuple[str, ...] = BASIC_COLORS, top: int = 5) -> list[tuple[str, float]]:
    """The likeliest basic colour names of a measured colour, best first, with probabilities (the fits
    normalised over `names`; the `top` best are returned, so they sum to at most 1)."""
    plain = all(n in COLOR_PROTOTYPES and n not in LIGHTNESS_ONLY for n in names)
    fits = _all_fits(names, lab) if plain else [term_fit(n, lab) for n in names]
    total = sum(fits) or 1.0
    ranked = sorted(((n, f / total) for n, f in zip(names, fits)), key=lambda nf: -nf[1])
    return ranked[:top]


@lru_cache(maxsize=8)
def _prototype_table(names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All prototypes of `names` in one array, the index of their name, and where each name's run starts."""
    protos, owner = [], []
    for i, n in enumerate(names):
        for p in prototypes(n):
            protos.append(p)
            owner.append(i)
    owner_arr = np.array(owner)
    starts = np.searchsorted(owner_arr, np.arange(len(names)))
    return np.array(protos, np.float64), owner_arr, starts


def _all_fits(names: tuple[str, ...], lab: Lab) -> list[float]:
    """term_fit of one colour for several plain terms (no modifier, not lightness-only): one array operation."""
    protos, _, starts = _prototype_table(names)
    nearest = np.minimum.reduceat(delta_e94_grid(np.asarray(lab), protos)[0], starts)
    return np.exp(-0.5 * (nearest / SIGMA) ** 2).tolist()


@lru_cache(maxsize=4096)
def name_similarity(term: str, name: str) -> float:
    """How well a colour term fits an object known only by a colour name (an old sender, the colour backend):
    the term's fit at the name's prototypes, the best one (red ~ orange partly, red ~ blue not at all)."""
    if term == name:
        return 1.0
    return max(term_fit(term, p) for p in prototypes(name)) if name in COLOR_PHRASES else 0.0
