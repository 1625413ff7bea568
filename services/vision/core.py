"""One frame in, the Detections content out: detector, colour attribute, tracking, quality."""

from __future__ import annotations

import cv2
import numpy as np

from common.color import name_distribution
from common.language import BASIC_COLORS, canonical_label
from common.schema import ColorShare, DetectedObject, ImageQuality
from services.vision.color import (
    ACHROMATIC_SATURATION,
    DARK_VALUE,
    WHITE_VALUE,
    colour_groups,
    illuminant_gains,
    measure_lab,
)
from services.vision.colour_memory import REUSE_FRAMES, Colour, ColourMemory
from services.vision.depth import DepthImage, with_depth
from services.vision.quality import image_quality
from services.vision.segment import ColorSegmenter, Detection
from services.vision.track import Tracker
from services.vision.yolo import YoloDetector

# Colour of a detector's box from the object's own pixels. The box of a cup on a table is mostly table, so the
# box is compared with a ring around it: colour bins (hue × saturation, or black/grey/white) at least 1.5× more
# frequent inside the box than in the ring are the object's; their main colour is measured (CIELAB, the scene's
# light corrected) and named (docs/vision.md "Colour of a detection").
COLOR_SIDE = 32  # px: the box is sampled so that its longer side is about this (cheap, and enough for a hue)
RING = 0.25  # the ring reaches this share of the box's size beyond each side
FOREGROUND_RATIO = 1.5
MIN_OWN = 0.15  # what stands out must be at least this share of the box to be the object
CENTRE_WEIGHT = 2.0  # the middle half of the box (in each direction) counts this much in the main colour
SKIN_HUE = 17  # OpenCV hue (0–179) up to which, or from 170, a pixel may be skin
SKIN_SATURATION = (40, 170)  # 0–255
SKIN_VALUE = 60
MIN_CLOTHES = 0.3  # a person's pixels left without skin must be this share of them to be used


