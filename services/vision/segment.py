"""The default detector: colour segmentation, no model needed.

Chromatic blobs: one mask per palette colour (pixels saturated and bright enough whose hue lies in that colour's
ranges — red from both ends of the hue circle), smoothed (Gaussian blur, morphological open and close), split
into connected components. One mask per colour, not one for all hues, so a red candy touching a blue one stays
two objects. Each component is named by the hue histogram of its own pixels.

Background is not an object, and never hides one: a chromatic component is background when it touches two or
more image borders (unless it is small: a candy cut off in a corner), when its box spans most of the frame while
it fills little of it (a ring around the object in front), or when it touches a border and its colour covers a
large share of the frame's border (the pieces of a coloured wall cut apart by the object in front of it).

Slivers: a candy whose pixels straddle two ranges (orange candies have a reddish rim) gives a big component in one
mask and a sliver in the neighbouring one. A box lying mostly inside a bigger kept box is dropped only when its
colour is the same or a neighbour on the hue circle and it is small or thin next to the bigger one — never a
distinct object inside a bigger box.

Achromatic blobs: dark pixels (black) and bright unsaturated ones (white) the same way, but only those that do not
touch two or more image borders (a table, a wall), are not background by the rules above (the edge share being
that of the whole black or white mask), and stand out from the ring around them. Components smaller
than `min_area_frac` or larger than `max_area_frac` of the image are dropped; the upper bound is most of the frame,
so a close-up object (a gripper camera's view) is kept.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from common.language import OBJECT_PHRASES, canonical_label
from services.vision.color import (
    ACHROMATIC_SATURATION,
    CHROMATIC,
    DARK_VALUE,
    HUE_RANGES,
    PALETTE,
    WHITE_VALUE,
    hue_name,
)


@dataclass
class Detection:
    """One object in one frame, before tracking gives it an id."""

    label: str
    color: str | None
    score: float
    bbox: tuple[float, float, float, float]  # x, y, w, h (px)
    lab: tuple[float, float, float] | None = None  # CIELAB of the object's own pixels (the ONNX path's colour model)
    colors: tuple[tuple[str, float], ...] = ()  # likeliest colour names with probabilities, best first

    @property
    def center(self) -> tuple[float, float]:
        x, y, w, h = self.bbox
        return x + w / 2.0, y + h / 2.0


@dataclass
class ColorSegmenter:
    min_saturation: int = 100
    min_value: int = DARK_VALUE
    min_area_frac: float = 0.0015
    max_area_frac: float = 0.85  # a close-up object may fill most of the frame
    achromatic: bool = True
    contained: float = 0.5  # a sliver: more than this share of the smaller box inside the other box ...
    sliver_area: float = 0.6  # ... and fewer pixels than this share of the bigger one's, or thinner than that
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
        # hues along the frame's edge (share of the edge's pixels per hue): a coloured wall or table owns many
        edge = np.concatenate([hsv[0], hsv[-1], hsv[1:-1, 0], hsv[1:-1, -1]])
        edge_vivid = np.concatenate([vivid[0], vivid[-1], vivid[1:-1, 0], vivid[1:-1, -1]]) > 0
        edge_hues = np.bincount(edge[edge_vivid, 0].astype(np.int64), minlength=180)[:180] / float(len(edge))
        found: list[Blob] = []
        for k in range(1, len(CHROMATIC) + 1):
            found += self._components(hsv, cv2.inRange(colour_index, k, k), None, edge_hues)
        found = merge_slivers(found, self.contained, self.sliver_area)
        for blob in found:
            self._name(blob)
        if self.achromatic:
            found += self._components(hsv, cv2.inRange(hsv, (0, 0, 0), (180, 255, DARK_VALUE - 1)), "black")
            found += self._components(
                hsv, cv2.inRange(hsv, (0, 0, WHITE_VALUE), (180, ACHROMATIC_SATURATION - 1, 255)), "white"
            )
        return [b.detection for b in found]

    def _name(self, blob: Blob) -> None:
        """Colour and score of a chromatic blob from its (possibly merged) hue histogram."""
        assert blob.hist is not None, "a chromatic blob has its hue histogram"
        color, agreement = hue_name(blob.hist)
        x, y, bw, bh = blob.detection.bbox
        fill = blob.area / float(bw * bh)  # a disc fills pi/4 of its box
        score = float(np.clip(0.4 + 0.3 * agreement + 0.3 * min(1.0, fill / 0.785), 0.0, 1.0))
        blob.detection = Detection(self.label_for(color), color, score, blob.detection.bbox)

    def _components(
        self, hsv: np.ndarray, mask: np.ndarray, achromatic_color: str | None, edge_hues: np.ndarray | None = None
    ) -> list[Blob]:
        """Connected components of `mask` that are objects, not background. Chromatic ones (achromatic_color
        None) are named by the hue histogram of their own pixels; achromatic ones have the colour of their mask."""
        h, w = mask.shape
        m = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, self._kernel)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        min_area, max_area = self.min_area_frac * h * w, self.max_area_frac * h * w
        if achromatic_color:  # the share of the frame's edge in this mask: a white wall or a black floor owns much
            mask_edge_share = (
                np.count_nonzero(m[0])
                + np.count_nonzero(m[-1])
                + np.count_nonzero(m[1:-1, 0])
                + np.count_nonzero(m[1:-1, -1])
            ) / float(2 * (h + w) - 4)
        out = []
        for i in range(1, n):
            x, y, bw, bh, area = (int(v) for v in stats[i])
            if not min_area <= area <= max_area:
                continue
            borders = (x == 0) + (y == 0) + (x + bw == w) + (y + bh == h)
            if achromatic_color and borders >= 2:
                continue
            box = (float(x), float(y), float(bw), float(bh))
            if achromatic_color:
                if is_background(bw, bh, area, w, h, borders, mask_edge_share):
                    continue
                if not stands_out(hsv[..., 2], labels, i, (x, y, bw, bh), achromatic_color == "white"):
                    continue  # a brighter (or darker) patch of the table, not an object on it
                fill = area / float(bw * bh)
                score = float(np.clip(0.7 + 0.3 * min(1.0, fill / 0.785), 0.0, 1.0))
                out.append(Blob(Detection(self.label_for(achromatic_color), achromatic_color, score, box), area))
                continue
            inside = (labels[y : y + bh, x : x + bw] == i).view(np.uint8)
            hist = cv2.calcHist([hsv[y : y + bh, x : x + bw]], [0], inside, [180], [0, 180]).ravel()
            edge_share = 0.0 if edge_hues is None else hue_window_share(edge_hues, int(np.argmax(hist)))
            if is_background(bw, bh, area, w, h, borders, edge_share):
                continue
            out.append(Blob(Detection("", None, 0.0, box), area, hist))  # named once slivers are merged
        return out


@dataclass
class Blob:
    """A detection, the number of pixels of its component and (chromatic) their hue histogram."""

    detection: Detection
    area: int
    hist: np.ndarray | None = None


EDGE_HUE_WINDOW = 10  # hue units either side of a blob's main hue that count as "its colour" along the edge


def hue_window_share(edge_hues: np.ndarray, hue: int) -> float:
    """The share of the frame's edge whose pixels are vivid with a hue within EDGE_HUE_WINDOW of `hue` (circular)."""
    idx = np.arange(hue - EDGE_HUE_WINDOW, hue + EDGE_HUE_WINDOW + 1) % 180
    return float(edge_hues[idx].sum())


