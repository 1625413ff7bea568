"""Colour in the vision service: the colour backend's HSV palette, and the colour model of a detector's box.

The palette (HUE_RANGES, color_name, hue_name) names the colour backend's segments. OpenCV's hue runs 0–179.
Red sits at both ends, so it is two ranges (0–4 and 170–179). Pixels with saturation below
ACHROMATIC_SATURATION carry no hue worth reading: they are white, grey or black by value.

A detector's box gets a measurement instead (illuminant_gains, dominant_mask, measure_lab): the CIELAB of the
object's own pixels, named by common.color.name_distribution (docs/vision.md "Colour of a detection").
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
ACHROMATIC_SATURATION = 60  # below: no hue (0–255 scale)
DARK_VALUE = 75  # below: black, whatever the hue (a black lid under a blue cast is V≈64)
WHITE_VALUE = 180  # achromatic and at least this bright: white

PALETTE: tuple[str, ...] = (*HUE_RANGES, "white", "black", "grey")  # the colour backend's names
assert set(PALETTE) <= set(COLOR_PHRASES), "palette and language disagree"

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
    votes = {
        "black": int(dark.sum()),
        "white": int((achromatic & (val >= WHITE_VALUE)).sum()),
        "grey": int((achromatic & (val < WHITE_VALUE)).sum()),
    }
    hist = np.bincount(_HUE_TO_COLOR[pixels[chromatic, 0].astype(np.int64)], minlength=len(CHROMATIC))
    votes.update({name: int(n) for name, n in zip(CHROMATIC, hist)})
    best = max(votes, key=votes.__getitem__)
    return best, votes[best] / len(pixels)


def hue_name(hue_hist: np.ndarray) -> tuple[str, float]:
    """The chromatic colour of a 180-bin hue histogram, and the share of its pixels that agree (0–1)."""
    votes = np.bincount(_HUE_TO_COLOR, weights=hue_hist.ravel(), minlength=len(CHROMATIC))
    best = int(votes.argmax())
    return CHROMATIC[best], float(votes[best] / max(votes.sum(), 1.0))


# -- the colour model of a detector's box: a measurement (CIELAB), not a word -------------------------------
# docs/vision.md "Colour of a detection". The pixels are sampled (core.foreground_mask picks the object's own),
# corrected for the scene's illuminant, trimmed of highlights and shadows, and averaged in linear light.

SRGB_TO_LINEAR = np.array(
    [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in np.arange(256) / 255.0], np.float32
)
_XYZ_FROM_LINEAR_BGR = np.array(
    [
        [0.1804375, 0.3575761, 0.4124564],  # rows X, Y, Z; columns B, G, R
        [0.0721750, 0.7151522, 0.2126729],
        [0.9503041, 0.1191920, 0.0193339],
    ],
    np.float32,
)
_D65 = np.array([0.95047, 1.0, 1.08883], np.float32)

ILLUMINANT_SIDE = 64  # px: the frame is shrunk to about this for the illuminant estimate
SHADES_OF_GREY_P = 6  # Minkowski norm of the estimate (1 = grey-world, ∞ = max-RGB / white-patch)
MAX_GAIN = 1.2  # no channel is scaled by more than this (or less than its inverse) for colour
BRIGHT_QUANTILE = 0.95  # the scene's bright surfaces: this luminance quantile of its unclipped pixels …
BRIGHT_REFERENCE = 0.85  # … is brought up to this luminance (lightness is judged relative to the scene)
MAX_EXPOSURE = 1.5  # at most this much brighter; never darker
CLIPPED = 250  # 8-bit: a channel at or above this is clipped (a highlight, or a window)
TRIM = (0.15, 0.90)  # luminance quantiles of the object's pixels kept: deep shadows and highlights out


def linear_to_lab(linear_bgr: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of linear-light BGR values (…×3, 0–1)."""
    xyz = np.asarray(linear_bgr, np.float32) @ _XYZ_FROM_LINEAR_BGR.T / _D65
    f = np.where(xyz > (6 / 29) ** 3, np.cbrt(np.maximum(xyz, 0)), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1)


