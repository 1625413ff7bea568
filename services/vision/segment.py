"""The default detector: colour segmentation, no model needed.

Chromatic blobs: one mask per palette colour (pixels saturated and bright enough whose hue lies in that colour's
ranges — red from both ends of the hue circle), smoothed (Gaussian blur, morphological open and close), split
into connected components. One mask per colour, not one for all hues, so a red candy touching a blue one stays
two objects. A candy whose pixels straddle two ranges (orange candies have a reddish rim) gives a big component
in one mask and a sliver in the other: a box lying mostly inside a bigger kept box is dropped. Each kept
component is named by the hue histogram of its own pixels. Achromatic blobs: dark pixels (black) and bright
unsaturated ones (white) the same way, but only those that do not touch two or more image borders (that is
background: a table, a wall). Components smaller than `min_area_frac` or larger than `max_area_frac` of the
image are dropped.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from common.language import COLOR_PHRASES, OBJECT_PHRASES, canonical_label
from services.vision.color import ACHROMATIC_SATURATION, CHROMATIC, DARK_VALUE, HUE_RANGES, WHITE_VALUE, hue_name


@dataclass
class Detection:
    """One object in one frame, before tracking gives it an id."""
    label: str
    color: str | None
    score: float
    bbox: tuple[float, float, float, float]  # x, y, w, h (px)

    @property
    def center(self) -> tuple[float, float]:
        x, y, w, h = self.bbox
        return x + w / 2.0, y + h / 2.0


@dataclass
class ColorSegmenter:
    min_saturation: int = 100
    min_value: int = DARK_VALUE
    min_area_frac: float = 0.0015
    max_area_frac: float = 0.25
    achromatic: bool = True
    contained: float = 0.5  # drop a box when more than this share of it lies inside a bigger kept box
    labels: dict[str, str] = field(default_factory=dict)  # colour -> label, "*" for any; default "object"

    def __post_init__(self) -> None:
        self._kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
        # hue -> 1 + index into CHROMATIC, for one LUT pass then one inRange per colour
        lut = np.zeros(256, np.uint8)
        for k, name in enumerate(CHROMATIC):
            for lo, hi in HUE_RANGES[name]:
                lut[lo:hi] = k + 1
        self._hue_lut = lut

    def label_for(self, color: str | None) -> str:
        return self.labels.get(color or "", self.labels.get("*", "object"))

    def detect(self, bgr: np.ndarray) -> list[Detection]:
        hsv = cv2.cvtColor(cv2.GaussianBlur(bgr, (5, 5), 0), cv2.COLOR_BGR2HSV)
        vivid = cv2.inRange(hsv, (0, self.min_saturation, self.min_value), (180, 255, 255))
        colour_index = cv2.bitwise_and(cv2.LUT(hsv[..., 0], self._hue_lut), vivid)  # 0 where not vivid
        found: list[Detection] = []
        for k in range(1, len(CHROMATIC) + 1):
            found += self._components(hsv, cv2.inRange(colour_index, k, k), None)
        found = drop_contained(found, self.contained)
        if self.achromatic:
            found += self._components(hsv, cv2.inRange(hsv, (0, 0, 0), (180, 255, DARK_VALUE - 1)), "black")
            found += self._components(hsv, cv2.inRange(hsv, (0, 0, WHITE_VALUE), (180, ACHROMATIC_SATURATION - 1, 255)),
                                      "white")
        return found

    def _components(self, hsv: np.ndarray, mask: np.ndarray, achromatic_color: str | None) -> list[Detection]:
        """Connected components of `mask`. Chromatic ones (achromatic_color None) are named by the hue
        histogram of their own pixels; achromatic ones have the colour of their mask and must not be
        background (touching two or more image borders)."""
        h, w = mask.shape
        m = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, self._kernel)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        min_area, max_area = self.min_area_frac * h * w, self.max_area_frac * h * w
        out = []
        for i in range(1, n):
            x, y, bw, bh, area = (int(v) for v in stats[i])
            if not min_area <= area <= max_area:
                continue
            if achromatic_color and (x == 0) + (y == 0) + (x + bw == w) + (y + bh == h) >= 2:
                continue
            if achromatic_color:
                if not stands_out(hsv[..., 2], labels, i, (x, y, bw, bh), achromatic_color == "white"):
                    continue  # a brighter (or darker) patch of the table, not an object on it
                color, agreement = achromatic_color, 1.0
            else:
                inside = (labels[y:y + bh, x:x + bw] == i).view(np.uint8)
                hist = cv2.calcHist([hsv[y:y + bh, x:x + bw]], [0], inside, [180], [0, 180])
                color, agreement = hue_name(hist)
            fill = area / float(bw * bh)  # a disc fills pi/4 of its box
            score = float(np.clip(0.4 + 0.3 * agreement + 0.3 * min(1.0, fill / 0.785), 0.0, 1.0))
            out.append(Detection(self.label_for(color), color, score, (float(x), float(y), float(bw), float(bh))))
        return out


EDGE_CONTRAST = 25  # grey levels between an achromatic object and the ring of pixels around it


def stands_out(val: np.ndarray, labels: np.ndarray, i: int, box: tuple[int, int, int, int], brighter: bool) -> bool:
    """Whether component `i` is brighter (or darker) than the ring of pixels around its box by EDGE_CONTRAST:
    a white ball on a grey table is; a sunlit patch of a white table is not."""
    x, y, bw, bh = box
    m = max(4, int(0.3 * max(bw, bh)))
    y0, y1, x0, x1 = max(0, y - m), min(val.shape[0], y + bh + m), max(0, x - m), min(val.shape[1], x + bw + m)
    region, owner = val[y0:y1, x0:x1], labels[y0:y1, x0:x1]
    inside = owner == i
    ring = ~inside
    if not ring.any():
        return True
    diff = float(region[inside].mean()) - float(region[ring].mean())
    return diff >= EDGE_CONTRAST if brighter else -diff >= EDGE_CONTRAST


def drop_contained(found: list[Detection], share: float) -> list[Detection]:
    """Largest first, keep a box unless more than `share` of it lies inside a box already kept."""
    kept: list[Detection] = []
    for det in sorted(found, key=lambda d: -d.bbox[2] * d.bbox[3]):
        if all(inside_share(det.bbox, k.bbox) <= share for k in kept):
            kept.append(det)
    return kept


def inside_share(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """The share of box a's area that lies inside box b."""
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    iw = min(ax + aw, bx + bw) - max(ax, bx)
    ih = min(ay + ah, by + bh) - max(ay, by)
    return iw * ih / (aw * ah) if iw > 0 and ih > 0 and aw * ah > 0 else 0.0