BACKGROUND_EDGE_SHARE = 0.25  # a colour covering this share of the frame's edge is a wall or table colour
CORNER_OBJECT_FRAC = 0.02  # a component touching two borders but smaller than this (of the frame) is an object
SPAN_FRAC = 0.2  # a box spanning at least this share of the frame ...
SPARSE_FILL = 0.7  # ... that it fills less than this × that share is scattered backdrop (a ring, speckle)


def is_background(bw: int, bh: int, area: int, w: int, h: int, borders: int, edge_share: float) -> bool:
    """Whether a chromatic component is background (a wall, a table, a cloth) rather than an object on it.
    `borders`: how many image borders it touches; `edge_share`: the share of the frame's edge that has its hue."""
    frame = float(w * h)
    if borders >= 2 and (area >= CORNER_OBJECT_FRAC * frame or bw >= w / 2 or bh >= h / 2):
        return True  # it runs off the frame on two sides and is not a small thing cut off in a corner
    box_frac = bw * bh / frame
    if box_frac >= SPAN_FRAC and area / float(bw * bh) < SPARSE_FILL * box_frac:
        return True  # a big box it fills little of: a backdrop around the object (half the frame filled < 35 %)
    return borders >= 1 and edge_share >= BACKGROUND_EDGE_SHARE  # one piece of a wall of its hue, cut by objects


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


