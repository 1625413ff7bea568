"""An object's colour measured at a lower rate than its box: reused while the object stays where it was measured.

Measuring a box's colour (core.object_colour) costs about as much for a small box as for a large one (numpy
overhead over a dozen small steps), so on a frame of many objects it is a real share of the detector's time. A
still object's colour does not change from one frame to the next, so it is reused: a detection takes the colour
measured on an earlier box when

* that box had the same label,
* the detection's box overlaps it at IoU >= REUSE_IOU (the box it was measured on, not the last frame's: a slow
  drift adds up until the object is measured again), and
* the measurement is at most REUSE_FRAMES frames old.

Anything else — a new object, one that moved, one measured REUSE_FRAMES frames ago — is measured on this frame.
Each earlier measurement serves at most one detection (the best overlapping), and a measurement no detection
took is forgotten. The cost: a colour change of an object that does not move (a light switched on, a cloth laid
over it) is seen up to REUSE_FRAMES frames late (133 ms at 30 fps at the default 4).

Association is by box, not by the tracker's ids: the tracker (track.py) matches on colour, so colour comes first.
Pure Python, no Zenoh.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from common.boxes import iou, match_in_order

REUSE_IOU = 0.85  # a box overlapping the one a colour was measured on this much shows the same pixels
REUSE_FRAMES = 4  # a colour is reused for at most this many frames after the one it was measured on

Box = tuple[float, float, float, float]
Lab = tuple[float, float, float]
Colour = tuple[Lab | None, list[tuple[str, float]]]  # (CIELAB, colour names best first), as core.object_colour


@dataclass(frozen=True)
class Measured:
    """One object's colour as measured, with the box and the frame it was measured on."""

    label: str
    box: Box
    frame: int
    colour: Colour


@dataclass
class ColourMemory:
    """Per camera: the colours measured on recent frames. Not thread-safe: the service's one worker calls it.
    `reuse_frames` 0: every object is measured on every frame."""

    reuse_frames: int = REUSE_FRAMES
    reuse_iou: float = REUSE_IOU
    frame: int = 0
    kept: list[Measured] = field(default_factory=list)
    measured: int = 0  # objects measured so far (reused ones are not counted)

    def colours(self, found: list[tuple[str, Box]], measure: Callable[[str, Box], Colour]) -> list[Colour]:
        """The colour of each (label, box) of this frame, in order: reused where the rule allows, else
        `measure(label, box)`."""
        self.frame += 1
        reused = self._reusable(found)
        out: list[Colour] = []
        kept: list[Measured] = []
        for di, (label, box) in enumerate(found):
            earlier = reused.get(di)
            if earlier is None:
                earlier = Measured(label, box, self.frame, measure(label, box))
                self.measured += 1
            kept.append(earlier)
            out.append(earlier.colour)
        self.kept = kept
        return out

    def _reusable(self, found: list[tuple[str, Box]]) -> dict[int, Measured]:
        """Detection index -> the earlier measurement it reuses: best overlap first, one to one."""
        if self.reuse_frames <= 0:
            return {}
        pairs = []
        for mi, m in enumerate(self.kept):
            if self.frame - m.frame > self.reuse_frames:
                continue
            for di, (label, box) in enumerate(found):
                if label == m.label:
                    overlap = iou(m.box, box)
                    if overlap >= self.reuse_iou:
                        pairs.append((overlap, mi, di))
        return {di: self.kept[mi] for di, mi in match_in_order(sorted(pairs, reverse=True)).items()}