_HUE_BIN = (np.arange(256) // 10 * 2).astype(np.uint8)  # hue -> 2 × (hue // 10)


def _colour_bins(hsv: np.ndarray) -> np.ndarray:
    """Per pixel: 2 × (hue // 10) + (saturation ≥ 150) for chromatic pixels (0–35); 36 dark, 37 grey, 38 white."""
    h, s, v = cv2.split(hsv)
    bins = _HUE_BIN[h] + (s >= 150)
    achromatic = s < ACHROMATIC_SATURATION
    bins[achromatic] = np.where(v[achromatic] >= WHITE_VALUE, 38, 37)
    bins[v < DARK_VALUE] = 36
    return bins


def foreground_mask(
    bgr: np.ndarray, bbox: tuple[float, float, float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(BGR of the box and the ring around it, every step-th pixel so that the box's longer side is about
    COLOR_SIDE; their colour bins (_colour_bins); boolean mask of the object's own pixels among them; per-pixel
    weights, CENTRE_WEIGHT in the middle half of the box, 1 elsewhere)."""
    frame_h, frame_w = bgr.shape[:2]
    x, y, w, h = bbox
    x0, y0 = int(max(0, x - RING * w)), int(max(0, y - RING * h))
    x1, y1 = int(min(frame_w, np.ceil(x + w + RING * w))), int(min(frame_h, np.ceil(y + h + RING * h)))
    step = max(1, int(max(w, h) // COLOR_SIDE))  # every step-th pixel: enough for a histogram, and cheap
    small = bgr[y0:y1:step, x0:x1:step]
    if small.size == 0:
        return np.zeros((0, 3), np.uint8), np.zeros(0, np.uint8), np.zeros(0, bool), np.zeros(0, np.float32)
    s = 1.0 / step
    bins = _colour_bins(cv2.cvtColor(small, cv2.COLOR_BGR2HSV))
    inbox = np.zeros(bins.shape, bool)
    bx0, by0 = int((x - x0) * s), int((y - y0) * s)
    bx1, by1 = max(bx0 + 1, int(np.ceil((x + w - x0) * s))), max(by0 + 1, int(np.ceil((y + h - y0) * s)))
    inbox[by0:by1, bx0:bx1] = True
    in_counts = np.bincount(bins[by0:by1, bx0:bx1].ravel(), minlength=39)  # counts from the slice: no mask pass
    n_in = int(in_counts.sum())
    if bins.size - n_in < 0.1 * n_in:  # the box fills the frame: its own outer band stands for the surroundings
        band = max(1, int(0.12 * min(by1 - by0, bx1 - bx0)))
        ring = inbox.copy()
        ring[by0 + band : by1 - band, bx0 + band : bx1 - band] = False
        ring_counts = np.bincount(bins[ring], minlength=39)
    else:  # the ring is everything outside the box
        ring_counts = np.bincount(bins.ravel(), minlength=39) - in_counts
    in_hist = in_counts / max(1, n_in)
    ring_hist = ring_counts / max(1, int(ring_counts.sum()))
    own = inbox & (in_hist > FOREGROUND_RATIO * ring_hist + 0.005)[bins]
    if own.sum() < MIN_OWN * n_in:  # too little stands out to be the object (a detector boxes it tightly):
        # a cushion on a sofa, a logo on a shirt. The box is all we have
        own = inbox
    centre = np.ones(bins.shape, np.float32)  # the object is where the box's middle is: its pixels count double
    cy0, cx0 = by0 + (by1 - by0) // 4, bx0 + (bx1 - bx0) // 4
    centre[cy0 : max(cy0 + 1, by1 - (by1 - by0) // 4), cx0 : max(cx0 + 1, bx1 - (bx1 - bx0) // 4)] = CENTRE_WEIGHT
    return small, bins, own, centre


def skin(bgr_pixels: np.ndarray) -> np.ndarray:
    """Pixels of skin tone (N×3 BGR): hue 0–34° or ≥ 340°, saturation 0.16–0.67, value ≥ 0.24 — a person's
    colour is what they wear, not their face and arms."""
    hsv = cv2.cvtColor(bgr_pixels.reshape(-1, 1, 3), cv2.COLOR_BGR2HSV).reshape(-1, 3)
    h, s, v = hsv[:, 0], hsv[:, 1], hsv[:, 2]
    return ((h <= SKIN_HUE) | (h >= 170)) & (s >= SKIN_SATURATION[0]) & (s <= SKIN_SATURATION[1]) & (v >= SKIN_VALUE)


def object_colour(
    bgr: np.ndarray, bbox: tuple[float, float, float, float], gains: np.ndarray | None = None, label: str | None = None
) -> tuple[tuple[float, float, float] | None, list[tuple[str, float]]]:
    """(CIELAB of the object's main colour, its likeliest colour names with probabilities, best first).
    The object's own pixels (foreground_mask; a person's without skin) in colour groups (color.colour_groups: the
    main one, and a second big one), each measured (color.measure_lab, corrected by the scene's illuminant
    `gains`: color.illuminant_gains of the whole frame, estimated here when not given) and named; the names are
    the groups' mixture."""
    if gains is None:
        gains = illuminant_gains(bgr)
    small, bins, own, centre = foreground_mask(bgr, bbox)
    if label == "person" and own.any():
        clothes = own.copy()
        clothes[own] = ~skin(small[own])
        if clothes.sum() >= MIN_CLOTHES * own.sum():  # else: mostly skin (a hand, a face close up): keep it
            own = clothes
    if not own.any():
        return None, []
    flat_own = own.ravel()  # selections by compress: the same as boolean indexing, at a third of its overhead
    pixels = small.reshape(-1, 3).compress(flat_own, axis=0)
    groups_found = colour_groups(bins.ravel().compress(flat_own), centre.ravel().compress(flat_own))
    measured = [(measure_lab(pixels.compress(mask, axis=0), gains), share) for mask, share in groups_found]
    groups = [(lab, share) for lab, share in measured if lab is not None]
    if not groups:
        return None, []
    return groups[0][0], mixed_names(groups)


def mixed_names(groups: list[tuple[tuple[float, float, float], float]], top: int = 5) -> list[tuple[str, float]]:
    """The colour names of an object of one or two colour groups ((lab, share) each): the groups' name
    distributions (common.color.name_distribution) mixed by their shares, best first, the `top` best."""
    total = sum(share for _, share in groups) or 1.0
    mixed: dict[str, float] = {}
    for lab, share in groups:
        for name, p in name_distribution(lab, top=len(BASIC_COLORS)):
            mixed[name] = mixed.get(name, 0.0) + p * share / total
    return sorted(mixed.items(), key=lambda np_: -np_[1])[:top]


class VisionPipeline:
    """Per camera: detect, name colours, keep ids stable. Not thread-safe: one worker calls it.
    `colour_reuse_frames`: a still object's colour is reused for up to this many frames; `colour_max`: at most this
    many objects' colours are measured per frame, the others carry theirs (0: no cap; colour_memory.py)."""

    def __init__(
        self,
        detector: ColorSegmenter | YoloDetector,
        colour_reuse_frames: int = REUSE_FRAMES,
        colour_max: int = 0,
    ):
        self.detector = detector
        self.colour_reuse_frames = colour_reuse_frames
        self.colour_max = colour_max
        self.trackers: dict[str, Tracker] = {}
        self.colours: dict[str, ColourMemory] = {}

    def new_scene(self) -> None:
        """Forget every camera's objects (ids and colours): the next frames show another scene."""
        self.trackers.clear()
        self.colours.clear()

    def colour_counts(self) -> dict[str, int]:
        """Objects whose colour was measured, carried under the cap, or left without one, over every camera so far
        (the service's stats)."""
        memories = self.colours.values()
        return {
            "colour_measured": sum(m.measured for m in memories),
            "colour_carried": sum(m.carried for m in memories),
            "colour_uncoloured": sum(m.uncoloured for m in memories),
        }

    def detections(self, bgr: np.ndarray, cam: str = "") -> list[Detection]:
        if isinstance(self.detector, ColorSegmenter):
            return self.detector.detect(bgr)  # colours come from the segmentation itself
        # labels as the language's classes where one fits ("mug" -> "cup")
        found = [(canonical_label(label), score, box) for label, score, box in self.detector.detect(bgr)]
        memory = self.colours.setdefault(cam, ColourMemory(self.colour_reuse_frames, max_measured=self.colour_max))
        gains: list[np.ndarray] = []  # the scene's light, estimated once per frame, and only if a box is measured

        def measure(label: str, box: tuple[float, float, float, float]) -> Colour:
            if not gains:
                gains.append(illuminant_gains(bgr))
            return object_colour(bgr, box, gains[0], label)

        colours = memory.colours([(label, box) for label, _, box in found], measure)
        return [
            Detection(label, names[0][0] if names else None, score, box, lab=lab, colors=tuple(names))
            for (label, score, box), (lab, names) in zip(found, colours)
        ]

    def process(
        self, cam: str, bgr: np.ndarray, depth: DepthImage | None = None
    ) -> tuple[list[DetectedObject], ImageQuality]:
        """`depth`: the depth image aligned to `bgr`, with its intrinsics, when known."""
        tracker = self.trackers.setdefault(cam, Tracker(prefix=f"{cam}-o"))
        objects = [
            DetectedObject(
                id=obj_id,
                label=d.label,
                color=d.color,
                score=round(d.score, 4),
                bbox=[round(v, 1) for v in d.bbox],
                center=[round(v, 1) for v in d.center],
                lab=None if d.lab is None else [round(v, 1) for v in d.lab],
                colors=[ColorShare(name=n, p=round(p, 3)) for n, p in d.colors],
            )
            for obj_id, d in tracker.update(self.detections(bgr, cam))
        ]
        if depth is not None:  # positions in metres (services/vision/depth.py)
            objects = [with_depth(o, depth) for o in objects]
        brightness, contrast, sharpness = image_quality(bgr)
        return objects, ImageQuality(brightness=brightness, contrast=contrast, sharpness=sharpness)
