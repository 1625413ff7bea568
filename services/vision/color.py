"""Naming colours from HSV pixels — the one palette of the vision service.

OpenCV's hue runs 0–179. Red sits at both ends, so it is two ranges (0–4 and 170–179). Pixels with
saturation below ACHROMATIC_SATURATION carry no hue worth reading: they are white, grey or black by value.
The colour names are the keys of common.language.COLOR_PHRASES, so "the crimson one" finds a `red` object.
"""

from __future__ import annotations

import numpy as np

from common.language import COLOR_PHRASES

HUE_RANGES: dict[str, tuple[tuple[int, int], ...]] = {
    "red": ((0, 5), (170, 180)),
    "orange": ((5, 21),),
    "yellow": ((21, 34),),
    "green": ((34, 85),),
    "blue": ((85, 130),),
    "purple": ((130, 170),),
}
ACHROMATIC_SATURATION = 60   # below: no hue (0–255 scale)
DARK_VALUE = 75              # below: black, whatever the hue (a black lid under a blue cast is V≈64)
WHITE_VALUE = 180            # achromatic and at least this bright: white

assert set(HUE_RANGES) | {"white", "black", "grey"} == set(COLOR_PHRASES), "palette and language disagree"

# hue (0..179) -> index into CHROMATIC, for a histogram in one bincount
CHROMATIC = tuple(HUE_RANGES)
_HUE_TO_COLOR = np.zeros(180, np.int64)
for _i, _name in enumerate(CHROMATIC):
    for _lo, _hi in HUE_RANGES[_name]:
        _HUE_TO_COLOR[_lo:_hi] = _i


def color_name(hsv_pixels: np.ndarray) -> tuple[str | None, float]:
    """The colour most of these pixels (N×3 HSV) have, and the share of pixels that agree (0–1).

    Dark pixels vote black, low-saturation ones white or grey by brightness, the rest by hue range.
    None for no pixels.
    """
    pixels = hsv_pixels.reshape(-1, 3)
    if len(pixels) == 0:
        return None, 0.0
    sat, val = pixels[:, 1], pixels[:, 2]
    dark = val < DARK_VALUE
    achromatic = ~dark & (sat < ACHROMATIC_SATURATION)
    chromatic = ~dark & ~achromatic
    votes = {"black": int(dark.sum()),
             "white": int((achromatic & (val >= WHITE_VALUE)).sum()),
             "grey": int((achromatic & (val < WHITE_VALUE)).sum())}
    hist = np.bincount(_HUE_TO_COLOR[pixels[chromatic, 0].astype(np.int64)], minlength=len(CHROMATIC))
    votes.update({name: int(n) for name, n in zip(CHROMATIC, hist)})
    best = max(votes, key=votes.__getitem__)
    return best, votes[best] / len(pixels)


def hue_name(hue_hist: np.ndarray) -> tuple[str, float]:
    """The chromatic colour of a 180-bin hue histogram, and the share of its pixels that agree (0–1)."""
    votes = np.bincount(_HUE_TO_COLOR, weights=hue_hist.ravel(), minlength=len(CHROMATIC))
    best = int(votes.argmax())
    return CHROMATIC[best], float(votes[best] / max(votes.sum(), 1.0))