def read_labels(path: str | Path) -> tuple[dict[str, str], list[str]]:
    """The colour backend's label rule from a JSON file: {colour: label, "*": label for any other colour}.

    Labels go through `canonical_label` ("mug" -> "cup"), so they are the language's classes where one fits.
    Returns the mapping and warnings (labels speech has no word for). Raises ValueError saying what is wrong.
    """
    try:
        raw = json.loads(Path(path).read_text())
    except OSError as exc:
        raise ValueError(f"cannot read --labels file {path}: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"--labels file {path} is not JSON: {exc}") from None
    if not isinstance(raw, dict) or not all(isinstance(k, str) and isinstance(v, str) and v.strip()
                                            for k, v in raw.items()):
        raise ValueError(f'--labels file {path} must be a JSON object of colour -> label, e.g. {{"*": "candy"}}')
    unknown = sorted(set(raw) - set(COLOR_PHRASES) - {"*"})
    if unknown:
        raise ValueError(f"--labels file {path}: {unknown} are not colours; use {', '.join(COLOR_PHRASES)} or \"*\"")
    labels = {colour: canonical_label(label) for colour, label in raw.items()}
    warnings = [f"label {label!r} is not a class of common.language: speech cannot name it"
                for label in sorted(set(labels.values())) if label not in OBJECT_PHRASES]
    return labels, warnings