def linear_to_srgb8(linear: np.ndarray) -> np.ndarray:
    """8-bit sRGB of linear-light values (0–1, any channel order)."""
    c = np.clip(linear, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.round(s * 255).astype(np.uint8)


def _channel_max(pixels: np.ndarray) -> np.ndarray:
    """The largest channel of each of N×3 pixels: as pixels.max(axis=1), several times faster (a reduction over
    an axis of 3 pays numpy's per-row overhead)."""
    return np.maximum(np.maximum(pixels[:, 0], pixels[:, 1]), pixels[:, 2])


def _column_mean(rows: np.ndarray) -> np.ndarray:
    """rows.mean(axis=0) as numpy computes it (the sum, then divided in place by the count), without its
    Python-level overhead."""
    total = np.add.reduce(rows, axis=0)
    return np.true_divide(total, np.intp(len(rows)), out=total, casting="unsafe")


def illuminant_gains(bgr: np.ndarray) -> np.ndarray:
    """Per-channel (B, G, R) gains that make the scene's light neutral: shades of grey (Finlayson & Trezzi 2004), the
    p-norm mean of each channel over the unclipped pixels of the whole frame, shrunk first. p = 6 lies between
    grey-world (fooled by one dominant colour: a wooden kitchen) and white-patch (fooled by one bright coloured
    surface); on the published benchmark sets it beats both (Gijsenij et al. 2011). The colour gains keep the mean
    luminance and are clamped to 1/MAX_GAIN–MAX_GAIN: a scene that is really all one colour is not turned grey. Then
    exposure: a dim scene is brightened (at most MAX_EXPOSURE×) until its bright surfaces (the BRIGHT_QUANTILE of
    luminance) reach BRIGHT_REFERENCE, as a person judges a white cup in a dim kitchen white, not grey."""
    h, w = bgr.shape[:2]
    step = max(1, max(h, w) // ILLUMINANT_SIDE)
    small = bgr[::step, ::step].reshape(-1, 3)
    small = small[_channel_max(small) < CLIPPED]
    if len(small) < 16:
        return np.ones(3, np.float32)
    lin = SRGB_TO_LINEAR[small]
    cubed = lin * lin * lin
    estimate = np.power(np.mean(cubed * cubed, axis=0), 1.0 / SHADES_OF_GREY_P)  # p = 6
    if estimate.min() <= 1e-6:
        return np.ones(3, np.float32)
    gains = np.clip(estimate.mean() / estimate, 1 / MAX_GAIN, MAX_GAIN)
    luminance = (lin * gains) @ _XYZ_FROM_LINEAR_BGR[1]
    k = int(BRIGHT_QUANTILE * (len(luminance) - 1))
    bright = float(np.partition(luminance, k)[k])
    exposure = min(MAX_EXPOSURE, max(1.0, BRIGHT_REFERENCE / max(bright, 1e-6)))
    return (gains * exposure).astype(np.float32)


SECOND_COLOUR = 0.3  # a second colour group with at least this share of the object's pixels joins `colors`


def colour_groups(bins: np.ndarray, weights: np.ndarray | None = None) -> list[tuple[np.ndarray, float]]:
    """The object's main colours among its own pixels (core._colour_bins codes), heaviest first, each as (mask,
    share of the pixel weight): groups of neighbouring bins — three adjacent 20° hue bins (any saturation), or
    dark+grey, or grey+white — by pixel count (times `weights`, e.g. more for the box's centre, where the object
    is). The main group is the heaviest; a second one that shares no bin with it is kept when it holds at least
    SECOND_COLOUR of the weight. A striped shirt is one of its colours, not their purple mean; an orange couch is
    its orange, not the dark cushion and table in its box; a black and white chair is both."""
    counts = np.bincount(bins, weights=weights, minlength=39)
    total = float(counts.sum()) or 1.0
    hues = counts[0:36:2] + counts[1:36:2]
    chromatic = hues + hues[_PREVIOUS_HUE] + hues[_NEXT_HUE]  # np.roll by 1 and -1, without its overhead
    weight = np.append(chromatic, (counts[36] + counts[37], counts[37] + counts[38]))
    first = int(np.argmax(weight))
    out = [(_GROUP_LUT[first][bins], float(weight[first]) / total)]
    apart = np.where(_GROUP_OVERLAP[first], -1.0, weight)  # the groups that share no bin with the first
    second = int(np.argmax(apart))
    if apart[second] / total >= SECOND_COLOUR:
        out.append((_GROUP_LUT[second][bins], float(weight[second]) / total))
    return out


def _group_lut() -> np.ndarray:
    """Per group (18 hue windows, dark+grey, grey+white): which of the 39 bins belong to it."""
    lut = np.zeros((20, 39), bool)
    for k in range(18):
        for h in ((k - 1) % 18, k, (k + 1) % 18):
            lut[k, 2 * h : 2 * h + 2] = True
    lut[18, [36, 37]] = True
    lut[19, [37, 38]] = True
    return lut


_GROUP_LUT = _group_lut()
_PREVIOUS_HUE = np.roll(np.arange(18), 1)  # hue window k's neighbours, cyclic
_NEXT_HUE = np.roll(np.arange(18), -1)
_GROUP_OVERLAP = (_GROUP_LUT.astype(np.int32) @ _GROUP_LUT.T.astype(np.int32)) > 0  # groups sharing a bin


def measure_lab(bgr_pixels: np.ndarray, gains: np.ndarray | None = None) -> tuple[float, float, float] | None:
    """CIELAB of an object's own pixels (N×3 uint8 BGR): linearised, corrected by the illuminant `gains`, the
    darkest and brightest (shadows, highlights, clipped channels) trimmed by luminance, the rest averaged in
    linear light. None for no pixels."""
    pixels = bgr_pixels.reshape(-1, 3)
    if len(pixels) == 0:
        return None
    unclipped = _channel_max(pixels) < CLIPPED
    if unclipped.sum() >= 0.3 * len(pixels):  # a white object may be mostly near clipping: then keep them
        pixels = pixels.compress(unclipped, axis=0)  # as pixels[unclipped], without boolean indexing's overhead
    lin = SRGB_TO_LINEAR[pixels]
    if gains is not None:
        lin = np.clip(lin * gains, 0.0, 1.0)
    luminance = lin @ _XYZ_FROM_LINEAR_BGR[1]
    ordered = np.sort(luminance)
    lo, hi = ordered[int(TRIM[0] * (len(ordered) - 1))], ordered[int(TRIM[1] * (len(ordered) - 1))]
    kept = lin.compress((luminance >= lo) & (luminance <= hi), axis=0)
    if len(kept) == 0:
        kept = lin
    lab = linear_to_lab(_column_mean(kept))
    return float(lab[0]), float(lab[1]), float(lab[2])
