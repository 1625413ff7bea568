"""Stable object ids across frames: greedy IoU association with a short memory.

Each new detection is matched to the live track of the same colour with the highest IoU (at least
`min_iou`), or failing that to the nearest one whose centre is within `max_jump` of the box size — so an
object that moves a little between frames keeps its id. A track unseen for more than `max_missed`
frames is forgotten. Ids come from a counter and are never reused, so "o7" always meant one object.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from common.boxes import iou, match_in_order
from services.vision.segment import Detection


@dataclass
class Track:
    id: str
    det: Detection
    missed: int = 0


@dataclass
class Tracker:
    min_iou: float = 0.3
    max_jump: float = 0.6  # centre distance, as a fraction of the larger box side
    max_missed: int = 5
    prefix: str = "o"
    tracks: list[Track] = field(default_factory=list)
    _next: int = 1

    def update(self, detections: list[Detection]) -> list[tuple[str, Detection]]:
        """Ids for this frame's detections, in the order given."""
        pairs = []
        for ti, track in enumerate(self.tracks):
            for di, det in enumerate(detections):
                if det.color != track.det.color or det.label != track.det.label:
                    continue
                overlap = iou(track.det.bbox, det.bbox)
                (tx, ty), (dx, dy) = track.det.center, det.center
                size = max(track.det.bbox[2], track.det.bbox[3], det.bbox[2], det.bbox[3], 1.0)
                jump = ((tx - dx) ** 2 + (ty - dy) ** 2) ** 0.5 / size
                if overlap >= self.min_iou or jump <= self.max_jump:
                    pairs.append((overlap - jump, ti, di))
        matched = match_in_order(sorted(pairs, reverse=True))
        ids: dict[int, str] = {}
        for di, ti in matched.items():
            ids[di] = self.tracks[ti].id
            self.tracks[ti].det, self.tracks[ti].missed = detections[di], 0
        used_tracks = set(matched.values())
        for ti, track in enumerate(self.tracks):
            if ti not in used_tracks:
                track.missed += 1
        self.tracks = [t for t in self.tracks if t.missed <= self.max_missed]
        for di, det in enumerate(detections):
            if di not in ids:
                ids[di] = f"{self.prefix}{self._next}"
                self._next += 1
                self.tracks.append(Track(ids[di], det))
        return [(ids[i], d) for i, d in enumerate(detections)]