NEIGHBOUR_HUES = {frozenset((a, b)) for a, b in zip(CHROMATIC, CHROMATIC[1:] + CHROMATIC[:1])}


def same_or_neighbour_hue(a: str | None, b: str | None) -> bool:
    """red–orange, orange–yellow, …, purple–red: the colours one object's pixels can straddle."""
    return a == b or frozenset((a, b)) in NEIGHBOUR_HUES


def overlap_of_smaller(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> float:
    """The share of the smaller box's area that lies inside the other box."""
    return max(inside_share(a, b), inside_share(b, a)) if a[2] * a[3] <= b[2] * b[3] else inside_share(b, a)


def merge_slivers(found: list[Blob], share: float, sliver_area: float) -> list[Blob]:
    """Largest first, merge into a kept blob each blob that is a sliver of the same object: a hue the same or next
    on the circle, more than `share` of the smaller box inside the other, and fewer pixels than `sliver_area` of the
    kept one's or a short side under `sliver_area` of its short side. The merged blob has the union box and both
    hue histograms. A blob of a distant hue, or as big as the other, is another object and stays."""
    kept: list[Blob] = []
    names: list[str] = []  # hue name of each kept blob
    for blob in sorted(found, key=lambda b: -b.area):
        assert blob.hist is not None, "slivers are merged among chromatic blobs, which have their hue histogram"
        name = hue_name(blob.hist)[0]
        b = blob.detection.bbox
        for j, k in enumerate(kept):
            kb = k.detection.bbox
            if (
                same_or_neighbour_hue(name, names[j])
                and overlap_of_smaller(b, kb) > share
                and (blob.area < sliver_area * k.area or min(b[2:]) < sliver_area * min(kb[2:]))
            ):
                x0, y0 = min(kb[0], b[0]), min(kb[1], b[1])
                x1, y1 = max(kb[0] + kb[2], b[0] + b[2]), max(kb[1] + kb[3], b[1] + b[3])
                k.detection = Detection("", None, 0.0, (x0, y0, x1 - x0, y1 - y0))
                k.area += blob.area
                assert k.hist is not None  # a kept blob went through the same check
                k.hist = k.hist + blob.hist
                names[j] = hue_name(k.hist)[0]
                break
        else:
            kept.append(blob)
            names.append(name)
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
    if not isinstance(raw, dict) or not all(
        isinstance(k, str) and isinstance(v, str) and v.strip() for k, v in raw.items()
    ):
        raise ValueError(f'--labels file {path} must be a JSON object of colour -> label, e.g. {{"*": "candy"}}')
    unknown = sorted(set(raw) - set(PALETTE) - {"*"})
    if unknown:
        raise ValueError(
            f'--labels file {path}: {unknown} are not colours of this backend; use {", ".join(PALETTE)} or "*"'
        )
    labels = {colour: canonical_label(label) for colour, label in raw.items()}
    warnings = [
        f"label {label!r} is not a class of common.language: speech cannot name it"
        for label in sorted(set(labels.values()))
        if label not in OBJECT_PHRASES
    ]
    return labels, warnings
