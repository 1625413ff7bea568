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

**A cap per frame** (`max_measured`, issue #42): on a busy scene (a restaurant table: cups, glasses, people
behind) many objects move at once and each needs measuring, so the cost per frame grows with what the scene holds.
At most `max_measured` objects are measured on a frame: the ones without a colour first (new objects), then the
longest unmeasured. Each of the others keeps the colour it had — carried from its box on the last frame it was
seen (same label, IoU >= CARRY_IOU with that box, one to one), however old its measurement. An object with no
colour to carry and no room on this frame has none for that frame (`(None, [])`) and is first in line on the next.
With n objects needing a measurement, every one of them is measured again within ceil(n / max_measured) frames
(`frames_to_measure_all`).

Association is by box, not by the tracker's ids: the tracker (track.py) matches on colour, so colour comes first.
Pure Python, no Zenoh.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

from common.boxes import iou, match_in_order

REUSE_IOU = 0.85  # a box overlapping the one a colour was measured on this much shows the same pixels
REUSE_FRAMES = 4  # a colour is reused for at most this many frames after the one it was measured on
MAX_MEASURED = 4  # objects measured per frame at most (0: no cap); the others carry their last colour
CARRY_IOU = 0.3  # a box overlapping an object's box of the last frame this much is that object (its colour carried)

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
    seen_at: Box | None = None  # the object's box on the last frame it was seen, when it moved since (carried)

    @property
    def last_box(self) -> Box:
        return self.seen_at if self.seen_at is not None else self.box


@dataclass
class ColourMemory:
    """Per camera: the colours measured on recent frames. Not thread-safe: the service's one worker calls it.
    `reuse_frames` 0: every object is measured on every frame."""

    reuse_frames: int = REUSE_FRAMES
    reuse_iou: float = REUSE_IOU
    max_measured: int = 0  # objects measured per frame at most; 0: every object that needs it
    frame: int = 0
    kept: list[Measured] = field(default_factory=list)
    measured: int = 0  # objects measured so far (reused ones are not counted)
    carried: int = 0  # objects that kept an older colour because the frame's cap was reached
    uncoloured: int = 0  # objects left without a colour for a frame because the cap was reached

    def colours(self, found: list[tuple[str, Box]], measure: Callable[[str, Box], Colour]) -> list[Colour]:
        """The colour of each (label, box) of this frame, in order: reused where the rule allows, else
        `measure(label, box)` for at most `max_measured` of them, else carried (module docstring)."""
        self.frame += 1
        reused = self._reusable(found)
        need = [di for di in range(len(found)) if di not in reused]
        carry = self._carriable(found, need, set(map(id, reused.values()))) if self._capped(len(need)) else {}
        chosen = set(measure_first(need, carry, self.max_measured))
        out: list[Colour] = []
        kept: list[Measured] = []
        for di, (label, box) in enumerate(found):
            earlier = reused.get(di)
            if earlier is None and di in chosen:
                earlier = Measured(label, box, self.frame, measure(label, box))
                self.measured += 1
            elif earlier is None and di in carry:
                earlier = replace(carry[di], seen_at=box)
                self.carried += 1
            elif earlier is None:
                self.uncoloured += 1
                out.append((None, []))
                continue
            kept.append(earlier)
            out.append(earlier.colour)
        self.kept = kept
        return out

    def _capped(self, needing: int) -> bool:
        return 0 < self.max_measured < needing

    def _carriable(self, found: list[tuple[str, Box]], need: list[int], taken: set[int]) -> dict[int, Measured]:
        """Detection index (of those in `need`) -> the kept colour of the same object on the last frame it was seen:
        same label, IoU >= CARRY_IOU with that frame's box, best overlap first, one to one; a colour a detection
        reuses by the rule (`taken`, by identity) is not carried to another."""
        pairs = []
        for mi, m in enumerate(self.kept):
            if id(m) in taken:
                continue
            for di in need:
                label, box = found[di]
                if label == m.label:
                    overlap = iou(m.last_box, box)
                    if overlap >= CARRY_IOU:
                        pairs.append((overlap, mi, di))
        return {di: self.kept[mi] for di, mi in match_in_order(sorted(pairs, reverse=True)).items()}

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


def measure_first(need: list[int], carry: dict[int, Measured], cap: int) -> list[int]:
    """Which of the detections needing a measurement (`need`, indices) are measured on this frame under a cap of
    `cap` (0: all): those with no colour to carry first (in order), then the ones measured longest ago."""
    if cap <= 0 or len(need) <= cap:
        return list(need)
    order = sorted(need, key=lambda di: (di in carry, carry[di].frame if di in carry else 0, di))
    return order[:cap]


def frames_to_measure_all(needing: int, cap: int) -> int:
    """Frames in which every one of `needing` objects that keep needing a measurement is measured at least once,
    under a cap of `cap` per frame (0: no cap): ceil(needing / cap)."""
    if needing <= 0:
        return 0
    return 1 if cap <= 0 else -(-needing // cap)
